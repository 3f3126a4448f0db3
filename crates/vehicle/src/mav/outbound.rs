//! What goes to the autopilot: VISION_POSITION_ESTIMATE for every `ok`
//! pose, VISION_SPEED_ESTIMATE when the surge is known, HEARTBEAT every
//! second; and the hand-off of poses from the frame thread (the outbox).
//!
//! Only a pose whose status is `ok` and whose five fields are all finite
//! gets into the outbox: the autopilot must never fuse a pose the daemon
//! does not trust. `reset_counter` is the low byte of the estimator's
//! track epoch, which the caller passes with each pose (see
//! [`RestartCounter`]): the autopilot's EKF resets its position to ours
//! when it changes instead of treating the jump as an outlier.

use super::signing::{timestamp_now, Signer, SigningConfig};
use crate::covariance::{position_covariance, speed_covariance, PoseStd, SpeedStd};
use crate::latest::{opt, word, Latest};
use crate::ned::{NedVec, Site};
use lightpose_core::{Angle, Pose, PoseEstimate, Status};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA, TIMESYNC_DATA,
    VISION_POSITION_ESTIMATE_DATA, VISION_SPEED_ESTIMATE_DATA,
};
use mavlink::{MAVLinkV2MessageRaw, MavHeader};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use tokio::sync::Notify;

/// What to do with an `ok` pose whose std is not known for every field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MissingStd {
    /// Send nothing (counted): the EKF cannot weigh a pose without its
    /// uncertainty.
    Skip,
    /// Send it with these 1σ in place of the missing ones.
    Assume {
        position_m: f64,
        angle: Angle,
        surge_mps: f64,
    },
}

/// How the poses are turned into messages.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputConfig {
    /// At most this many VISION_POSITION_ESTIMATE per second of capture
    /// time (`None`: one per `ok` pose).
    pub position_rate_hz: Option<f64>,
    /// Send VISION_SPEED_ESTIMATE when the surge is known.
    pub speed: bool,
    /// 1σ of the roll when the estimate gives none of its own (it then
    /// claims 0, or the roll of the frame's attitude with no σ).
    pub roll_std: Angle,
    /// 1σ of the sway and heave the speed leaves out, m/s.
    pub side_speed_std_mps: f64,
    pub missing_std: MissingStd,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            position_rate_hz: None,
            speed: true,
            roll_std: Angle::from_deg(5.0),
            side_speed_std_mps: 0.1,
            missing_std: MissingStd::Skip,
        }
    }
}

/// What [`PoseOutbox::offer`] did with a pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Offer {
    /// Handed to the sender.
    Queued,
    /// Not `ok`: nothing goes out.
    NotOk(Status),
    /// `ok` but a field is missing or not finite: nothing goes out.
    Incomplete,
}

/// A pose waiting for the sender: 17 words (see `to_words`).
const WORDS: usize = 17;

/// An `ok` pose as the sender takes it from the outbox.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outgoing {
    pub seq: u64,
    /// Capture time, s.
    pub t: f64,
    pub pose: Pose,
    pub surge: Option<f64>,
    /// x, y, z (m), pitch, yaw (degrees), surge (m/s), as in `StdDev`.
    pub std: [Option<f64>; 6],
    /// Spec v3: the roll's 1σ, degrees (`StdDev::roll`), when the
    /// estimate knows it.
    pub roll_std: Option<f64>,
    pub epoch: u32,
}

impl Outgoing {
    fn to_words(self) -> [u64; WORDS] {
        let p = &self.pose;
        let mut w = [0u64; WORDS];
        w[0] = self.seq;
        w[1] = self.t.to_bits();
        w[2..7].copy_from_slice(&[
            p.x.to_bits(),
            p.y.to_bits(),
            p.z.to_bits(),
            p.pitch.rad().to_bits(),
            p.yaw.rad().to_bits(),
        ]);
        w[7] = word(self.surge);
        for (k, s) in self.std.iter().enumerate() {
            w[8 + k] = word(*s);
        }
        w[14] = self.epoch as u64;
        w[15] = p.roll.rad().to_bits();
        w[16] = word(self.roll_std);
        w
    }

    fn from_words(w: &[u64; WORDS]) -> Self {
        let f = |k: usize| f64::from_bits(w[k]);
        Outgoing {
            seq: w[0],
            t: f(1),
            pose: Pose::new(
                f(2),
                f(3),
                f(4),
                Angle::from_rad(f(5)),
                Angle::from_rad(f(6)),
            )
            .with_roll(Angle::from_rad(f(15))),
            surge: opt(w[7]),
            std: std::array::from_fn(|k| opt(w[8 + k])),
            roll_std: opt(w[16]),
            epoch: w[14] as u32,
        }
    }
}

/// The frame thread's hand-off to the sender: the latest `ok` pose, and a
/// wake-up. Offering neither allocates nor blocks; a pose the sender has
/// not taken yet is replaced by the next (counted as overwritten).
#[derive(Default)]
pub struct PoseOutbox {
    slot: Latest<WORDS>,
    notify: Notify,
    queued: AtomicU64,
    incomplete: AtomicU64,
    not_ok: [AtomicU64; Status::ALL.len()],
}

/// STATUS figures of the outbox.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutboxStatus {
    pub queued: u64,
    pub incomplete: u64,
    /// Poses not sent because their status was not `ok`, per status word.
    #[serde(serialize_with = "crate::counts_as_map")]
    pub not_ok: Vec<(&'static str, u64)>,
}

impl PoseOutbox {
    /// Offer the estimate of a frame; `epoch` counts the estimator's
    /// restarts so far (its low byte becomes `reset_counter`).
    pub fn offer(&self, est: &PoseEstimate, epoch: u32) -> Offer {
        if est.status != Status::Ok {
            self.not_ok[est.status.index()].fetch_add(1, Relaxed);
            return Offer::NotOk(est.status);
        }
        let fields = [est.x, est.y, est.z, est.pitch_deg, est.yaw_deg];
        let [Some(x), Some(y), Some(z), Some(p), Some(yaw)] = fields else {
            self.incomplete.fetch_add(1, Relaxed);
            return Offer::Incomplete;
        };
        // Spec v3: without a roll the estimate's vehicle is level (0, as
        // spec v2 sent); a roll that is not finite is no roll.
        let roll = est.roll_deg.unwrap_or(0.0);
        if ![x, y, z, p, yaw, roll, est.t].iter().all(|v| v.is_finite()) {
            self.incomplete.fetch_add(1, Relaxed);
            return Offer::Incomplete;
        }
        let out = Outgoing {
            seq: est.seq,
            t: est.t,
            pose: Pose::new(x, y, z, Angle::from_deg(p), Angle::from_deg(yaw))
                .with_roll(Angle::from_deg(roll)),
            surge: est.surge.filter(|s| s.is_finite()),
            std: est.std.values(),
            roll_std: est.std.roll,
            epoch,
        };
        self.slot.store(out.to_words());
        self.queued.fetch_add(1, Relaxed);
        self.notify.notify_one();
        Offer::Queued
    }

    /// The latest pose if its version differs from `*seen` (then updated).
    pub fn take_new(&self, seen: &mut u64) -> Option<Outgoing> {
        let (v, w) = self.slot.load()?;
        if v == *seen {
            return None;
        }
        *seen = v;
        Some(Outgoing::from_words(&w))
    }

    /// Resolves when a pose has been offered since the last wake-up.
    pub async fn offered(&self) {
        self.notify.notified().await
    }

    pub fn status(&self) -> OutboxStatus {
        OutboxStatus {
            queued: self.queued.load(Relaxed),
            incomplete: self.incomplete.load(Relaxed),
            not_ok: Status::ALL
                .iter()
                .map(|s| (s.as_str(), self.not_ok[s.index()].load(Relaxed)))
                .filter(|(_, n)| *n > 0)
                .collect(),
        }
    }
}

/// Derives the track epoch from the stream of estimates, for estimators
/// that do not count their own restarts: a pose that is `initialising` or
/// `diverged` after an `ok` one means the estimator started over, and the
/// next `ok` pose opens a new epoch.
///
/// The first epoch is drawn at random ([`RestartCounter::new`], also the
/// `Default`), not 0: the autopilot remembers the last `reset_counter` it
/// saw, and a restarted daemon that began again at 0 after an epoch-0 run
/// would tell it nothing although the track, and the pose, started over.
#[derive(Debug, Clone)]
pub struct RestartCounter {
    epoch: u32,
    seen_ok: bool,
    restarting: bool,
}

impl Default for RestartCounter {
    fn default() -> Self {
        RestartCounter::new()
    }
}

/// The first epoch of a process, from the OS's entropy: its low byte (the
/// `reset_counter`) differs between any two starts 255 times in 256. Not
/// from the wall clock: a vehicle computer without an RTC boots at the
/// same saved time again and again (fake-hwclock, no network underwater),
/// so its seconds repeat across reboots of the companion alone, which the
/// autopilot would not see as a restart. Should the OS refuse, the clock's
/// nanoseconds and the process id stand in.
pub fn first_epoch() -> u32 {
    use rand::RngCore;
    let mut b = [0u8; 4];
    match rand::rngs::OsRng.try_fill_bytes(&mut b) {
        Ok(()) => u32::from_le_bytes(b),
        Err(_) => {
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.subsec_nanos());
            nanos ^ std::process::id().rotate_left(16)
        }
    }
}

impl RestartCounter {
    /// A counter whose first epoch is [`first_epoch`].
    pub fn new() -> Self {
        RestartCounter::starting_at(first_epoch())
    }

    /// A counter whose first epoch is `epoch` (tests, replays that must
    /// give the same bytes every run).
    pub fn starting_at(epoch: u32) -> Self {
        RestartCounter {
            epoch,
            seen_ok: false,
            restarting: false,
        }
    }

    /// The epoch the next estimate would get, were it `ok` and no restart.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// Feed every estimate in order; returns the epoch to offer it with.
    pub fn observe(&mut self, est: &PoseEstimate) -> u32 {
        match est.status {
            Status::Initialising | Status::Diverged if self.seen_ok => self.restarting = true,
            Status::Ok => {
                if self.restarting {
                    self.epoch = self.epoch.wrapping_add(1);
                    self.restarting = false;
                }
                self.seen_ok = true;
            }
            _ => {}
        }
        self.epoch
    }

    /// The estimator was reset or replaced by its owner (a new run, a jump
    /// in time, a calibration reload): the next `ok` pose opens a new
    /// epoch, so the autopilot's EKF takes it as a reset rather than as an
    /// outlier. (Before any `ok` pose there is nothing to reset.)
    pub fn reset(&mut self) {
        if self.seen_ok {
            self.restarting = true;
        }
    }
}

/// Why an `ok` pose taken from the outbox was not sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Skip {
    /// A std is missing and the policy is to skip.
    NoStd,
    /// A std is negative or not finite.
    BadStd,
    /// Capture time negative (usec is unsigned).
    BadTime,
    /// A value does not fit a MAVLink float.
    NotFinite,
    /// Within the position rate limit.
    Decimated,
}

impl Skip {
    pub const ALL: [Skip; 5] = [
        Skip::NoStd,
        Skip::BadStd,
        Skip::BadTime,
        Skip::NotFinite,
        Skip::Decimated,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Skip::NoStd => "no_std",
            Skip::BadStd => "bad_std",
            Skip::BadTime => "bad_time",
            Skip::NotFinite => "not_finite",
            Skip::Decimated => "decimated",
        }
    }
    pub fn index(self) -> usize {
        self as usize
    }
}

/// The names of `Outgoing::std`'s six, for log lines.
const STD_NAMES: [&str; 6] = ["x", "y", "z", "pitch", "yaw", "surge"];

/// Why `o` was skipped for `k`, in words, for the journal (worded only
/// when a line is due). `speed`: the skip was VISION_SPEED_ESTIMATE's,
/// which also needs the surge's std.
pub fn skip_why(o: &Outgoing, k: Skip, speed: bool) -> String {
    let stds = &o.std[..if speed { 6 } else { 5 }];
    let named = |pick: fn(&Option<f64>) -> bool| {
        let v: Vec<&str> = (stds.iter().zip(STD_NAMES))
            .filter(|(s, _)| pick(s))
            .map(|(_, n)| n)
            .collect();
        if v.is_empty() {
            "the assumed one".to_string()
        } else {
            v.join(", ")
        }
    };
    match k {
        Skip::NoStd => format!(
            "no std for {} (missing_std = \"skip\")",
            named(|s| s.is_none())
        ),
        Skip::BadStd => format!(
            "the std of {} is negative or not finite ({:?})",
            named(|s| s.is_some_and(|v| !(v.is_finite() && v >= 0.0))),
            stds
        ),
        Skip::BadTime => format!(
            "capture time {} s does not fit MAVLink's usec (negative or too large)",
            o.t
        ),
        Skip::NotFinite => format!(
            "a value overflows a MAVLink float (x {} y {} z {} m, std {:?})",
            o.pose.x, o.pose.y, o.pose.z, stds
        ),
        Skip::Decimated => "within the position rate limit".into(),
    }
}

/// The content of VISION_POSITION_ESTIMATE, in NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisionPosition {
    pub usec: u64,
    pub position: NedVec,
    /// Spec v3: the estimate's roll (0 when it has none, as spec v2 sent).
    pub roll: Angle,
    pub pitch: Angle,
    pub heading: Angle,
    pub covariance: [f64; 21],
    pub reset_counter: u8,
}

/// The content of VISION_SPEED_ESTIMATE, in NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisionSpeed {
    pub usec: u64,
    pub velocity: NedVec,
    pub covariance: [f64; 9],
    pub reset_counter: u8,
}

fn usec(t: f64) -> Result<u64, Skip> {
    let us = (t * 1e6).round();
    if us.is_finite() && (0.0..1.8e19).contains(&us) {
        Ok(us as u64)
    } else {
        Err(Skip::BadTime)
    }
}

/// A std that is known, else the policy's stand-in.
fn std_or(v: Option<f64>, assume: Option<f64>) -> Result<f64, Skip> {
    match v.or(assume) {
        None => Err(Skip::NoStd),
        Some(s) if s.is_finite() && s >= 0.0 => Ok(s),
        Some(_) => Err(Skip::BadStd),
    }
}

/// The pose's five std's, filled in per the policy.
fn pose_std(o: &Outgoing, policy: MissingStd) -> Result<PoseStd, Skip> {
    let (pos, ang) = match policy {
        MissingStd::Skip => (None, None),
        MissingStd::Assume {
            position_m, angle, ..
        } => (Some(position_m), Some(angle.deg())),
    };
    Ok(PoseStd {
        x: std_or(o.std[0], pos)?,
        y: std_or(o.std[1], pos)?,
        z: std_or(o.std[2], pos)?,
        pitch: Angle::from_deg(std_or(o.std[3], ang)?),
        yaw: Angle::from_deg(std_or(o.std[4], ang)?),
    })
}

/// VISION_POSITION_ESTIMATE for an outgoing pose.
pub fn vision_position(
    o: &Outgoing,
    site: &Site,
    cfg: &OutputConfig,
) -> Result<VisionPosition, Skip> {
    let std = pose_std(o, cfg.missing_std)?;
    // The estimate's own roll σ when it has one (a std that is not finite
    // is refused as the others are); else the configured figure.
    let roll_std = Angle::from_deg(std_or(o.roll_std, Some(cfg.roll_std.deg()))?);
    let ned = site.pose_ned(&o.pose);
    Ok(VisionPosition {
        usec: usec(o.t)?,
        position: ned.position,
        roll: ned.roll,
        pitch: ned.pitch,
        heading: ned.heading,
        covariance: position_covariance(site, &std, roll_std),
        reset_counter: o.epoch as u8,
    })
}

/// VISION_SPEED_ESTIMATE for an outgoing pose, if it has a surge and the
/// std's it needs.
pub fn vision_speed(o: &Outgoing, site: &Site, cfg: &OutputConfig) -> Result<VisionSpeed, Skip> {
    let surge = o.surge.ok_or(Skip::NoStd)?;
    let assume = match cfg.missing_std {
        MissingStd::Skip => None,
        MissingStd::Assume { surge_mps, .. } => Some(surge_mps),
    };
    let ps = pose_std(o, cfg.missing_std)?;
    let std = SpeedStd {
        surge: std_or(o.std[5], assume)?,
        pitch: ps.pitch,
        yaw: ps.yaw,
        side: cfg.side_speed_std_mps,
    };
    let att = o.pose.attitude();
    let bow = site.bow_ned(&att).0;
    Ok(VisionSpeed {
        usec: usec(o.t)?,
        velocity: NedVec([surge * bow[0], surge * bow[1], surge * bow[2]]),
        covariance: speed_covariance(site, &att, surge, &std),
        reset_counter: o.epoch as u8,
    })
}

/// f64 → f32 for the wire, refusing what f32 cannot hold.
fn f32s<const N: usize>(v: &[f64; N]) -> Result<[f32; N], Skip> {
    let out: [f32; N] = std::array::from_fn(|k| v[k] as f32);
    if out.iter().all(|x| x.is_finite()) {
        Ok(out)
    } else {
        Err(Skip::NotFinite)
    }
}

impl VisionPosition {
    pub fn message(&self) -> Result<MavMessage, Skip> {
        let [x, y, z] = f32s(&self.position.0)?;
        Ok(MavMessage::VISION_POSITION_ESTIMATE(
            VISION_POSITION_ESTIMATE_DATA {
                usec: self.usec,
                x,
                y,
                z,
                roll: self.roll.rad() as f32,
                pitch: self.pitch.rad() as f32,
                yaw: self.heading.rad() as f32,
                covariance: f32s(&self.covariance)?,
                reset_counter: self.reset_counter,
            },
        ))
    }
}

impl VisionSpeed {
    pub fn message(&self) -> Result<MavMessage, Skip> {
        let [x, y, z] = f32s(&self.velocity.0)?;
        Ok(MavMessage::VISION_SPEED_ESTIMATE(
            VISION_SPEED_ESTIMATE_DATA {
                usec: self.usec,
                x,
                y,
                z,
                covariance: f32s(&self.covariance)?,
                reset_counter: self.reset_counter,
            },
        ))
    }
}

/// HEARTBEAT of an onboard component (not an autopilot); `active` while
/// poses are going out, standby otherwise.
pub fn heartbeat(active: bool) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: if active {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        },
        mavlink_version: 3,
    })
}

/// The answer to the autopilot's TIMESYNC request `ts1` (its time, echoed)
/// from (system, component): `tc1` our time in ns, on the clock `usec` is
/// on ([`monotonic_ns`]), so PX4 and ArduPilot can map our estimates'
/// capture times to theirs and measure the link's round trip.
pub fn timesync_reply(ts1: i64, tc1: i64, to: (u8, u8)) -> MavMessage {
    MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1,
        ts1,
        target_system: to.0,
        target_component: to.1,
    })
}

/// CLOCK_MONOTONIC in ns: the clock live frames are stamped on (seconds
/// since boot, `lightpose_hal::clock`), so the clock of our `usec`.
pub fn monotonic_ns() -> i64 {
    use nix::sys::time::TimeValLike;
    use nix::time::{clock_gettime, ClockId};
    // num_nanoseconds is i64 on every target: tv_sec and tv_nsec are i32
    // on armv7, where the sum in their own type did not build.
    clock_gettime(ClockId::CLOCK_MONOTONIC).map_or(0, |t| t.num_nanoseconds())
}

/// MAVLink 2 framing with this component's ids and its own sequence
/// numbers, into one reused buffer; signed when signing is configured.
pub struct Encoder {
    system_id: u8,
    component_id: u8,
    seq: u8,
    raw: MAVLinkV2MessageRaw,
    signer: Option<Signer>,
}

impl Encoder {
    pub fn new(system_id: u8, component_id: u8) -> Self {
        Encoder {
            system_id,
            component_id,
            seq: 0,
            raw: MAVLinkV2MessageRaw::new(),
            signer: None,
        }
    }

    /// Frames signed with `signing`'s key (and its link id).
    pub fn signed(self, signing: Option<SigningConfig>) -> Self {
        Encoder {
            signer: signing.map(Signer::new),
            ..self
        }
    }

    /// The signing state, which the frames taken also move (their
    /// timestamps; see [`Signer::check`]).
    pub fn signer_mut(&mut self) -> Option<&mut Signer> {
        self.signer.as_mut()
    }

    /// The frame of `msg`, valid until the next call.
    pub fn encode(&mut self, msg: &MavMessage) -> &[u8] {
        let h = MavHeader {
            system_id: self.system_id as u32,
            component_id: self.component_id,
            sequence: self.seq,
        };
        self.seq = self.seq.wrapping_add(1);
        match &mut self.signer {
            Some(sg) => sg.serialize(&mut self.raw, h, msg, timestamp_now()),
            None => self.raw.serialize_message(h, msg),
        }
        self.raw.raw_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::covariance::upper_index;

    fn est(status: Status) -> PoseEstimate {
        PoseEstimate::empty(0, 1.0, status, "test")
    }

    /// A daemon that starts again must not start at the `reset_counter` it
    /// started at before (0 every time, or the seconds of a clock that
    /// boots at the same saved time): two counters made in the same second
    /// differ on the wire. Each pair collides 1 time in 256, so 7 or more
    /// collisions in 64 pairs come about once in 10^8 runs; a clock's
    /// seconds would collide in nearly all.
    #[test]
    fn the_first_epoch_does_not_come_from_the_clock() {
        let differ = (0..64)
            .filter(|_| {
                let (a, b) = (RestartCounter::new(), RestartCounter::default());
                a.epoch() as u8 != b.epoch() as u8
            })
            .count();
        assert!(differ >= 58, "{differ} of 64 pairs differ");
        let mut c = RestartCounter::new();
        assert_eq!(c.observe(&est(Status::Ok)), c.epoch());
    }

    /// The journal's line for a skipped pose names what was wrong.
    #[test]
    fn a_skip_is_worded_with_its_cause() {
        let mut o = Outgoing {
            seq: 3,
            t: 1.0,
            pose: Pose::new(1.0, 2.0, 3.0, Angle::ZERO, Angle::ZERO),
            surge: Some(0.2),
            std: [Some(0.1), None, Some(0.1), Some(1.0), None, None],
            roll_std: None,
            epoch: 0,
        };
        let why = skip_why(&o, Skip::NoStd, false);
        assert_eq!(why, "no std for y, yaw (missing_std = \"skip\")");
        assert!(skip_why(&o, Skip::NoStd, true).contains("y, yaw, surge"));
        o.std = [
            Some(0.1),
            Some(-1.0),
            Some(0.1),
            Some(1.0),
            Some(f64::NAN),
            None,
        ];
        let why = skip_why(&o, Skip::BadStd, false);
        assert!(why.starts_with("the std of y, yaw is negative"), "{why}");
        o.t = -2.0;
        assert!(skip_why(&o, Skip::BadTime, false).contains("-2 s"));
    }

    /// A calibration reload replaces the estimator: `reset` makes the next
    /// `ok` pose a new epoch even when the new estimator is `ok` at once.
    #[test]
    fn a_reset_opens_a_new_epoch_at_the_next_ok_pose() {
        let mut c = RestartCounter::starting_at(255);
        c.reset(); // before any ok pose: nothing to reset
        assert_eq!(c.observe(&est(Status::Ok)), 255);
        assert_eq!(c.observe(&est(Status::Ok)), 255);
        c.reset();
        // reset_counter is the low byte: 255 → 0.
        assert_eq!(c.observe(&est(Status::Ok)) as u8, 0);
        assert_eq!(c.observe(&est(Status::Ok)), 256);
        // An estimator that starts over by itself.
        assert_eq!(c.observe(&est(Status::Initialising)), 256);
        assert_eq!(c.observe(&est(Status::Ok)), 257);
    }

    /// Spec v3: VISION_POSITION_ESTIMATE carries the estimate's roll and
    /// its σ; without them roll 0 and the configured σ, as spec v2 sent.
    #[test]
    fn roll_and_its_std_go_out_with_the_pose() {
        let site = Site::new(Angle::from_deg(30.0), 3.0);
        let cfg = OutputConfig::default();
        let mut e = est(Status::Ok);
        (e.x, e.y, e.z, e.pitch_deg, e.yaw_deg) =
            (Some(5.0), Some(0.5), Some(0.2), Some(3.0), Some(-4.0));
        (e.std.x, e.std.y, e.std.z, e.std.pitch, e.std.yaw) =
            (Some(0.2), Some(0.05), Some(0.05), Some(1.0), Some(1.0));
        let sent = |e: &PoseEstimate| {
            let outbox = PoseOutbox::default();
            assert_eq!(outbox.offer(e, 0), Offer::Queued);
            let o = outbox.take_new(&mut 0).expect("offered");
            let v = vision_position(&o, &site, &cfg).expect("sent");
            let MavMessage::VISION_POSITION_ESTIMATE(m) = v.message().expect("message") else {
                panic!("not a VPE")
            };
            (o, m)
        };
        let var = |m: &VISION_POSITION_ESTIMATE_DATA| m.covariance[upper_index(3, 3)] as f64;
        // A v2 estimate: roll 0, the configured 5°.
        let (o, m) = sent(&e);
        assert_eq!((o.pose.roll, o.roll_std), (Angle::ZERO, None));
        assert_eq!(m.roll, 0.0);
        assert!((var(&m) - 5f64.to_radians().powi(2)).abs() < 1e-9);
        // Roll known, without a σ: the roll, the configured σ.
        e.roll_deg = Some(-7.5);
        let (_, m) = sent(&e);
        assert!((m.roll as f64 - (-7.5f64).to_radians()).abs() < 1e-7);
        assert!((var(&m) - 5f64.to_radians().powi(2)).abs() < 1e-9);
        // With its σ: that σ.
        e.std.roll = Some(0.4);
        let (o, m) = sent(&e);
        assert_eq!(o.roll_std, Some(0.4));
        assert!((var(&m) - 0.4f64.to_radians().powi(2)).abs() < 1e-12);
        assert!(m.covariance.iter().all(|c| c.is_finite()));
        // Roll is B's and NED's alike: pitch and heading are unchanged by it.
        let level = {
            let mut l = e;
            l.roll_deg = None;
            sent(&l).1
        };
        assert_eq!((m.pitch, m.yaw), (level.pitch, level.yaw));
        // A negative σ is refused as the others are; one not finite is no
        // σ (the outbox's words hold NaN as none): the configured one.
        e.std.roll = Some(-1.0);
        let outbox = PoseOutbox::default();
        outbox.offer(&e, 0);
        let o = outbox.take_new(&mut 0).expect("offered");
        assert_eq!(vision_position(&o, &site, &cfg), Err(Skip::BadStd));
        e.std.roll = Some(f64::NAN);
        let (_, m) = sent(&e);
        assert!((var(&m) - 5f64.to_radians().powi(2)).abs() < 1e-9);
        // A roll that is not finite makes the pose incomplete.
        e.roll_deg = Some(f64::INFINITY);
        assert_eq!(PoseOutbox::default().offer(&e, 0), Offer::Incomplete);
    }
}
