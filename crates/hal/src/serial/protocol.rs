//! The `$LPADC` line protocol of the serial ADC boards
//! (docs/serial-protocol.md): a pure parser and a line assembler, apart from
//! any port so that every malformed input can be tested byte by byte.
//!
//! `$LPADC,<board>,<seq>,<bits>,<v0>,...,<vN>*<XOR hex>\r\n`

use crate::chanmap::MAX_CH;

/// Longest line accepted (16 five-digit values plus header is ~130 bytes).
pub const MAX_LINE: usize = 200;
const TALKER: &[u8] = b"LPADC";

/// One parsed line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    pub board: u8,
    pub seq: u32,
    pub bits: u8,
    /// Number of values in `values`.
    pub n: u8,
    pub values: [u16; MAX_CH],
}

/// Why a line was rejected; every variant says where.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LineError {
    #[error("no '$' start")]
    NoStart,
    #[error("no '*' checksum delimiter")]
    NoChecksum,
    #[error("checksum is not two hex digits")]
    BadChecksumField,
    #[error("checksum mismatch: line says {given:02X}, computed {computed:02X}")]
    Checksum { given: u8, computed: u8 },
    #[error("not an LPADC sentence")]
    WrongTalker,
    #[error("field {field} ({name}) is missing or not a number in range")]
    Field { field: usize, name: &'static str },
    #[error("bits {0} outside 1..=16")]
    Bits(u8),
    #[error("no channel values")]
    NoValues,
    #[error("more than {MAX_CH} channel values")]
    TooManyValues,
    #[error("channel {ch} value {value} exceeds {bits}-bit full scale")]
    ValueRange { ch: u8, value: u32, bits: u8 },
    #[error("line longer than {MAX_LINE} bytes")]
    TooLong,
}

/// XOR of the bytes between '$' and '*', as in NMEA 0183.
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |a, b| a ^ b)
}

fn hex(d: u8) -> Option<u8> {
    match d {
        b'0'..=b'9' => Some(d - b'0'),
        b'a'..=b'f' => Some(d - b'a' + 10),
        b'A'..=b'F' => Some(d - b'A' + 10),
        _ => None,
    }
}

/// Decimal, digits only, no sign, fits in u32.
fn number(f: &[u8]) -> Option<u32> {
    if f.is_empty() || f.len() > 10 {
        return None;
    }
    let mut v: u64 = 0;
    for &d in f {
        if !d.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (d - b'0') as u64;
    }
    u32::try_from(v).ok()
}

/// Parse one line (with or without its `\r\n`). Bytes before the last '$'
/// are ignored, so that a line glued to boot noise still parses.
pub fn parse_line(line: &[u8]) -> Result<Sample, LineError> {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    let start = line
        .iter()
        .rposition(|&b| b == b'$')
        .ok_or(LineError::NoStart)?;
    let s = &line[start + 1..];
    let star = s
        .iter()
        .rposition(|&b| b == b'*')
        .ok_or(LineError::NoChecksum)?;
    let (body, ck) = (&s[..star], &s[star + 1..]);
    let given = match ck {
        [h, l] => match (hex(*h), hex(*l)) {
            (Some(h), Some(l)) => (h << 4) | l,
            _ => return Err(LineError::BadChecksumField),
        },
        _ => return Err(LineError::BadChecksumField),
    };
    let computed = checksum(body);
    if given != computed {
        return Err(LineError::Checksum { given, computed });
    }
    let mut fields = body.split(|&b| b == b',');
    if fields.next() != Some(TALKER) {
        return Err(LineError::WrongTalker);
    }
    let mut head = |field: usize, name: &'static str, max: u32| {
        fields
            .next()
            .and_then(number)
            .filter(|&v| v <= max)
            .ok_or(LineError::Field { field, name })
    };
    let board = head(1, "board", 255)? as u8;
    let seq = head(2, "seq", u32::MAX)?;
    let bits = head(3, "bits", 255)? as u8;
    if !(1..=16).contains(&bits) {
        return Err(LineError::Bits(bits));
    }
    let fs = (1u32 << bits) - 1;
    let mut values = [0u16; MAX_CH];
    let mut n = 0usize;
    for (i, f) in fields.enumerate() {
        if n == MAX_CH {
            return Err(LineError::TooManyValues);
        }
        let v = number(f).ok_or(LineError::Field {
            field: 4 + i,
            name: "value",
        })?;
        if v > fs {
            return Err(LineError::ValueRange {
                ch: i as u8,
                value: v,
                bits,
            });
        }
        values[n] = v as u16;
        n += 1;
    }
    if n == 0 {
        return Err(LineError::NoValues);
    }
    Ok(Sample {
        board,
        seq,
        bits,
        n: n as u8,
        values,
    })
}

/// Format a line into `out` (for tests, benches and simulators of a board);
/// returns its length.
pub fn format_line(board: u8, seq: u32, bits: u8, values: &[u16], out: &mut Vec<u8>) {
    use std::io::Write;
    let start = out.len();
    // writing to a Vec cannot fail
    let _ = write!(out, "$LPADC,{board},{seq},{bits}");
    for v in values {
        let _ = write!(out, ",{v}");
    }
    let ck = checksum(&out[start + 1..]);
    let _ = write!(out, "*{ck:02X}\r\n");
}

/// Splits a byte stream into lines without allocating: bytes go in, each
/// complete line comes out through a callback. A line longer than
/// [`MAX_LINE`] is dropped whole and reported as [`LineError::TooLong`].
#[derive(Debug, Clone)]
pub struct LineAssembler {
    buf: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
}

impl Default for LineAssembler {
    fn default() -> Self {
        LineAssembler {
            buf: [0; MAX_LINE],
            len: 0,
            overflow: false,
        }
    }
}

impl LineAssembler {
    /// Forget a partial line (the port was reopened).
    pub fn clear(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// Feed bytes; `on_line` gets each complete line, `\r\n` stripped, or
    /// the error of an overlong one. Empty lines are skipped silently.
    pub fn push(&mut self, bytes: &[u8], mut on_line: impl FnMut(Result<&[u8], LineError>)) {
        for &b in bytes {
            if b == b'\n' {
                if self.overflow {
                    on_line(Err(LineError::TooLong));
                } else {
                    let mut l = &self.buf[..self.len];
                    if let Some(s) = l.strip_suffix(b"\r") {
                        l = s;
                    }
                    if !l.is_empty() {
                        on_line(Ok(l));
                    }
                }
                self.clear();
            } else if self.len < MAX_LINE {
                self.buf[self.len] = b;
                self.len += 1;
            } else {
                self.overflow = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(board: u8, seq: u32, bits: u8, v: &[u16]) -> Vec<u8> {
        let mut out = Vec::new();
        format_line(board, seq, bits, v, &mut out);
        out
    }

    #[test]
    fn documented_example_line_parses() {
        // the example in docs/serial-protocol.md
        let l = b"$LPADC,1,42,10,512,0,1023,7*71\r\n";
        assert_eq!(checksum(b"LPADC,1,42,10,512,0,1023,7"), 0x71);
        let s = parse_line(l).unwrap();
        assert_eq!((s.board, s.seq, s.bits, s.n), (1, 42, 10, 4));
        assert_eq!(&s.values[..4], &[512, 0, 1023, 7]);
    }

    #[test]
    fn round_trip_and_lowercase_checksum_and_no_crlf() {
        let l = line(3, u32::MAX, 12, &[4095, 1, 2, 3, 4, 5, 6, 7]);
        let s = parse_line(&l).unwrap();
        assert_eq!((s.board, s.seq, s.n), (3, u32::MAX, 8));
        let text = String::from_utf8(l).unwrap();
        let lower = text.trim_end().to_lowercase().replace("lpadc", "LPADC");
        assert_eq!(parse_line(lower.as_bytes()).unwrap(), s);
        let full16 = line(0, 0, 16, &[65535; 16]);
        assert_eq!(parse_line(&full16).unwrap().n, 16);
    }

    #[test]
    fn leading_noise_is_skipped() {
        let mut l = b"\x00\xffboot v1.2 $$".to_vec();
        l.extend(line(0, 5, 10, &[1, 2]));
        assert_eq!(parse_line(&l).unwrap().seq, 5);
    }

    #[test]
    fn every_malformation_has_its_error() {
        use LineError::*;
        let ck = |body: &str| format!("${body}*{:02X}", checksum(body.as_bytes()));
        assert_eq!(parse_line(b"LPADC,1,2,10,5*00"), Err(NoStart));
        assert_eq!(parse_line(b"$LPADC,1,2,10,5"), Err(NoChecksum));
        assert_eq!(parse_line(b"$LPADC,1,2,10,5*G1"), Err(BadChecksumField));
        assert_eq!(parse_line(b"$LPADC,1,2,10,5*1"), Err(BadChecksumField));
        let good = ck("LPADC,1,2,10,5");
        let bad = good.replace(",5*", ",6*");
        assert!(matches!(parse_line(bad.as_bytes()), Err(Checksum { .. })));
        assert_eq!(
            parse_line(ck("GPGGA,1,2,10,5").as_bytes()),
            Err(WrongTalker)
        );
        assert_eq!(
            parse_line(ck("LPADC,256,2,10,5").as_bytes()),
            Err(Field {
                field: 1,
                name: "board"
            })
        );
        assert_eq!(
            parse_line(ck("LPADC,1,-2,10,5").as_bytes()),
            Err(Field {
                field: 2,
                name: "seq"
            })
        );
        assert_eq!(
            parse_line(ck("LPADC,1,99999999999,10,5").as_bytes()),
            Err(Field {
                field: 2,
                name: "seq"
            })
        );
        assert_eq!(parse_line(ck("LPADC,1,2,17,5").as_bytes()), Err(Bits(17)));
        assert_eq!(parse_line(ck("LPADC,1,2,0,5").as_bytes()), Err(Bits(0)));
        assert_eq!(
            parse_line(ck("LPADC,1,2").as_bytes()),
            Err(Field {
                field: 3,
                name: "bits"
            })
        );
        assert_eq!(parse_line(ck("LPADC,1,2,10").as_bytes()), Err(NoValues));
        assert_eq!(
            parse_line(ck("LPADC,1,2,10,5,,7").as_bytes()),
            Err(Field {
                field: 5,
                name: "value"
            })
        );
        assert_eq!(
            parse_line(ck("LPADC,1,2,10,5, 7").as_bytes()),
            Err(Field {
                field: 5,
                name: "value"
            })
        );
        assert_eq!(
            parse_line(ck("LPADC,1,2,10,1024").as_bytes()),
            Err(ValueRange {
                ch: 0,
                value: 1024,
                bits: 10
            })
        );
        let many = format!("LPADC,1,2,10{}", ",1".repeat(17));
        assert_eq!(parse_line(ck(&many).as_bytes()), Err(TooManyValues));
        assert_eq!(parse_line(b""), Err(NoStart));
    }

    #[test]
    fn assembler_joins_split_lines_and_drops_overlong_ones() {
        let mut a = LineAssembler::default();
        let l1 = line(0, 1, 10, &[1, 2, 3]);
        let l2 = line(0, 2, 10, &[4, 5, 6]);
        let mut stream = l1.clone();
        stream.extend(b"\r\n\n"); // empty lines are skipped
        stream.extend(vec![b'x'; MAX_LINE + 10]);
        stream.push(b'\n');
        stream.extend(&l2);
        let mut got: Vec<Result<u32, LineError>> = Vec::new();
        // feed in awkward chunks: 1 byte, then 7, then the rest
        for chunk in [&stream[..1], &stream[1..8], &stream[8..]] {
            a.push(chunk, |r| got.push(r.and_then(parse_line).map(|s| s.seq)));
        }
        assert_eq!(got, vec![Ok(1), Err(LineError::TooLong), Ok(2)]);
        // a partial line waits for its end
        a.push(&l1[..10], |_| panic!("no line yet"));
        a.clear();
        let mut n = 0;
        a.push(&l2, |r| {
            assert_eq!(r.and_then(parse_line).map(|s| s.seq), Ok(2));
            n += 1;
        });
        assert_eq!(n, 1);
    }
}
