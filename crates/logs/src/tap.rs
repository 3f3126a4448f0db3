//! A line source that keeps the line it served last, so that a conversion
//! can carry a log's lines as they are: parsing a FRAME and writing it
//! again does not always give the same text (core keeps angles in radians,
//! and degrees → radians → degrees may move the last digit).
//!
//! Lines are taken in pieces of at most core's bound and one byte
//! ([`MAX_LINE_BYTES`] + 1): a line that long is refused by core's
//! `read_line_bounded`, which reads the rest of it piece by piece and
//! throws it away, so that a 200 MB line is never held whole here either.

use lightpose_core::log::MAX_LOG_LINE_BYTES;
use std::io::{self, BufRead, Read};

pub struct LineTap<R> {
    src: R,
    line: Vec<u8>,
    pos: usize,
}

impl<R: BufRead> LineTap<R> {
    pub fn new(src: R) -> Self {
        LineTap {
            src,
            line: Vec::new(),
            pos: 0,
        }
    }

    /// The line served last, with its newline if it had one.
    pub fn line(&self) -> &[u8] {
        &self.line
    }
}

impl<R: BufRead> Read for LineTap<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let avail = self.fill_buf()?;
        let n = avail.len().min(buf.len());
        buf[..n].copy_from_slice(&avail[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl<R: BufRead> BufRead for LineTap<R> {
    fn fill_buf(&mut self) -> io::Result<&[u8]> {
        if self.pos >= self.line.len() {
            // At the end the last line stays what `line` gives: a log whose
            // last line has no newline is asked once more for a newline
            // after it, and that look must not take the line away (its
            // frame was converted as an empty message).
            if self.src.fill_buf()?.is_empty() {
                return Ok(&[]);
            }
            self.line.clear();
            self.pos = 0;
            (&mut self.src)
                .take(MAX_LOG_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut self.line)?;
        }
        Ok(&self.line[self.pos..])
    }

    fn consume(&mut self, n: usize) {
        self.pos = (self.pos + n).min(self.line.len());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_line_stays_after_the_end_is_seen() {
        for text in ["a\nlast", "a\nlast\n", "a\r\nlast\r\n"] {
            let mut t = LineTap::new(text.as_bytes());
            let mut s = String::new();
            while t.read_line(&mut s).expect("read") > 0 {}
            assert!(t.line().starts_with(b"last"), "{text:?}: {:?}", t.line());
            assert_eq!(s, text);
        }
    }
}
