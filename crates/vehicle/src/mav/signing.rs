//! MAVLink 2 message signing (mavlink.io/en/guide/message_signing.html).
//! With a key configured, every frame this component sends is signed, and
//! only frames signed with the key are taken.
//!
//! Why: an autopilot with signing on (ArduPilot after `SETUP_SIGNING`)
//! drops unsigned frames on every link but USB, so an unsigned
//! `VISION_POSITION_ESTIMATE` never reaches its EKF. And on a vehicle's
//! LAN, without it whoever can send a UDP datagram can feed the estimator
//! an attitude or a depth, or (on `udpin`) become the poses' destination.
//!
//! The signature is SHA-256 over the key and the frame from its start
//! marker through the timestamp, cut to 6 bytes; the timestamp counts
//! 10 µs since 2015-01-01 UTC and must grow on each stream (link id,
//! system, component), which is what stops a recorded frame from being
//! played again.

use mavlink::MAVLinkV2MessageRaw;
use sha2::{Digest, Sha256};
use std::fmt;
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

/// Link id, timestamp and signature after a signed frame's checksum.
pub const SIGNATURE_LEN: usize = 13;
const SIG_VALUE_LEN: usize = 6;
const STX_V2: u8 = 0xFD;
const IFLAG_SIGNED: u8 = 0x01;
/// 2015-01-01 00:00:00 UTC in Unix seconds: the timestamps' epoch.
const EPOCH_2015_S: u64 = 1_420_070_400;
/// A frame is refused when its timestamp is more than a minute behind the
/// link's: the later of our clock and the newest timestamp we sent or took
/// from the autopilot (the spec's rule for a new stream, an old recording
/// is not new; held for every frame, so a stream once known is still
/// judged against the clock).
const BEHIND_SLACK: u64 = 60 * 100_000;
/// Streams remembered (link id, system, component). Only frames with a
/// valid signature make one, so this is a bound, not a working size: a
/// vehicle has a handful (autopilot, GCS, a companion or two).
const MAX_STREAMS: usize = 32;
/// The largest timestamp 48 bits hold: ours stops there (in the year
/// 2104) rather than wrap to 0, which every receiver would refuse.
const MAX_TIMESTAMP: u64 = (1 << 48) - 1;

/// The 32-byte secret both ends share. Its `Debug` shows a fingerprint,
/// never the key (settings are logged).
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; 32]);

/// How a key file holds the key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeyForm {
    /// 64 hexadecimal digits: the 32 bytes themselves.
    Hex,
    /// A passphrase: the key is its SHA-256, as MAVProxy's `signing setup`
    /// and QGroundControl derive it.
    Passphrase,
}

impl SigningKey {
    pub fn from_bytes(key: [u8; 32]) -> Self {
        SigningKey(key)
    }

    /// 64 hexadecimal digits.
    pub fn from_hex(text: &str) -> Result<Self, String> {
        let t = text.trim();
        if t.len() != 64 || !t.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(format!(
                "not a key: want 64 hexadecimal digits (32 bytes), found {} characters",
                t.chars().count()
            ));
        }
        let mut key = [0u8; 32];
        for (k, pair) in key.iter_mut().zip(t.as_bytes().chunks(2)) {
            let hex = std::str::from_utf8(pair).map_err(|e| e.to_string())?;
            *k = u8::from_str_radix(hex, 16).map_err(|e| e.to_string())?;
        }
        Ok(SigningKey(key))
    }

    /// The SHA-256 of `passphrase` (its bytes as written).
    pub fn from_passphrase(passphrase: &str) -> Self {
        SigningKey(Sha256::digest(passphrase.as_bytes()).into())
    }

    /// The key in the file at `path`: its first line (a trailing newline
    /// is not part of a passphrase; an empty one is refused).
    pub fn load(path: &Path, form: KeyForm) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let line = text.lines().next().unwrap_or("").trim_end_matches('\r');
        match form {
            KeyForm::Hex => Self::from_hex(line).map_err(|e| format!("{}: {e}", path.display())),
            KeyForm::Passphrase if line.is_empty() => {
                Err(format!("{}: the passphrase is empty", path.display()))
            }
            KeyForm::Passphrase => Ok(Self::from_passphrase(line)),
        }
    }

    /// A name for the key in logs and STATUS: the first 4 bytes of its
    /// SHA-256, which tell two keys apart without saying either.
    pub fn fingerprint(&self) -> String {
        let d = Sha256::digest(self.0);
        d[..4].iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The signature of `signed`: a frame from its start marker through
    /// the timestamp.
    fn sign(&self, signed: &[u8]) -> [u8; SIG_VALUE_LEN] {
        let mut h = Sha256::new();
        h.update(self.0);
        h.update(signed);
        let d = h.finalize();
        let mut out = [0u8; SIG_VALUE_LEN];
        out.copy_from_slice(&d[..SIG_VALUE_LEN]);
        out
    }
}

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SigningKey({})", self.fingerprint())
    }
}

/// `[mavlink.signing]` as validated.
#[derive(Debug, Clone, PartialEq)]
pub struct SigningConfig {
    pub key: SigningKey,
    /// The link id this component signs with (one per link of a system).
    pub link_id: u8,
    /// Take unsigned frames too (MAVLink 1 included): for a change-over,
    /// while the autopilot's link is not signed yet. Frames that are
    /// signed must still carry a good signature.
    pub allow_unsigned: bool,
}

/// Why a frame was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejected {
    /// No signature, and unsigned frames are not taken.
    Unsigned,
    /// A signature that is not the key's (another key, or altered bytes).
    BadSignature,
    /// A good signature on a timestamp not newer than its stream's last
    /// (a frame played again).
    Replayed,
    /// A good signature on a timestamp more than a minute behind the
    /// link's (our clock, or the newest we sent or took): an old recording,
    /// or a sender whose clock is behind (an autopilot without the time;
    /// see docs/vehicle.md, "Signing").
    Behind,
}

#[derive(Debug, Clone, Copy, Default)]
struct Stream {
    id: (u8, u8, u8),
    timestamp: u64,
    used: bool,
    /// When it was last heard, as a count of frames taken: the one heard
    /// longest ago makes room for a new stream.
    heard: u64,
}

/// One link's signing: the key, the last timestamp sent or taken, and each
/// stream's last timestamp. No allocation after it is made.
#[derive(Debug, Clone)]
pub struct Signer {
    cfg: SigningConfig,
    /// The link's timestamp: from the clock at start, then the newest sent
    /// or taken from the autopilot. It started at 0 and moved only with a
    /// send, so on `udpin` (nothing sent before a peer) a replay of the
    /// day before was a new stream within a minute of 0, taken, and took
    /// the peer from the autopilot (issue 44).
    timestamp: u64,
    streams: [Stream; MAX_STREAMS],
    /// Frames taken so far (the streams' clock of when heard).
    taken: u64,
}

/// Now in the timestamps' unit (10 µs since 2015), 0 for a clock before
/// 2015 (a computer that booted without its time): the timestamp then
/// comes from the frames taken (see [`Signer::check`]).
pub fn timestamp_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| (d.as_micros() / 10) as u64)
        .saturating_sub(EPOCH_2015_S * 100_000)
}

impl Signer {
    /// A link's signing from now: its timestamp starts at the clock.
    pub fn new(cfg: SigningConfig) -> Self {
        Self::starting_at(cfg, timestamp_now())
    }

    /// As [`Signer::new`] with the clock reading `now` (tests).
    pub fn starting_at(cfg: SigningConfig, now: u64) -> Self {
        Signer {
            cfg,
            timestamp: now.min(MAX_TIMESTAMP),
            streams: [Stream::default(); MAX_STREAMS],
            taken: 0,
        }
    }

    pub fn config(&self) -> &SigningConfig {
        &self.cfg
    }

    /// Serialize `msg` into `raw` signed, with timestamp the later of
    /// `now` and one past the last used or taken.
    pub fn serialize<M: mavlink::Message>(
        &mut self,
        raw: &mut MAVLinkV2MessageRaw,
        header: mavlink::MavHeader,
        msg: &M,
        now: u64,
    ) {
        raw.serialize_message_for_signing(header, msg);
        self.timestamp = now.max(self.timestamp + 1).min(MAX_TIMESTAMP);
        *raw.signature_link_id_mut() = self.cfg.link_id;
        raw.signature_timestamp_bytes_mut()
            .copy_from_slice(&self.timestamp.to_le_bytes()[..6]);
        let n = raw.raw_bytes().len();
        let sig = self.cfg.key.sign(&raw.raw_bytes()[..n - SIG_VALUE_LEN]);
        raw.signature_value_mut().copy_from_slice(&sig);
    }

    /// Whether `frame` (a whole CRC-valid MAVLink 1 or 2 frame) may be
    /// taken. A good signature moves the stream's timestamp and ours (so a
    /// computer without the time signs after the autopilot's clock): for a
    /// peer that is the autopilot. A daemon that takes frames from others
    /// too checks with [`Signer::verify`] and follows only the autopilot's.
    pub fn check(&mut self, frame: &[u8]) -> Result<(), Rejected> {
        self.check_at(frame, timestamp_now())
    }

    /// As [`Signer::check`] with the clock reading `now`.
    pub fn check_at(&mut self, frame: &[u8], now: u64) -> Result<(), Rejected> {
        if let Some(ts) = self.verify_at(frame, now)? {
            self.follow(ts);
        }
        Ok(())
    }

    /// Our timestamp is at least `ts` from now on: a timestamp of a frame
    /// taken from the autopilot. (Any key holder's frame moved it, even
    /// one then refused for its origin: a GCS's frame stamped 2⁴⁸ − 1 held
    /// ours at the end of the 48 bits, and every frame after was a replay
    /// to the autopilot.)
    pub fn follow(&mut self, ts: u64) {
        self.timestamp = self.timestamp.max(ts);
    }

    /// As [`Signer::check`], without moving our timestamp: the timestamp
    /// of a signed frame that may be taken, `None` for an unsigned one
    /// (when those are allowed).
    pub fn verify(&mut self, frame: &[u8]) -> Result<Option<u64>, Rejected> {
        self.verify_at(frame, timestamp_now())
    }

    /// As [`Signer::verify`] with the clock reading `now`. A frame is fresh
    /// when its timestamp is newer than its stream's last and at most a
    /// minute behind the link's (the later of `now` and ours); only a
    /// fresh frame with a good signature makes or moves a stream.
    pub fn verify_at(&mut self, frame: &[u8], now: u64) -> Result<Option<u64>, Rejected> {
        let signed =
            frame.len() >= 12 + SIGNATURE_LEN && frame[0] == STX_V2 && frame[2] & IFLAG_SIGNED != 0;
        if !signed {
            return if self.cfg.allow_unsigned {
                Ok(None)
            } else {
                Err(Rejected::Unsigned)
            };
        }
        let (body, sig) = frame.split_at(frame.len() - SIG_VALUE_LEN);
        // Compared in constant time: how many bytes matched is not told.
        let differ = self
            .cfg
            .key
            .sign(body)
            .iter()
            .zip(sig)
            .fold(0u8, |d, (a, b)| d | (a ^ b));
        if differ != 0 {
            return Err(Rejected::BadSignature);
        }
        let tail = &body[body.len() - 7..];
        let mut ts = [0u8; 8];
        ts[..6].copy_from_slice(&tail[1..]);
        let ts = u64::from_le_bytes(ts);
        let id = (tail[0], frame[5], frame[6]);
        let link = self.timestamp.max(now.min(MAX_TIMESTAMP));
        let stream = self.streams.iter_mut().find(|s| s.used && s.id == id);
        if stream.as_ref().is_some_and(|s| ts <= s.timestamp) {
            return Err(Rejected::Replayed);
        }
        if ts.saturating_add(BEHIND_SLACK) < link {
            return Err(Rejected::Behind);
        }
        self.taken += 1;
        let heard = self.taken;
        match stream {
            Some(s) => (s.timestamp, s.heard) = (ts, heard),
            None => {
                // A free slot, else the stream heard longest ago.
                let slot = self
                    .streams
                    .iter_mut()
                    .min_by_key(|s| (s.used, s.heard))
                    .expect("MAX_STREAMS > 0");
                *slot = Stream {
                    id,
                    timestamp: ts,
                    used: true,
                    heard,
                };
            }
        }
        Ok(Some(ts))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
    use mavlink::MavHeader;

    fn cfg(allow_unsigned: bool) -> SigningConfig {
        SigningConfig {
            key: SigningKey::from_passphrase("correct horse"),
            link_id: 3,
            allow_unsigned,
        }
    }

    /// A signer whose clock reads 0 (the small timestamps below; the
    /// clock's own rule is tested with `check_at`).
    fn new0(c: SigningConfig) -> Signer {
        Signer::starting_at(c, 0)
    }

    impl Signer {
        fn check0(&mut self, frame: &[u8]) -> Result<(), Rejected> {
            self.check_at(frame, 0)
        }
    }

    fn attitude() -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            pitch: 0.1,
            ..Default::default()
        })
    }

    fn header(system: u8, component: u8) -> MavHeader {
        MavHeader {
            system_id: system as u32,
            component_id: component,
            sequence: 0,
        }
    }

    fn signed(s: &mut Signer, system: u8, now: u64) -> Vec<u8> {
        let mut raw = MAVLinkV2MessageRaw::new();
        s.serialize(&mut raw, header(system, 1), &attitude(), now);
        raw.raw_bytes().to_vec()
    }

    /// A passphrase's key is its SHA-256, as MAVProxy makes it: FIPS
    /// 180's vector for "abc".
    #[test]
    fn a_passphrase_is_hashed_and_hex_is_read_as_bytes() {
        let k = SigningKey::from_passphrase("abc");
        let hex = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        assert_eq!(k, SigningKey::from_hex(hex).unwrap());
        assert_eq!(k, SigningKey::from_hex(&hex.to_uppercase()).unwrap());
        assert!(SigningKey::from_hex(&hex[..62]).is_err());
        assert!(SigningKey::from_hex(&format!("{}zz", &hex[..62])).is_err());
        assert_eq!(format!("{k:?}"), format!("SigningKey({})", k.fingerprint()));
        assert!(!format!("{k:?}").contains("ba7816"));
    }

    #[test]
    fn key_files_are_read_by_their_first_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("key");
        std::fs::write(&p, "abc\n").unwrap();
        assert_eq!(
            SigningKey::load(&p, KeyForm::Passphrase).unwrap(),
            SigningKey::from_passphrase("abc")
        );
        let e = SigningKey::load(&p, KeyForm::Hex).unwrap_err();
        assert!(e.contains("64 hexadecimal digits"), "{e}");
        std::fs::write(&p, "\n").unwrap();
        let e = SigningKey::load(&p, KeyForm::Passphrase).unwrap_err();
        assert!(e.contains("empty"), "{e}");
        let e = SigningKey::load(&dir.path().join("none"), KeyForm::Hex).unwrap_err();
        assert!(e.contains("none"), "{e}");
    }

    #[test]
    fn a_frame_signed_with_the_key_is_taken_once() {
        let (mut a, mut b) = (new0(cfg(false)), new0(cfg(false)));
        let f = signed(&mut a, 1, 1000);
        assert_eq!(f[2] & IFLAG_SIGNED, IFLAG_SIGNED);
        assert_eq!(b.check0(&f), Ok(()));
        // The same frame again is a replay.
        assert_eq!(b.check0(&f), Err(Rejected::Replayed));
        // The next one from the same stream is newer even at the same now.
        let g = signed(&mut a, 1, 1000);
        assert_eq!(b.check0(&g), Ok(()));
    }

    #[test]
    fn another_key_or_an_altered_byte_is_refused() {
        let mut a = new0(cfg(false));
        let mut other = new0(SigningConfig {
            key: SigningKey::from_passphrase("wrong"),
            ..cfg(false)
        });
        let f = signed(&mut a, 1, 5);
        assert_eq!(other.check0(&f), Err(Rejected::BadSignature));
        let mut b = new0(cfg(false));
        for k in 0..f.len() {
            let mut g = f.clone();
            g[k] ^= 0x10;
            // The start marker altered makes it no MAVLink 2 frame (hence
            // unsigned); any other byte breaks the signature.
            let want = if k == 0 {
                Rejected::Unsigned
            } else {
                Rejected::BadSignature
            };
            assert_eq!(b.check0(&g), Err(want), "byte {k}");
        }
        assert_eq!(b.check0(&f), Ok(()));
    }

    #[test]
    fn unsigned_frames_are_taken_only_when_allowed() {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(header(1, 1), &attitude());
        let f = raw.raw_bytes().to_vec();
        assert_eq!(new0(cfg(false)).check0(&f), Err(Rejected::Unsigned));
        assert_eq!(new0(cfg(true)).check0(&f), Ok(()));
        // Allowed unsigned does not let a bad signature through.
        let mut a = new0(cfg(true));
        let mut g = signed(&mut a, 1, 9);
        let n = g.len();
        g[n - 1] ^= 1;
        assert_eq!(new0(cfg(true)).check0(&g), Err(Rejected::BadSignature));
    }

    /// A computer whose clock is at 1970 signs after what it has taken; a
    /// new stream a minute behind is a recording, not a newcomer.
    #[test]
    fn timestamps_follow_the_frames_taken() {
        let minute = 60 * 100_000;
        let mut ap = new0(cfg(false));
        let mut me = new0(cfg(false));
        assert_eq!(me.check0(&signed(&mut ap, 1, 50 * minute)), Ok(()));
        let mine = signed(&mut me, 1, 0);
        let ts = u64::from_le_bytes({
            let mut b = [0u8; 8];
            b[..6].copy_from_slice(&mine[mine.len() - 12..mine.len() - 6]);
            b
        });
        assert_eq!(ts, 50 * minute + 1);
        // A stream first heard 2 minutes behind: refused; 30 s behind: taken.
        let mut old = new0(cfg(false));
        assert_eq!(
            me.check0(&signed(&mut old, 2, 48 * minute)),
            Err(Rejected::Behind)
        );
        let mut late = new0(cfg(false));
        assert_eq!(
            me.check0(&signed(&mut late, 3, 50 * minute - minute / 2)),
            Ok(())
        );
    }

    /// Streams are bounded; the one heard longest ago makes room, not the
    /// one with the smallest timestamp (a live sender whose clock lags).
    #[test]
    fn streams_are_bounded_and_the_one_heard_longest_ago_is_forgotten() {
        let mut me = new0(cfg(false));
        let mut peers: Vec<Signer> = (0..=MAX_STREAMS).map(|_| new0(cfg(false))).collect();
        // System 1 has the smallest timestamps, but is heard last.
        for (k, p) in peers.iter_mut().enumerate().skip(1).take(MAX_STREAMS - 1) {
            let f = signed(p, k as u8 + 1, 1000 + 10 * k as u64);
            assert_eq!(me.check0(&f), Ok(()), "stream {k}");
        }
        assert_eq!(me.check0(&signed(&mut peers[0], 1, 500)), Ok(()));
        let f = signed(&mut peers[MAX_STREAMS], MAX_STREAMS as u8 + 1, 2000);
        assert_eq!(me.check0(&f), Ok(()));
        assert!(me.streams.iter().all(|s| s.used));
        assert!(
            me.streams.iter().any(|s| s.id.1 == 1),
            "the one heard last stays"
        );
        assert!(
            !me.streams.iter().any(|s| s.id.1 == 2),
            "the one heard first went"
        );
    }

    /// Ours stops at the 48 bits' end instead of wrapping to 0.
    #[test]
    fn the_timestamp_saturates_at_48_bits() {
        let mut me = new0(cfg(false));
        let mut far = new0(cfg(false));
        assert_eq!(me.check0(&signed(&mut far, 1, MAX_TIMESTAMP)), Ok(()));
        let mine = signed(&mut me, 1, 0);
        let n = mine.len();
        assert_eq!(&mine[n - 12..n - 6], &[0xFF; 6]);
    }

    /// Issue 44: on `udpin` nothing is sent before a peer, so the link's
    /// timestamp was 0 and a replay of frames signed the day before was a
    /// new stream within a minute of it: taken. The link starts at the
    /// clock, and every frame (of a stream known or not) is judged against
    /// the later of the clock and ours.
    #[test]
    fn a_replay_from_the_day_before_is_refused_from_the_start() {
        let day = 86_400 * 100_000;
        let now = timestamp_now();
        let mut recorder = new0(cfg(false));
        let old: Vec<Vec<u8>> = (0..5)
            .map(|k| signed(&mut recorder, 1, now - day + k))
            .collect();
        let mut me = Signer::new(cfg(false));
        for f in &old {
            assert_eq!(me.check(f), Err(Rejected::Behind));
        }
        // Nothing of the replay was remembered: the autopilot's own
        // stream (same ids), stamped now, is taken.
        let mut ap = Signer::new(cfg(false));
        assert_eq!(me.check(&signed(&mut ap, 1, now)), Ok(()));
        // A stream known from before the clock moved on a day is judged
        // against the clock too, not only against its own last timestamp.
        let mut me = Signer::starting_at(cfg(false), now - day);
        assert_eq!(me.check_at(&old[0], now - day), Ok(()));
        assert_eq!(me.check_at(&old[1], now), Err(Rejected::Behind));
        // A minute's slack: a sender 30 s behind the clock is taken.
        let mut late = new0(cfg(false));
        let f = signed(&mut late, 2, now - 30 * 100_000);
        assert_eq!(Signer::new(cfg(false)).check(&f), Ok(()));
    }

    #[test]
    fn the_clock_counts_from_2015_in_10_microseconds() {
        let now = timestamp_now();
        // 2026 is 11+ years after 2015: over 3.4e13 units.
        assert!(now > 11 * 365 * 86_400 * 100_000, "{now}");
        assert!(now < 1 << 48, "fits 48 bits");
    }
}
