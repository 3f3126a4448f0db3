//! Finding MAVLink frames in received bytes, and saying what was dropped.
//!
//! The `mavlink` crate's readers skip a frame with a wrong CRC or an unknown
//! message id without a word; STATUS must count both, so framing is done
//! here and the crate gives the CRC, the CRC_EXTRA table and the payload
//! decoders. MAVLink 1 (0xFE) and 2 (0xFD) frames are read; a signed
//! MAVLink 2 frame's signature is checked by the task when signing is
//! configured (`signing`), from the frame's bytes.

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{calculate_crc, MavlinkVersion, Message};

const STX_V1: u8 = 0xFE;
const STX_V2: u8 = 0xFD;
const IFLAG_SIGNED: u8 = 0x01;
const SIGNATURE_LEN: usize = 13;
/// Room for any UDP datagram (at most 65 507 bytes), whole: a buffer of
/// 16 KiB cut a 64 KiB datagram's frames past it, counted nowhere (an
/// audit). A burst of serial or TCP bytes is read in such pieces too.
pub const CAPACITY: usize = 64 * 1024;

/// One CRC-valid frame of a known message.
#[derive(Debug, Clone, Copy)]
pub struct RawFrame<'a> {
    pub version: MavlinkVersion,
    pub seq: u8,
    pub system: u8,
    pub component: u8,
    pub msg_id: u32,
    pub payload: &'a [u8],
    /// The whole frame, start marker to signature.
    pub bytes: &'a [u8],
}

/// What the scanner found next.
#[derive(Debug)]
pub enum Scanned<'a> {
    Frame(RawFrame<'a>),
    /// A known message whose checksum does not match.
    BadCrc {
        msg_id: u32,
    },
    /// A message id the dialect does not have (its CRC cannot be checked).
    Unknown {
        msg_id: u32,
    },
    /// A MAVLink 2 frame with incompatibility flags this reader lacks.
    BadFlags,
}

/// Whether frame boundaries can be trusted beyond the checksum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// Each datagram holds whole frames of the dialect: the first
    /// candidate that fails (flags, an id the dialect lacks, its CRC) ends
    /// the datagram, whose rest is refused, and a partial frame at the end
    /// is dropped. A datagram of 0xFD bytes was a candidate at every byte,
    /// each refused and counted (issue 44: 300 a second held the daemon at
    /// 101 % CPU and counted 8 000 datagrams as 132 million frames).
    Datagram,
    /// A byte stream (serial): a candidate that fails its CRC is skipped by
    /// one byte, since a real frame may start inside it. The work stays
    /// linear: a candidate's CRC covers at most 264 bytes.
    Stream,
}

/// What the scanner did, for STATUS and for tests that bound its work.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ScanWork {
    /// Candidates looked at (a marker with enough bytes behind it).
    pub candidates: u64,
    /// Bytes the CRC went over.
    pub crc_bytes: u64,
    /// Datagrams ended by a candidate that failed.
    pub refused_datagrams: u64,
    /// Their bytes from that candidate on.
    pub refused_bytes: u64,
}

/// Incremental frame finder over a fixed buffer (allocated once).
pub struct Scanner {
    buf: Box<[u8]>,
    start: usize,
    end: usize,
    framing: Framing,
    garbage: u64,
    work: ScanWork,
}

/// A message the dialect knows. CRC_EXTRA is 0 for unknown ids, and also
/// for a few real ones, which the default-message table then tells apart.
#[inline]
fn extra_crc(msg_id: u32) -> Option<u8> {
    let e = MavMessage::extra_crc(msg_id);
    (e != 0 || MavMessage::default_message_from_id(msg_id).is_some()).then_some(e)
}

impl Scanner {
    pub fn new(framing: Framing) -> Self {
        Scanner {
            buf: vec![0; CAPACITY].into_boxed_slice(),
            start: 0,
            end: 0,
            framing,
            garbage: 0,
            work: ScanWork::default(),
        }
    }

    /// The work done so far.
    pub fn work(&self) -> ScanWork {
        self.work
    }

    /// The refused datagrams and bytes since the last call.
    pub fn take_refused(&mut self) -> (u64, u64) {
        let w = &mut self.work;
        (
            std::mem::take(&mut w.refused_datagrams),
            std::mem::take(&mut w.refused_bytes),
        )
    }

    /// Bytes skipped so far that were not part of any frame.
    pub fn garbage_bytes(&self) -> u64 {
        self.garbage
    }

    /// The garbage count since the last call.
    pub fn take_garbage(&mut self) -> u64 {
        std::mem::take(&mut self.garbage)
    }

    pub fn framing(&self) -> Framing {
        self.framing
    }

    /// Where to receive into. Never empty: consumed bytes are dropped first.
    pub fn spare(&mut self) -> &mut [u8] {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        if self.end == self.buf.len() {
            // Cannot happen with whole frames (at most 280 bytes); a
            // buffer full of undecidable bytes is dropped as garbage.
            self.garbage += self.end as u64;
            self.end = 0;
        }
        &mut self.buf[self.end..]
    }

    /// `n` bytes were received into [`Scanner::spare`].
    pub fn commit(&mut self, n: usize) {
        self.end = (self.end + n).min(self.buf.len());
    }

    /// Copy `bytes` in (for callers that already hold them).
    pub fn push(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(CAPACITY / 2) {
            let spare = self.spare();
            let n = chunk.len().min(spare.len());
            spare[..n].copy_from_slice(&chunk[..n]);
            self.commit(n);
        }
    }

    /// The end of a datagram: what is left is an incomplete frame, dropped
    /// and counted as garbage. Returns the number of bytes dropped.
    pub fn end_of_datagram(&mut self) -> usize {
        let n = self.end - self.start;
        self.garbage += n as u64;
        self.start = 0;
        self.end = 0;
        n
    }

    fn skip_to_marker(&mut self) -> bool {
        let avail = &self.buf[self.start..self.end];
        match avail.iter().position(|&b| b == STX_V2 || b == STX_V1) {
            Some(k) => {
                self.garbage += k as u64;
                self.start += k;
                true
            }
            None => {
                self.garbage += avail.len() as u64;
                self.start = 0;
                self.end = 0;
                false
            }
        }
    }

    /// A candidate at `start` failed: in a stream, skip `skip` bytes of
    /// it; in a datagram, the rest of the datagram is refused.
    fn failed(&mut self, skip: usize) {
        match self.framing {
            Framing::Stream => self.start += skip,
            Framing::Datagram => {
                self.work.refused_datagrams += 1;
                self.work.refused_bytes += (self.end - self.start) as u64;
                self.start = 0;
                self.end = 0;
            }
        }
    }

    /// The next frame or dropped candidate, or `None` when more bytes are
    /// needed.
    pub fn next_frame(&mut self) -> Option<Scanned<'_>> {
        if !self.skip_to_marker() {
            return None;
        }
        let c = &self.buf[self.start..self.end];
        if c.len() < 3 {
            return None;
        }
        self.work.candidates += 1;
        let v2 = c[0] == STX_V2;
        let (header, signature) = if v2 {
            if c[2] & !IFLAG_SIGNED != 0 {
                self.failed(1);
                return Some(Scanned::BadFlags);
            }
            (
                10,
                if c[2] & IFLAG_SIGNED != 0 {
                    SIGNATURE_LEN
                } else {
                    0
                },
            )
        } else {
            (6, 0)
        };
        let len = c[1] as usize;
        let total = header + len + 2 + signature;
        if c.len() < total {
            return None;
        }
        let msg_id = if v2 {
            u32::from_le_bytes([c[7], c[8], c[9], 0])
        } else {
            c[5] as u32
        };
        // A candidate that cannot be checked or fails its check ends a
        // datagram; in a stream it is skipped by one byte, since it may be
        // line noise with a real frame starting inside it.
        let Some(extra) = extra_crc(msg_id) else {
            self.failed(1);
            return Some(Scanned::Unknown { msg_id });
        };
        self.work.crc_bytes += (header + len - 1) as u64;
        let crc = calculate_crc(&c[1..header + len], extra);
        if crc != u16::from_le_bytes([c[header + len], c[header + len + 1]]) {
            self.failed(1);
            return Some(Scanned::BadCrc { msg_id });
        }
        let at = self.start;
        self.start += total;
        let c = &self.buf[at..at + total];
        let (seq, system, component) = if v2 {
            (c[4], c[5], c[6])
        } else {
            (c[2], c[3], c[4])
        };
        Some(Scanned::Frame(RawFrame {
            version: if v2 {
                MavlinkVersion::V2
            } else {
                MavlinkVersion::V1
            },
            seq,
            system,
            component,
            msg_id,
            payload: &c[header..header + len],
            bytes: c,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{ATTITUDE_DATA, SYS_STATUS_DATA};
    use mavlink::{MAVLinkV2MessageRaw, MavHeader};

    fn frame(msg: &MavMessage, seq: u8) -> Vec<u8> {
        let mut raw = MAVLinkV2MessageRaw::new();
        let h = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        };
        raw.serialize_message(h, msg);
        raw.raw_bytes().to_vec()
    }

    fn attitude(pitch: f32) -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            pitch,
            ..Default::default()
        })
    }

    fn ids(s: &mut Scanner) -> Vec<String> {
        let mut out = Vec::new();
        while let Some(e) = s.next_frame() {
            out.push(match e {
                Scanned::Frame(f) => format!("{}@{}", f.msg_id, f.seq),
                Scanned::BadCrc { msg_id } => format!("crc{msg_id}"),
                Scanned::Unknown { msg_id } => format!("unknown{msg_id}"),
                Scanned::BadFlags => "flags".into(),
            });
        }
        out
    }

    #[test]
    fn frames_split_anywhere_in_a_stream_are_found() {
        let mut bytes = vec![0x55, 0x00, 0x13];
        bytes.extend(frame(&attitude(0.1), 7));
        bytes.extend(frame(
            &MavMessage::SYS_STATUS(SYS_STATUS_DATA::default()),
            8,
        ));
        for cut in 1..bytes.len() {
            let mut s = Scanner::new(Framing::Stream);
            let mut got = Vec::new();
            for part in [&bytes[..cut], &bytes[cut..]] {
                s.push(part);
                got.extend(ids(&mut s));
            }
            assert_eq!(got, ["30@7", "1@8"], "cut at {cut}");
            assert_eq!(s.garbage_bytes(), 3);
        }
    }

    #[test]
    fn wrong_crc_and_unknown_ids_are_reported_not_hidden() {
        let mut bad = frame(&attitude(0.2), 1);
        let n = bad.len();
        bad[n - 1] ^= 0xFF;
        let mut unknown = frame(&attitude(0.2), 2);
        unknown[7..10].copy_from_slice(&[0x21, 0x43, 0x0F]); // id 0x0F4321
        let mut s = Scanner::new(Framing::Datagram);
        for d in [&bad, &unknown, &frame(&attitude(0.3), 3)] {
            s.push(d);
            let got = ids(&mut s);
            s.end_of_datagram();
            match d[4] {
                1 => assert_eq!(got, ["crc30"]),
                2 => assert_eq!(got, [format!("unknown{}", 0x0F4321)]),
                _ => assert_eq!(got, ["30@3"]),
            }
        }
        assert_eq!(s.garbage_bytes(), 0);
    }

    #[test]
    fn noise_that_looks_like_an_unknown_message_does_not_hide_a_frame_in_a_stream() {
        // Line noise: a v2 start byte, a length of 40 and an id no dialect
        // has, so the candidate spans the real frame that follows.
        let mut bytes = vec![0xFD, 40, 0, 0, 0, 1, 1, 0x21, 0x43, 0x0F];
        bytes.extend(frame(&attitude(0.1), 9));
        bytes.extend([0u8; 40]);
        let mut s = Scanner::new(Framing::Stream);
        s.push(&bytes);
        let got = ids(&mut s);
        assert!(got.contains(&"30@9".to_string()), "{got:?}");
        assert_eq!(got[0], format!("unknown{}", 0x0F4321));
    }

    #[test]
    fn a_truncated_datagram_is_garbage() {
        let f = frame(&attitude(0.2), 1);
        let mut s = Scanner::new(Framing::Datagram);
        s.push(&f[..f.len() - 3]);
        assert!(s.next_frame().is_none());
        assert_eq!(s.end_of_datagram(), f.len() - 3);
    }

    /// Issue 44: a datagram of 0xFD bytes was a candidate at every byte
    /// (65 507 refusals, and a CRC of up to 264 bytes for many). Now its first
    /// candidate fails and ends it: one refusal, one refused datagram of
    /// all its bytes, no CRC.
    #[test]
    fn a_datagram_of_start_bytes_is_one_refused_datagram() {
        let n = 65_507;
        let mut s = Scanner::new(Framing::Datagram);
        s.push(&vec![0xFD; n]);
        assert_eq!(ids(&mut s), ["flags"]);
        s.end_of_datagram();
        let w = s.work();
        assert_eq!((w.candidates, w.crc_bytes), (1, 0), "{w:?}");
        assert_eq!((w.refused_datagrams, w.refused_bytes), (1, n as u64));
        assert_eq!(s.garbage_bytes(), 0);
        // Start bytes with valid flags and a length: the CRC is computed
        // once, over the first candidate, and the datagram ends there.
        let mut d = vec![0xFD, 0xFF, 0x00, 0, 0, 1, 1, 30, 0, 0];
        d.resize(n, 0xFD);
        let mut s = Scanner::new(Framing::Datagram);
        s.push(&d);
        assert_eq!(ids(&mut s), ["crc30"]);
        let w = s.work();
        assert_eq!((w.candidates, w.crc_bytes), (1, 9 + 255), "{w:?}");
        assert_eq!(s.take_refused(), (1, n as u64));
        assert_eq!(s.take_refused(), (0, 0));
    }

    /// A frame that fails ends its datagram: the frames after it in the
    /// same datagram are refused with it (counted, not read).
    #[test]
    fn a_bad_frame_ends_its_datagram_and_the_next_datagram_is_read() {
        let good = frame(&attitude(0.1), 1);
        let mut bad = frame(&attitude(0.2), 2);
        let n = bad.len();
        bad[n - 1] ^= 0xFF;
        let mut s = Scanner::new(Framing::Datagram);
        s.push(&[good.clone(), bad.clone(), good.clone()].concat());
        assert_eq!(ids(&mut s), ["30@1", "crc30"]);
        s.end_of_datagram();
        assert_eq!(s.take_refused(), (1, (bad.len() + good.len()) as u64));
        s.push(&good);
        assert_eq!(ids(&mut s), ["30@1"]);
    }

    proptest::proptest! {
        /// Any datagram costs work linear in its length: each candidate
        /// either is a frame (at least 8 bytes consumed, a bare MAVLink 1 one) or ends the
        /// datagram, and the CRC goes over each byte at most once.
        #[test]
        fn a_datagram_costs_work_linear_in_its_length(
            bytes in proptest::collection::vec(
                proptest::prop_oneof![
                    3 => proptest::prelude::Just(0xFDu8),
                    1 => proptest::prelude::Just(0xFEu8),
                    4 => proptest::prelude::any::<u8>(),
                ],
                0..4096,
            ),
            frames in 0usize..4,
        ) {
            let mut d = frame(&attitude(0.3), 0).repeat(frames);
            d.extend(&bytes);
            let mut s = Scanner::new(Framing::Datagram);
            s.push(&d);
            let got = ids(&mut s);
            s.end_of_datagram();
            let w = s.work();
            proptest::prop_assert!(w.candidates as usize <= d.len() / 8 + 1, "{w:?}");
            proptest::prop_assert!(w.crc_bytes as usize <= d.len(), "{w:?}");
            proptest::prop_assert!(w.refused_datagrams <= 1);
            proptest::prop_assert!(got.len() >= frames);
        }

        /// A stream resyncs byte by byte, and stays linear: at most one
        /// candidate per byte and a CRC of at most 264 bytes each.
        #[test]
        fn a_stream_costs_work_linear_in_its_length(
            bytes in proptest::collection::vec(
                proptest::prop_oneof![
                    3 => proptest::prelude::Just(0xFDu8),
                    4 => proptest::prelude::any::<u8>(),
                ],
                0..4096,
            ),
        ) {
            let mut s = Scanner::new(Framing::Stream);
            s.push(&bytes);
            ids(&mut s);
            let w = s.work();
            proptest::prop_assert!(w.candidates as usize <= bytes.len(), "{w:?}");
            proptest::prop_assert!(w.crc_bytes <= 264 * w.candidates, "{w:?}");
            proptest::prop_assert_eq!(w.refused_datagrams, 0);
        }
    }
}
