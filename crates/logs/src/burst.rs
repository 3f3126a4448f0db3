//! The binary message of `/lightpose/burst` (spec v3): a BURST's raw
//! samples as little-endian u16 beside the rest of its line as JSON
//! ([`crate::schema::BURST_LAYOUT`]). Why binary: a BURST line spends
//! 3–5 bytes of text per sample, a u16 two, and at 8 kHz × 25 channels the
//! samples are nearly all of a recording.
//!
//! Exact: the message keeps the line's own text but for its samples, and
//! where they were cut out, so the line is rebuilt byte for byte (JSONL →
//! MCAP → JSONL gives back the same file). A line whose samples are not
//! written as core writes them (spaces, say) is kept whole in `side`, its
//! samples in binary all the same. Buffers are the caller's and reused:
//! once warm, neither way allocates.

use lightpose_core::{Burst, NDET};
use std::io::Write;

const MAGIC: &[u8; 4] = b"LPB1";
/// Bytes before `side`.
pub const HEAD_BYTES: usize = 34;
const KEY: &[u8] = b"\"samples\":";

/// How the line is made from `side` and the samples.
const CUT_KEY_COMMA: u8 = 0;
const CUT_COMMA_KEY: u8 = 1;
const CUT_WHOLE: u8 = 2;

/// `"samples":` and the samples as JSON, as core's `LogWriter` writes them
/// (`[[1,2],[3,4],...]`), appended to `out`.
fn write_samples(samples: &[u16], n: usize, out: &mut Vec<u8>) {
    out.extend_from_slice(KEY);
    out.push(b'[');
    for k in 0..NDET {
        if k > 0 {
            out.push(b',');
        }
        out.push(b'[');
        for (i, v) in samples[k * n..(k + 1) * n].iter().enumerate() {
            if i > 0 {
                out.push(b',');
            }
            // Writing into a Vec cannot fail.
            let _ = write!(out, "{v}");
        }
        out.push(b']');
    }
    out.push(b']');
}

/// The message of burst `b`, whose line (without its newline) is `line`,
/// into `out` (cleared first); `scratch` is a reused buffer.
pub fn encode(b: &Burst, line: &[u8], out: &mut Vec<u8>, scratch: &mut Vec<u8>) {
    let n = b.n();
    scratch.clear();
    write_samples(b.samples(), n, scratch);
    // Where the samples are, as core writes them (a nested "samples" of
    // the same text would be cut and put back at the same place: exact
    // either way).
    let found = (0..line.len().saturating_sub(scratch.len() - 1))
        .find(|&p| line[p] == b'"' && line[p..].starts_with(scratch));
    let (cut, at, keep) = match found {
        Some(p) if line.get(p + scratch.len()) == Some(&b',') => {
            (CUT_KEY_COMMA, p, (p, p + scratch.len() + 1))
        }
        Some(p) if p > 0 && line[p - 1] == b',' => {
            (CUT_COMMA_KEY, p - 1, (p - 1, p + scratch.len()))
        }
        _ => (CUT_WHOLE, 0, (line.len(), line.len())),
    };
    let side_len = line.len() - (keep.1 - keep.0);
    out.clear();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&b.seq.to_le_bytes());
    out.extend_from_slice(&b.t.to_le_bytes());
    out.extend_from_slice(&(NDET as u16).to_le_bytes());
    out.extend_from_slice(&(n as u16).to_le_bytes());
    out.push(b.adc_bits);
    out.push(cut);
    out.extend_from_slice(&(at as u32).to_le_bytes());
    out.extend_from_slice(&(side_len as u32).to_le_bytes());
    out.extend_from_slice(&line[..keep.0]);
    out.extend_from_slice(&line[keep.1..]);
    for v in b.samples() {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// The fields of a message's head.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Head {
    pub seq: u64,
    pub t: f64,
    pub channels: usize,
    pub n: usize,
    pub adc_bits: u8,
    cut: u8,
    at: usize,
    side_len: usize,
}

/// A message's head, checked against its length.
pub fn head(msg: &[u8]) -> Result<Head, String> {
    if msg.len() < HEAD_BYTES || &msg[..4] != MAGIC {
        return Err(format!(
            "a {} message that is not one ({} bytes, no LPB1 magic)",
            crate::schema::topic::BURST,
            msg.len()
        ));
    }
    let u16_at = |i: usize| u16::from_le_bytes([msg[i], msg[i + 1]]) as usize;
    let u32_at =
        |i: usize| u32::from_le_bytes([msg[i], msg[i + 1], msg[i + 2], msg[i + 3]]) as usize;
    let mut w = [0u8; 8];
    w.copy_from_slice(&msg[4..12]);
    let seq = u64::from_le_bytes(w);
    w.copy_from_slice(&msg[12..20]);
    let t = f64::from_le_bytes(w);
    let h = Head {
        seq,
        t,
        channels: u16_at(20),
        n: u16_at(22),
        adc_bits: msg[24],
        cut: msg[25],
        at: u32_at(26),
        side_len: u32_at(30),
    };
    if h.channels != NDET {
        return Err(format!(
            "burst seq {seq}: {} channels, not {NDET}",
            h.channels
        ));
    }
    let want = HEAD_BYTES as u64 + h.side_len as u64 + 2 * (h.channels * h.n) as u64;
    if msg.len() as u64 != want {
        return Err(format!(
            "burst seq {seq}: {} bytes, its head says {want}",
            msg.len()
        ));
    }
    if h.cut > CUT_WHOLE || h.at > h.side_len {
        return Err(format!(
            "burst seq {seq}: cut {} at {} of a side of {} bytes",
            h.cut, h.at, h.side_len
        ));
    }
    Ok(h)
}

/// The BURST line of message `msg` (without a newline) into `line`
/// (cleared first); `samples` is a reused buffer.
pub fn decode_line(msg: &[u8], line: &mut Vec<u8>, samples: &mut Vec<u16>) -> Result<Head, String> {
    let h = head(msg)?;
    let side = &msg[HEAD_BYTES..HEAD_BYTES + h.side_len];
    line.clear();
    if h.cut == CUT_WHOLE {
        line.extend_from_slice(side);
        return Ok(h);
    }
    samples.clear();
    samples.extend(
        msg[HEAD_BYTES + h.side_len..]
            .chunks_exact(2)
            .map(|p| u16::from_le_bytes([p[0], p[1]])),
    );
    line.extend_from_slice(&side[..h.at]);
    if h.cut == CUT_COMMA_KEY {
        line.push(b',');
    }
    write_samples(samples, h.n, line);
    if h.cut == CUT_KEY_COMMA {
        line.push(b',');
    }
    line.extend_from_slice(&side[h.at..]);
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{LogHeader, LogReader, LogWriter, Record};

    fn burst(n: usize, seq: u64) -> Burst {
        let mut b = Burst::new(n);
        for (i, v) in b.samples_mut().iter_mut().enumerate() {
            *v = ((i * 37 + seq as usize * 11) % 1024) as u16;
        }
        b.seq = seq;
        b.t = 0.05 * seq as f64;
        b.adc_bits = 10;
        b
    }

    fn line_of(b: &Burst) -> Vec<u8> {
        let mut w = LogWriter::new(Vec::new(), &LogHeader::new(10, 20.0)).unwrap();
        w.get_mut().clear();
        w.write_burst(b).unwrap();
        let mut l = w.into_inner();
        l.pop();
        l
    }

    #[test]
    fn lines_come_back_byte_for_byte() {
        let (mut msg, mut scratch, mut back, mut s) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut b = burst(100, 3);
        // Samples last (cut 1), then with fields after them (cut 0).
        for with_temp in [false, true] {
            b.temp_c = with_temp.then_some(12.5);
            let line = line_of(&b);
            encode(&b, &line, &mut msg, &mut scratch);
            assert_eq!(msg[25], if with_temp { 0 } else { 1 });
            // The side is the object without its samples: JSON.
            let h = head(&msg).unwrap();
            let side: serde_json::Value =
                serde_json::from_slice(&msg[HEAD_BYTES..HEAD_BYTES + h.side_len]).unwrap();
            assert_eq!(side["seq"], 3);
            assert!(side.get("samples").is_none());
            assert_eq!(msg.len(), HEAD_BYTES + h.side_len + 2 * 25 * 100);
            decode_line(&msg, &mut back, &mut s).unwrap();
            assert_eq!(back, line);
        }
        // A line written by hand, spaces in its samples: kept whole.
        let line = String::from_utf8(line_of(&b))
            .unwrap()
            .replace("],[", "], [");
        encode(&b, line.as_bytes(), &mut msg, &mut scratch);
        assert_eq!(msg[25], 2);
        decode_line(&msg, &mut back, &mut s).unwrap();
        assert_eq!(back, line.as_bytes());
        // What it rebuilds reads as the same burst.
        let text = format!("{{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":20.0,\"sample_hz\":2000.0,\"beacons\":[{{\"id\":\"b\",\"mod_hz\":200.0}}]}}\n{}\n", String::from_utf8(back.clone()).unwrap());
        let mut r = LogReader::new(text.as_bytes(), "t").unwrap();
        match r.next_record() {
            Some(Ok(Record::Burst(got))) => assert_eq!(got.samples(), b.samples()),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn damaged_messages_are_refused() {
        let (mut msg, mut scratch, mut back, mut s) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let b = burst(8, 1);
        encode(&b, &line_of(&b), &mut msg, &mut scratch);
        assert!(decode_line(&msg[..msg.len() - 1], &mut back, &mut s).is_err());
        assert!(decode_line(&msg[..10], &mut back, &mut s).is_err());
        let mut bad = msg.clone();
        bad[26..30].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode_line(&bad, &mut back, &mut s)
            .unwrap_err()
            .contains("cut"));
        let mut bad = msg.clone();
        bad[0] = b'X';
        assert!(decode_line(&bad, &mut back, &mut s).is_err());
    }
}
