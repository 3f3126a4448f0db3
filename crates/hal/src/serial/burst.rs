//! The LPBST burst packet of the serial ADC boards (docs/serial-protocol.md,
//! "Bursts"): blocks of samples for a blinking beacon, which a `$LPADC`
//! text line per sample cannot carry (16 values of 12 bits at 2 kHz as
//! text are ~200 kB/s; 115 200 baud moves 11.5 kB/s). A pure encoder,
//! decoder and stream assembler, apart from any port, so that every
//! malformed input can be tested byte by byte.
//!
//! A packet is little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 2 | sync `0xA5 0x5A` |
//! | 1 | version, 1 |
//! | 1 | board id |
//! | 1 | bits, 1..=16 |
//! | 1 | channels C, 1..=16 |
//! | 2 | K, samples in the block, 1..=[`MAX_BLOCK`] |
//! | 4 | index of the block's first sample (+K a block, wraps at 2³²) |
//! | P | K·C values of `bits` bits, sample after sample, LSB first, the last byte padded with 0: P = ⌈K·C·bits / 8⌉ |
//! | 2 | CRC-16/CCITT-FALSE of every byte after the sync and before the CRC |

use crate::chanmap::MAX_CH;

/// The packet's first two bytes.
pub const SYNC: [u8; 2] = [0xA5, 0x5A];
pub const VERSION: u8 = 1;
/// Header bytes after the sync and before the payload.
pub const HEADER: usize = 10;
/// Sync, header and CRC: what a packet costs beyond its samples.
pub const OVERHEAD: usize = SYNC.len() + HEADER + 2;
/// Most samples a block may hold: 64 samples of 16 channels of 16 bits
/// is a 2 kB payload, what the assembler keeps.
pub const MAX_BLOCK: usize = 64;
/// The largest packet.
pub const MAX_PACKET: usize = OVERHEAD + MAX_BLOCK * MAX_CH * 2;

/// One decoded block.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Block {
    pub board: u8,
    pub bits: u8,
    pub channels: u8,
    /// K: samples in `values`.
    pub samples: u16,
    /// Index of the first sample.
    pub first: u32,
    /// Sample i's channel c at `i * MAX_CH + c` (fixed size: no heap).
    pub values: [u16; MAX_BLOCK * MAX_CH],
}

impl Default for Block {
    fn default() -> Self {
        Block {
            board: 0,
            bits: 0,
            channels: 0,
            samples: 0,
            first: 0,
            values: [0; MAX_BLOCK * MAX_CH],
        }
    }
}

impl Block {
    /// Sample `i`'s values, channel 0 first.
    pub fn sample(&self, i: usize) -> &[u16] {
        let c = self.channels as usize;
        &self.values[i * MAX_CH..i * MAX_CH + c]
    }
    /// The index of the block's last sample.
    pub fn last(&self) -> u32 {
        self.first
            .wrapping_add(u32::from(self.samples).saturating_sub(1))
    }
}

/// Why bytes were thrown away; every variant says what was wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PacketError {
    #[error("bytes outside a packet (no sync 0xA5 0x5A)")]
    Garbage,
    #[error("packet version {0}, this reader takes {VERSION}")]
    Version(u8),
    #[error("packet header: {name} = {value} outside {range}")]
    Header {
        name: &'static str,
        value: u16,
        range: &'static str,
    },
    #[error("packet CRC mismatch: packet says {given:04X}, computed {computed:04X}")]
    Crc { given: u16, computed: u16 },
    #[error("packet cut short: a new sync came {at} bytes into a {len}-byte packet")]
    Truncated { at: usize, len: usize },
}

/// CRC-16/CCITT-FALSE (polynomial 0x1021, initial 0xFFFF, no reflection,
/// no final XOR): "123456789" gives 0x29B1. Bitwise: an MCU without room
/// for a table computes it the same way.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Payload bytes of K samples of C channels of `bits` bits.
pub fn payload_len(samples: usize, channels: usize, bits: usize) -> usize {
    (samples * channels * bits).div_ceil(8)
}

/// Bytes a board sends per sample of its C channels in blocks of K: the
/// payload and its share of a packet's overhead (the bandwidth check).
pub fn bytes_per_sample(channels: u32, bits: u32, block: u32) -> f64 {
    f64::from(channels * bits) / 8.0 + OVERHEAD as f64 / f64::from(block.max(1))
}

/// Append one packet to `out` (for tests, benches and simulated boards):
/// `samples` holds K samples of `channels` values each, sample after
/// sample. Values above `bits` are cut to it.
pub fn encode(board: u8, bits: u8, channels: u8, first: u32, samples: &[u16], out: &mut Vec<u8>) {
    let c = usize::from(channels.max(1));
    let k = samples.len() / c;
    out.extend_from_slice(&SYNC);
    let start = out.len();
    out.extend_from_slice(&[VERSION, board, bits, channels]);
    out.extend_from_slice(&(k as u16).to_le_bytes());
    out.extend_from_slice(&first.to_le_bytes());
    let mask = if bits >= 16 {
        u32::MAX
    } else {
        (1u32 << bits) - 1
    };
    let (mut acc, mut have) = (0u32, 0u32);
    for &v in &samples[..k * c] {
        acc |= (u32::from(v) & mask) << have;
        have += u32::from(bits);
        while have >= 8 {
            out.push(acc as u8);
            acc >>= 8;
            have -= 8;
        }
    }
    if have > 0 {
        out.push(acc as u8);
    }
    let crc = crc16(&out[start..]);
    out.extend_from_slice(&crc.to_le_bytes());
}

/// The header's fields, checked: (bits, channels, K, packet length).
fn header(h: &[u8]) -> Result<(u8, u8, u16, usize), PacketError> {
    if h[0] != VERSION {
        return Err(PacketError::Version(h[0]));
    }
    let (bits, channels) = (h[2], h[3]);
    let k = u16::from_le_bytes([h[4], h[5]]);
    if !(1..=16).contains(&bits) {
        return Err(PacketError::Header {
            name: "bits",
            value: u16::from(bits),
            range: "1..=16",
        });
    }
    if channels == 0 || usize::from(channels) > MAX_CH {
        return Err(PacketError::Header {
            name: "channels",
            value: u16::from(channels),
            range: "1..=16",
        });
    }
    if k == 0 || usize::from(k) > MAX_BLOCK {
        return Err(PacketError::Header {
            name: "samples",
            value: k,
            range: "1..=64",
        });
    }
    let p = payload_len(usize::from(k), usize::from(channels), usize::from(bits));
    Ok((bits, channels, k, OVERHEAD + p))
}

/// Decode one whole packet (sync to CRC) into `into`.
pub fn decode(packet: &[u8], into: &mut Block) -> Result<(), PacketError> {
    if packet.len() < OVERHEAD || packet[..2] != SYNC {
        return Err(PacketError::Garbage);
    }
    let (bits, channels, k, len) = header(&packet[2..2 + HEADER])?;
    if packet.len() < len {
        return Err(PacketError::Truncated {
            at: packet.len(),
            len,
        });
    }
    let body = &packet[2..len - 2];
    let given = u16::from_le_bytes([packet[len - 2], packet[len - 1]]);
    let computed = crc16(body);
    if given != computed {
        return Err(PacketError::Crc { given, computed });
    }
    into.board = packet[3];
    into.bits = bits;
    into.channels = channels;
    into.samples = k;
    into.first = u32::from_le_bytes([packet[8], packet[9], packet[10], packet[11]]);
    let payload = &body[HEADER..];
    let mask = (1u32 << bits) - 1;
    let (mut acc, mut have, mut byte) = (0u32, 0u32, 0usize);
    let c = usize::from(channels);
    for i in 0..usize::from(k) {
        for ch in 0..c {
            while have < u32::from(bits) {
                acc |= u32::from(payload.get(byte).copied().unwrap_or(0)) << have;
                byte += 1;
                have += 8;
            }
            into.values[i * MAX_CH + ch] = (acc & mask) as u16;
            acc >>= bits;
            have -= u32::from(bits);
        }
    }
    Ok(())
}

/// Splits a byte stream into packets without allocating: bytes go in,
/// each packet (or the error of bytes thrown away) comes out through a
/// callback. Bytes before a sync are one [`PacketError::Garbage`] per run;
/// a packet whose CRC fails is thrown away and the search for a sync goes
/// on from the byte after its sync (its length may be what was damaged);
/// a packet that a new sync interrupts is reported
/// [`PacketError::Truncated`] only once its CRC has failed, since a sync's
/// two bytes may also be payload.
#[derive(Clone)]
pub struct PacketAssembler {
    buf: Box<[u8; MAX_PACKET]>,
    len: usize,
    /// Garbage is being skipped (said once per run).
    skipping: bool,
    block: Box<Block>,
}

impl Default for PacketAssembler {
    fn default() -> Self {
        PacketAssembler {
            buf: Box::new([0; MAX_PACKET]),
            len: 0,
            skipping: false,
            block: Box::default(),
        }
    }
}

impl std::fmt::Debug for PacketAssembler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PacketAssembler({} bytes held)", self.len)
    }
}

impl PacketAssembler {
    /// Forget a partial packet (the port was reopened).
    pub fn clear(&mut self) {
        self.len = 0;
        self.skipping = false;
    }

    /// Feed bytes; `on` gets each decoded block or the error of bytes
    /// thrown away.
    pub fn push(&mut self, mut bytes: &[u8], mut on: impl FnMut(Result<&Block, PacketError>)) {
        while !bytes.is_empty() {
            let room = MAX_PACKET - self.len;
            let take = room.min(bytes.len());
            self.buf[self.len..self.len + take].copy_from_slice(&bytes[..take]);
            self.len += take;
            bytes = &bytes[take..];
            self.drain(&mut on);
        }
    }

    /// Take every packet the buffer holds, keeping a partial one.
    fn drain(&mut self, on: &mut impl FnMut(Result<&Block, PacketError>)) {
        let mut at = 0;
        loop {
            let held = &self.buf[at..self.len];
            let Some(s) = find_sync(held) else {
                // Keep a last 0xA5: it may start a sync.
                let keep = usize::from(held.last() == Some(&SYNC[0]));
                self.garbage(held.len() - keep, on);
                at = self.len - keep;
                break;
            };
            self.garbage(s, on);
            at += s;
            let held = &self.buf[at..self.len];
            if held.len() < 2 + HEADER {
                break;
            }
            let len = match header(&held[2..2 + HEADER]) {
                Ok((.., len)) => len,
                Err(e) => {
                    on(Err(e));
                    at += 1;
                    self.skipping = true;
                    continue;
                }
            };
            if held.len() < len {
                break;
            }
            match decode(&held[..len], &mut self.block) {
                Ok(()) => {
                    on(Ok(&self.block));
                    at += len;
                    self.skipping = false;
                }
                Err(e) => {
                    // A sync inside the bad packet: it was cut short there
                    // (a board reset mid-packet) rather than merely damaged.
                    let e = match find_sync(&held[2..len]) {
                        Some(i) if matches!(e, PacketError::Crc { .. }) => {
                            PacketError::Truncated { at: i + 2, len }
                        }
                        _ => e,
                    };
                    on(Err(e));
                    at += 1;
                    self.skipping = true;
                }
            }
        }
        self.buf.copy_within(at..self.len, 0);
        self.len -= at;
    }

    /// `n` bytes before a sync: one error per run of them.
    fn garbage(&mut self, n: usize, on: &mut impl FnMut(Result<&Block, PacketError>)) {
        if n == 0 {
            return;
        }
        if !self.skipping {
            on(Err(PacketError::Garbage));
        }
        self.skipping = true;
    }
}

fn find_sync(b: &[u8]) -> Option<usize> {
    b.windows(2).position(|w| w == SYNC)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(first: u32, k: usize, c: u8, bits: u8) -> Vec<u8> {
        let v: Vec<u16> = (0..k * c as usize)
            .map(|i| (i as u16 * 37 + first as u16) & ((1 << bits) - 1) as u16)
            .collect();
        let mut out = Vec::new();
        encode(3, bits, c, first, &v, &mut out);
        out
    }

    fn blocks(stream: &[u8], chunk: usize) -> Vec<Result<u32, PacketError>> {
        let mut a = PacketAssembler::default();
        let mut got = Vec::new();
        for piece in stream.chunks(chunk) {
            a.push(piece, |r| got.push(r.map(|b| b.first)));
        }
        got
    }

    #[test]
    fn crc_is_ccitt_false() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn round_trip_at_every_width() {
        for bits in [1u8, 7, 10, 12, 15, 16] {
            for c in [1u8, 3, 8, 16] {
                let k = 5;
                let v: Vec<u16> = (0..k * c as usize)
                    .map(|i| ((i * 2654435761) as u32 as u16) & (((1u32 << bits) - 1) as u16))
                    .collect();
                let mut out = Vec::new();
                encode(9, bits, c, 77, &v, &mut out);
                assert_eq!(
                    out.len(),
                    OVERHEAD + payload_len(k, c as usize, bits as usize)
                );
                let mut b = Block::default();
                decode(&out, &mut b).unwrap();
                assert_eq!(
                    (b.board, b.bits, b.channels, b.samples, b.first),
                    (9, bits, c, 5, 77)
                );
                for i in 0..k {
                    assert_eq!(b.sample(i), &v[i * c as usize..(i + 1) * c as usize]);
                }
            }
        }
    }

    #[test]
    fn split_packets_join_and_garbage_is_one_error_per_run() {
        let mut s = b"boot v1\r\n".to_vec();
        s.extend(packet(0, 4, 16, 12));
        s.extend(packet(4, 4, 16, 12));
        s.extend([0x00, 0xA5, 0x00, 0x5A]);
        s.extend(packet(8, 4, 16, 12));
        for chunk in [1, 7, 1000] {
            assert_eq!(
                blocks(&s, chunk),
                vec![
                    Err(PacketError::Garbage),
                    Ok(0),
                    Ok(4),
                    Err(PacketError::Garbage),
                    Ok(8)
                ],
                "chunks of {chunk}"
            );
        }
    }

    #[test]
    fn a_bad_crc_a_bad_header_and_a_cut_packet_are_each_said() {
        let good = packet(10, 8, 16, 12);
        let mut bad = good.clone();
        bad[20] ^= 0x40;
        let mut s = bad;
        s.extend(&good);
        let got = blocks(&s, 13);
        assert!(matches!(got[0], Err(PacketError::Crc { .. })), "{got:?}");
        assert_eq!(got.last(), Some(&Ok(10)), "{got:?}");

        let mut hdr = good.clone();
        hdr[5] = 17; // channels
        let mut s = hdr;
        s.extend(&good);
        let got = blocks(&s, 1000);
        assert_eq!(
            got[0],
            Err(PacketError::Header {
                name: "channels",
                value: 17,
                range: "1..=16"
            })
        );
        assert_eq!(got.last(), Some(&Ok(10)), "{got:?}");

        // Cut after 30 bytes (a board reset), then a whole packet.
        let mut s = good[..30].to_vec();
        s.extend(&good);
        let got = blocks(&s, 1000);
        assert!(
            matches!(got[0], Err(PacketError::Truncated { at: 30, .. })),
            "{got:?}"
        );
        assert_eq!(got.last(), Some(&Ok(10)), "{got:?}");
        assert!(got.iter().filter(|r| r.is_ok()).count() == 1, "{got:?}");
    }

    #[test]
    fn a_version_or_zero_block_is_refused() {
        let mut v2 = packet(0, 2, 4, 10);
        v2[2] = 2;
        assert_eq!(
            decode(&v2, &mut Block::default()),
            Err(PacketError::Version(2))
        );
        let mut zero = packet(0, 2, 4, 10);
        zero[6] = 0;
        zero[7] = 0;
        assert!(matches!(
            decode(&zero, &mut Block::default()),
            Err(PacketError::Header {
                name: "samples",
                ..
            })
        ));
    }
}
