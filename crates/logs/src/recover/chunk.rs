//! The records of a chunk, whole or the one a cut fell in: checked, then
//! carried one by one up to the first that does not parse.

use super::{count_messages, Out, RecoverError, Salvage, Whole};
use crate::lines::{Fields, HEAD};
use mcap::records::op;

impl Salvage {
    /// The records of a chunk (`body`, its record at `offset`); the input
    /// bytes kept.
    pub(super) fn chunk(
        &mut self,
        w: &mut Out,
        offset: u64,
        body: &[u8],
        whole: Whole,
    ) -> Result<u64, RecoverError> {
        let total = HEAD as u64 + body.len() as u64;
        let Some((start, records)) = self.chunk_records(offset, body, whole)? else {
            return Ok(0);
        };
        let records_at = offset + HEAD as u64 + start as u64;
        let lost_before = self.s.lost_bytes;
        let p = self.chunk_walk(w, records, records_at, whole)?;
        let kept = HEAD as u64 + start as u64 + p as u64;
        match whole {
            Whole::Yes => {
                self.s.chunks += 1;
                if p < records.len() {
                    let rest = &records[p..];
                    let msg = format!(
                        "a record in a chunk that runs past its end: the chunk's last {} bytes dropped",
                        rest.len()
                    );
                    let n = count_messages(rest);
                    self.lose(records_at + p as u64, rest.len() as u64, n, msg);
                }
                // Less what its records that were lost took.
                self.s.kept_bytes += total - (self.s.lost_bytes - lost_before);
                Ok(total)
            }
            Whole::Cut => {
                if p > 0 {
                    self.s.kept_bytes += kept;
                    Ok(kept)
                } else {
                    Ok(0)
                }
            }
        }
    }

    /// A chunk's records (and where they start in `body`), checked:
    /// uncompressed, whole, and their CRC right when the chunk is whole;
    /// None (the loss counted) when nothing of it can be taken.
    fn chunk_records<'b>(
        &mut self,
        offset: u64,
        body: &'b [u8],
        whole: Whole,
    ) -> Result<Option<(usize, &'b [u8])>, RecoverError> {
        let total = HEAD as u64 + body.len() as u64;
        let mut f = Fields::new(body);
        let parsed = (|| {
            f.take(8 + 8 + 8)?;
            let crc = f.u32()?;
            let compression = f.str()?;
            let size = f.u64()?;
            Ok::<_, String>((crc, compression, size))
        })();
        let (crc, compression, size) = match parsed {
            Ok(p) => p,
            Err(e) if whole == Whole::Yes => {
                self.lose(offset, total, 0, format!("chunk: {e}"));
                return Ok(None);
            }
            // Cut before its first record: nothing of it to take.
            Err(_) => return Ok(None),
        };
        if !compression.is_empty() {
            return Err(RecoverError::Input {
                file: self.name.clone(),
                offset,
                msg: format!(
                    "chunk compressed with {compression}: recover reads uncompressed chunks (the MCAP CLI's `mcap recover` reads compressed ones)"
                ),
            });
        }
        let start = f.pos;
        let records = &body[start..];
        let records = match usize::try_from(size) {
            Ok(n) if n <= records.len() => &records[..n],
            _ if whole == Whole::Yes => {
                let msg = format!(
                    "chunk: {size} bytes of records in a chunk with {} left",
                    records.len()
                );
                self.lose(offset, total, count_messages(records), msg);
                return Ok(None);
            }
            _ => records,
        };
        if whole == Whole::Yes && crc != 0 {
            let computed = crc32fast::hash(records);
            if computed != crc {
                let n = count_messages(records);
                let msg = format!(
                    "chunk CRC {computed:08x} is not the recorded {crc:08x}: its {} bytes and {n} messages dropped",
                    records.len()
                );
                self.lose(offset, total, n, msg);
                return Ok(None);
            }
        }
        Ok(Some((start, records)))
    }

    /// Carries the records of a chunk (at `records_at` in the input) in
    /// order; how many of its bytes were walked before one did not parse
    /// or the records ended.
    fn chunk_walk(
        &mut self,
        w: &mut Out,
        records: &[u8],
        records_at: u64,
        whole: Whole,
    ) -> Result<usize, RecoverError> {
        let mut p = 0usize;
        while p < records.len() {
            let mut r = Fields::new(&records[p..]);
            let whole_record = match (r.take(1), r.u64()) {
                (Ok(o), Ok(l)) => usize::try_from(l)
                    .ok()
                    .and_then(|n| r.take(n).ok())
                    .map(|rec| (o[0], rec)),
                _ => None,
            };
            let Some((opcode, rec)) = whole_record else {
                if whole == Whole::Cut && records[p] == op::MESSAGE {
                    // The message the cut fell in.
                    self.s.lost_messages += 1;
                }
                break;
            };
            if opcode == 0 {
                break;
            }
            if matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE)
                && !self.record(w, opcode, rec, records_at + p as u64, whole == Whole::Cut)?
                && whole == Whole::Cut
            {
                // In the chunk cut short, a record that does not parse is
                // where the bytes stop being what was written.
                break;
            }
            p += HEAD + rec.len();
        }
        Ok(p)
    }
}
