//! The damaged input, read record by record with every length checked.

use super::RecoverError;
use crate::lines::{read_full, Fields, HEAD, RECORD_LIMIT};
use mcap::records::op;
use std::io::{self, Read};

/// Message records in `records`, as far as their heads can be followed.
pub(super) fn count_messages(records: &[u8]) -> u64 {
    let mut f = Fields::new(records);
    let mut n = 0;
    while let (Ok(o), Ok(len)) = (f.take(1), f.u64()) {
        n += u64::from(o[0] == op::MESSAGE);
        if usize::try_from(len)
            .ok()
            .and_then(|l| f.take(l).ok())
            .is_none()
        {
            break;
        }
    }
    n
}

/// A record's kind, for messages.
pub(super) fn kind(opcode: u8) -> &'static str {
    match opcode {
        op::HEADER => "a Header",
        op::SCHEMA => "a Schema",
        op::CHANNEL => "a Channel",
        op::MESSAGE => "a Message",
        op::CHUNK => "a Chunk",
        op::METADATA => "a Metadata record",
        op::ATTACHMENT => "an Attachment",
        op::MESSAGE_INDEX | op::CHUNK_INDEX | op::ATTACHMENT_INDEX | op::METADATA_INDEX => {
            "an index"
        }
        _ => "a record",
    }
}

/// What the input holds next.
pub(super) enum Next {
    /// A whole record, its body in `Input::body`.
    Record { opcode: u8, offset: u64 },
    /// A whole record larger than [`RECORD_LIMIT`], skipped unread.
    TooLarge { opcode: u8, offset: u64, len: u64 },
    /// A record whose end is past the end of the file; of a chunk, the
    /// bytes there are in `Input::body` (at most [`RECORD_LIMIT`]).
    Cut {
        opcode: u8,
        offset: u64,
        len: u64,
        avail: u64,
    },
    /// No record from `offset` on: the end of the file, or (with `why`)
    /// `lost` bytes that are no record.
    End {
        offset: u64,
        lost: u64,
        why: Option<String>,
    },
}

/// The input, record by record.
pub(super) struct Input<'a, R> {
    pub(super) src: &'a mut R,
    pub(super) name: String,
    /// File offset of the next byte of `src`.
    pub(super) pos: u64,
    pub(super) size: u64,
    pub(super) body: Vec<u8>,
}

impl<R: Read> Input<'_, R> {
    fn io_err(&self, err: io::Error) -> RecoverError {
        RecoverError::File {
            file: self.name.clone(),
            err,
        }
    }

    /// Read `len` bytes into `body`.
    fn fill(&mut self, len: u64) -> Result<(), RecoverError> {
        self.body.clear();
        let got = (&mut *self.src).take(len).read_to_end(&mut self.body);
        let got = got.map_err(|e| self.io_err(e))?;
        self.pos += got as u64;
        Ok(())
    }

    pub(super) fn next(&mut self) -> Result<Next, RecoverError> {
        let offset = self.pos;
        let rest = self.size.saturating_sub(offset);
        let mut head = [0u8; HEAD];
        let n = read_full(&mut *self.src, &mut head).map_err(|e| self.io_err(e))?;
        self.pos += n as u64;
        if n == 0 {
            return Ok(Next::End {
                offset,
                lost: 0,
                why: None,
            });
        }
        if n < HEAD {
            return Ok(Next::End {
                offset,
                lost: n as u64,
                why: Some(format!(
                    "cut inside a record's head ({n} of its 9 bytes written)"
                )),
            });
        }
        let opcode = head[0];
        let mut lb = [0u8; 8];
        lb.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(lb);
        if opcode == 0 {
            // Opcode 0 is no record: a zero-filled tail (what a file
            // system may leave after a power loss), or garbage.
            let why = if head.iter().all(|&b| b == 0) {
                "zeros, no record: the rest of the file dropped"
            } else {
                "opcode 0x00 is no MCAP record: the rest of the file dropped"
            };
            return Ok(Next::End {
                offset,
                lost: rest,
                why: Some(why.into()),
            });
        }
        let avail = rest.saturating_sub(HEAD as u64);
        if len > avail {
            if opcode == op::CHUNK {
                self.fill(avail.min(RECORD_LIMIT))?;
            }
            return Ok(Next::Cut {
                opcode,
                offset,
                len,
                avail,
            });
        }
        if len > RECORD_LIMIT {
            let skipped = io::copy(&mut (&mut *self.src).take(len), &mut io::sink());
            self.pos += skipped.map_err(|e| self.io_err(e))?;
            return Ok(Next::TooLarge {
                opcode,
                offset,
                len,
            });
        }
        self.fill(len)?;
        Ok(Next::Record { opcode, offset })
    }
}
