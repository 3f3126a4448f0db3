//! What the autopilot's messages say about the vehicle, in the frames of
//! MODEL.md, and why a message is refused.
//!
//! - `ATTITUDE` → pitch, roll (spec v3: MAVLink's roll, starboard side
//!   down, is MODEL.md's), and yaw in B = heading − h − 180°, with pitch's
//!   and yaw's rates from the body rates (the roll enters those), so that
//!   the frame thread can carry the attitude to a frame's capture. Roll is
//!   attached as it was read, not carried (a few tenths of a degree at a
//!   wave's roll rate over the ≤ 0.25 s of `attitude_max_age_s`).
//! - `GLOBAL_POSITION_INT.relative_alt` (the default) or `VFR_HUD.alt`
//!   (below the surface negative) → z in B = d_b − depth. The depth
//!   sensor's lever arm is not applied here: the estimator applies it in
//!   its measurement model with its own attitude estimate.
//! - `SCALED_PRESSURE2.temperature` (c°C, the external pressure sensor's)
//!   → water temperature.

use crate::ned::Site;
use crate::readings::AttitudeRates;
use lightpose_core::{Angle, AttitudeReading, DepthReading};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavType, ATTITUDE_DATA, GLOBAL_POSITION_INT_DATA, HEARTBEAT_DATA,
    SCALED_PRESSURE2_DATA, TIMESYNC_DATA, VFR_HUD_DATA,
};
use mavlink::MessageData;
use std::f64::consts::PI;

use super::scan::RawFrame;

/// Where the vehicle's depth comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthSource {
    /// `VFR_HUD.alt` (m). ArduSub sends `get_alt_msl()` there: the EKF
    /// origin's altitude plus the EKF's height, and exactly 0 when it has
    /// no depth sensor or no EKF origin. Right only with an origin at
    /// altitude 0 (sea level); a reading of exactly 0 is refused
    /// ([`Refusal::VfrHudZero`]).
    VfrHud,
    /// `GLOBAL_POSITION_INT.relative_alt` (mm above home; ArduPilot falls
    /// back to the barometer's depth against its surface pressure when no
    /// home is set; PX4 the same field): −depth either way. The default.
    GlobalPositionInt,
    /// No depth from the autopilot.
    Off,
}

/// Which inputs to take and what to believe.
#[derive(Debug, Clone, PartialEq)]
pub struct InputConfig {
    pub attitude: bool,
    pub depth: DepthSource,
    pub temperature: bool,
    /// The autopilot's system id; when unset it is learned from the first
    /// autopilot HEARTBEAT of `autopilot_component` (see [`origin`]).
    pub autopilot_system: Option<u8>,
    /// The autopilot's component id (1, MAV_COMP_ID_AUTOPILOT1, by
    /// default): a GCS, a camera or a second flight controller on the
    /// same system is not the autopilot.
    pub autopilot_component: u8,
    /// Depths (m, positive down) outside this range are refused.
    pub depth_range_m: [f64; 2],
    /// Water temperatures (°C) outside this range are refused.
    pub temperature_range_c: [f64; 2],
}

impl Default for InputConfig {
    fn default() -> Self {
        InputConfig {
            attitude: true,
            depth: DepthSource::GlobalPositionInt,
            temperature: true,
            autopilot_system: None,
            autopilot_component: 1,
            depth_range_m: [-10.0, 1000.0],
            temperature_range_c: [-5.0, 50.0],
        }
    }
}

/// Why a message (or a frame candidate) was not used. Each is a STATUS
/// counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Refusal {
    BadCrc,
    UnknownMessage,
    BadFlags,
    OtherSystem,
    /// The autopilot's system, but another component (a GCS, a gimbal).
    OtherComponent,
    /// Before the autopilot is known (configured or learned from its
    /// HEARTBEAT), nothing but a HEARTBEAT is taken.
    AutopilotUnknown,
    /// On `udpin`, a datagram from an address other than the autopilot's
    /// while the autopilot still speaks (see `link::PEER_SILENCE`).
    OtherAddress,
    Malformed,
    NotFinite,
    AngleOutOfRange,
    DepthOutOfRange,
    TemperatureOutOfRange,
    /// `VFR_HUD.alt` exactly 0: what ArduSub sends with no depth sensor or
    /// no EKF origin, not a depth.
    VfrHudZero,
    /// Signing is configured and the frame has no signature.
    Unsigned,
    /// A signature that is not the configured key's.
    BadSignature,
    /// A good signature on a timestamp its stream has had (a frame played
    /// again).
    Replayed,
    /// A good signature on a stream first heard over a minute behind our
    /// signing clock (an old recording, or an autopilot whose clock is).
    SigningClockBehind,
}

impl Refusal {
    pub const ALL: [Refusal; 17] = [
        Refusal::BadCrc,
        Refusal::UnknownMessage,
        Refusal::BadFlags,
        Refusal::OtherSystem,
        Refusal::OtherComponent,
        Refusal::AutopilotUnknown,
        Refusal::OtherAddress,
        Refusal::Malformed,
        Refusal::NotFinite,
        Refusal::AngleOutOfRange,
        Refusal::DepthOutOfRange,
        Refusal::TemperatureOutOfRange,
        Refusal::VfrHudZero,
        Refusal::Unsigned,
        Refusal::BadSignature,
        Refusal::Replayed,
        Refusal::SigningClockBehind,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Refusal::BadCrc => "bad_crc",
            Refusal::UnknownMessage => "unknown_message",
            Refusal::BadFlags => "bad_flags",
            Refusal::OtherSystem => "other_system",
            Refusal::OtherComponent => "other_component",
            Refusal::AutopilotUnknown => "autopilot_unknown",
            Refusal::OtherAddress => "other_address",
            Refusal::Malformed => "malformed",
            Refusal::NotFinite => "not_finite",
            Refusal::AngleOutOfRange => "angle_out_of_range",
            Refusal::DepthOutOfRange => "depth_out_of_range",
            Refusal::TemperatureOutOfRange => "temperature_out_of_range",
            Refusal::VfrHudZero => "vfr_hud_zero",
            Refusal::Unsigned => "unsigned",
            Refusal::BadSignature => "bad_signature",
            Refusal::Replayed => "replayed",
            Refusal::SigningClockBehind => "signing_clock_behind",
        }
    }

    pub fn index(self) -> usize {
        self as usize
    }
}

/// A refused message: why, which message, and the offending value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refused {
    pub reason: Refusal,
    pub msg_id: u32,
    pub system: u8,
    /// The value that broke the rule (NaN when the message had none).
    pub value: f64,
}

/// A message that was used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Input {
    /// The attitude in B and its rates, when the message's body rates give
    /// them.
    Attitude(AttitudeReading, Option<AttitudeRates>),
    Depth(DepthReading),
    Temperature(f64),
    /// A HEARTBEAT from an autopilot (not from a GCS or a companion).
    AutopilotHeartbeat,
    /// A TIMESYNC request (`tc1` 0): answered with our time and its `ts1`.
    TimesyncRequest {
        ts1: i64,
    },
    /// A valid message this reader has no use for (or whose input is off).
    Unused,
}

impl Input {
    /// The counter a used message goes to.
    pub fn kind(&self) -> Option<usize> {
        match self {
            Input::Attitude(..) => Some(0),
            Input::Depth(_) => Some(1),
            Input::Temperature(_) => Some(2),
            Input::AutopilotHeartbeat => Some(3),
            Input::TimesyncRequest { .. } => Some(4),
            Input::Unused => None,
        }
    }
}

fn refuse(reason: Refusal, f: &RawFrame, value: f64) -> Refused {
    Refused {
        reason,
        msg_id: f.msg_id,
        system: f.system,
        value,
    }
}

fn decode<D: MessageData>(f: &RawFrame) -> Result<D, Refused> {
    D::deser(f.version, f.payload).map_err(|_| refuse(Refusal::Malformed, f, f64::NAN))
}

/// Whether a frame comes from the autopilot: its component, and its
/// system as configured or else as `learned` (the first autopilot
/// HEARTBEAT's). Anyone on the LAN can send MAVLink (a GCS, a second ROV
/// with the same default ids), and their readings must not reach a pose.
/// Until the system is known only a HEARTBEAT passes, to be told apart.
pub fn origin(f: &RawFrame, cfg: &InputConfig, learned: Option<u8>) -> Result<(), Refused> {
    if f.component != cfg.autopilot_component {
        return Err(refuse(Refusal::OtherComponent, f, f.component as f64));
    }
    match cfg.autopilot_system.or(learned) {
        Some(s) if s != f.system => Err(refuse(Refusal::OtherSystem, f, f.system as f64)),
        Some(_) => Ok(()),
        None if f.msg_id == HEARTBEAT_DATA::ID => Ok(()),
        None => Err(refuse(Refusal::AutopilotUnknown, f, f.system as f64)),
    }
}

/// Interpret one CRC-valid frame of the configured autopilot component
/// (and system, when set); the caller checks the rest with [`origin`].
pub fn interpret(f: &RawFrame, cfg: &InputConfig, site: &Site) -> Result<Input, Refused> {
    if cfg.autopilot_system.is_some_and(|s| s != f.system) {
        return Err(refuse(Refusal::OtherSystem, f, f.system as f64));
    }
    if f.component != cfg.autopilot_component {
        return Err(refuse(Refusal::OtherComponent, f, f.component as f64));
    }
    match f.msg_id {
        ATTITUDE_DATA::ID if cfg.attitude => attitude(f, &decode(f)?, site),
        VFR_HUD_DATA::ID if cfg.depth == DepthSource::VfrHud => {
            let m: VFR_HUD_DATA = decode(f)?;
            if m.alt == 0.0 {
                return Err(refuse(Refusal::VfrHudZero, f, 0.0));
            }
            depth(f, -(m.alt as f64), cfg, site)
        }
        GLOBAL_POSITION_INT_DATA::ID if cfg.depth == DepthSource::GlobalPositionInt => {
            let m: GLOBAL_POSITION_INT_DATA = decode(f)?;
            depth(f, -(m.relative_alt as f64) / 1000.0, cfg, site)
        }
        SCALED_PRESSURE2_DATA::ID if cfg.temperature => {
            let m: SCALED_PRESSURE2_DATA = decode(f)?;
            let c = m.temperature as f64 / 100.0;
            let [lo, hi] = cfg.temperature_range_c;
            if !(lo..=hi).contains(&c) {
                return Err(refuse(Refusal::TemperatureOutOfRange, f, c));
            }
            Ok(Input::Temperature(c))
        }
        TIMESYNC_DATA::ID => {
            let m: TIMESYNC_DATA = decode(f)?;
            // tc1 set: an answer (to another component's request).
            Ok(if m.tc1 == 0 {
                Input::TimesyncRequest { ts1: m.ts1 }
            } else {
                Input::Unused
            })
        }
        HEARTBEAT_DATA::ID => Ok(if is_autopilot_heartbeat(f) {
            Input::AutopilotHeartbeat
        } else {
            Input::Unused
        }),
        _ => Ok(Input::Unused),
    }
}

/// Whether `f` is a HEARTBEAT of an autopilot: its `autopilot` field not
/// MAV_AUTOPILOT_INVALID (what GCSs and companions send) and its type not
/// a GCS (whatever its component).
pub fn is_autopilot_heartbeat(f: &RawFrame) -> bool {
    f.msg_id == HEARTBEAT_DATA::ID
        && decode::<HEARTBEAT_DATA>(f).is_ok_and(|m| {
            m.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID && m.mavtype != MavType::MAV_TYPE_GCS
        })
}

fn attitude(f: &RawFrame, m: &ATTITUDE_DATA, site: &Site) -> Result<Input, Refused> {
    let (roll, pitch, yaw) = (m.roll as f64, m.pitch as f64, m.yaw as f64);
    for v in [roll, pitch, yaw] {
        if !v.is_finite() {
            return Err(refuse(Refusal::NotFinite, f, v));
        }
    }
    // ATTITUDE is in radians: roll and yaw within ±π, pitch within ±π/2
    // (yaw also accepted in 0..2π; a small margin for float rounding).
    let eps = 1e-3;
    if pitch.abs() > PI / 2.0 + eps {
        return Err(refuse(Refusal::AngleOutOfRange, f, pitch));
    }
    if roll.abs() > PI + eps {
        return Err(refuse(Refusal::AngleOutOfRange, f, roll));
    }
    if yaw.abs() > 2.0 * PI + eps {
        return Err(refuse(Refusal::AngleOutOfRange, f, yaw));
    }
    // The rates are a bonus: a message without usable ones (not finite,
    // near θ = ±90°) still gives its attitude, attached as it is.
    let rates = AttitudeRates::from_body(roll, pitch, m.pitchspeed as f64, m.yawspeed as f64);
    let mut reading =
        AttitudeReading::new(Angle::from_rad(pitch), site.yaw_b(Angle::from_rad(yaw)));
    // Roll about the bow is the same angle in B and in NED (R_BV's last
    // factor, Rx(φ), either way).
    reading.roll = Some(Angle::from_rad(roll));
    Ok(Input::Attitude(reading, rates))
}

fn depth(f: &RawFrame, depth_m: f64, cfg: &InputConfig, site: &Site) -> Result<Input, Refused> {
    if !depth_m.is_finite() {
        return Err(refuse(Refusal::NotFinite, f, depth_m));
    }
    let [lo, hi] = cfg.depth_range_m;
    if !(lo..=hi).contains(&depth_m) {
        return Err(refuse(Refusal::DepthOutOfRange, f, depth_m));
    }
    Ok(Input::Depth(DepthReading::new(site.z_from_depth(depth_m))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::MavlinkVersion;

    fn raw<D: MessageData>(m: &D, buf: &mut [u8; 255]) -> usize {
        m.ser(MavlinkVersion::V2, buf)
    }

    fn frame(id: u32, system: u8, payload: &[u8]) -> RawFrame<'_> {
        RawFrame {
            version: MavlinkVersion::V2,
            seq: 0,
            system,
            component: 1,
            msg_id: id,
            payload,
            bytes: payload,
        }
    }

    #[test]
    fn attitude_is_referred_to_the_beam() {
        let site = Site::new(Angle::from_deg(30.0), 3.0);
        let mut buf = [0u8; 255];
        let m = ATTITUDE_DATA {
            pitch: 0.1,
            yaw: 200f32.to_radians() - 2.0 * std::f32::consts::PI, // −160°
            ..Default::default()
        };
        let n = raw(&m, &mut buf);
        let got = interpret(&frame(30, 1, &buf[..n]), &InputConfig::default(), &site);
        let Ok(Input::Attitude(a, w)) = got else {
            panic!("{got:?}")
        };
        // −160° − 30° − 180° = −370° ≡ −10°
        assert!((a.yaw.deg() + 10.0).abs() < 1e-4, "{}", a.yaw.deg());
        assert!((a.pitch.rad() - 0.1).abs() < 1e-7);
        // Still: zero rates, not none.
        assert_eq!(
            w,
            Some(AttitudeRates {
                pitch: 0.0,
                yaw: 0.0
            })
        );
    }

    /// Audit: ATTITUDE's body rates were dropped, so nothing could carry a
    /// heading to a frame's capture. They become B's pitch and yaw rates
    /// (the heading's rate: yaw in B is the heading less a constant).
    #[test]
    fn attitude_rates_come_from_the_body_rates() {
        let site = Site::new(Angle::from_deg(30.0), 3.0);
        let mut buf = [0u8; 255];
        let rolled = 20f32.to_radians();
        let m = ATTITUDE_DATA {
            roll: rolled,
            pitch: 0.1,
            yaw: 1.0,
            rollspeed: 0.7,
            pitchspeed: 0.2,
            yawspeed: 0.5,
            ..Default::default()
        };
        let n = raw(&m, &mut buf);
        let got = interpret(&frame(30, 1, &buf[..n]), &InputConfig::default(), &site);
        let Ok(Input::Attitude(a, Some(w))) = got else {
            panic!("{got:?}")
        };
        // Spec v3: the roll itself goes on the reading, as sent.
        assert_eq!(a.roll.map(|r| r.rad()), Some(rolled as f64));
        let (sr, cr) = (rolled as f64).sin_cos();
        let want_pitch = 0.2f32 as f64 * cr - 0.5f32 as f64 * sr;
        let want_yaw = (0.2f32 as f64 * sr + 0.5f32 as f64 * cr) / (0.1f32 as f64).cos();
        assert!((w.pitch - want_pitch).abs() < 1e-9, "{w:?}");
        assert!((w.yaw - want_yaw).abs() < 1e-9, "{w:?}");
        // A NaN rate costs the rates, not the attitude.
        let n = raw(
            &ATTITUDE_DATA {
                yawspeed: f32::NAN,
                ..m
            },
            &mut buf,
        );
        let got = interpret(&frame(30, 1, &buf[..n]), &InputConfig::default(), &site);
        assert!(matches!(got, Ok(Input::Attitude(_, None))), "{got:?}");
    }

    #[test]
    fn bad_values_are_refused_with_their_reason() {
        let site = Site::new(Angle::ZERO, 3.0);
        let cfg = InputConfig::default();
        let mut buf = [0u8; 255];
        let n = raw(
            &ATTITUDE_DATA {
                pitch: f32::NAN,
                ..Default::default()
            },
            &mut buf,
        );
        let r = interpret(&frame(30, 1, &buf[..n]), &cfg, &site).unwrap_err();
        assert_eq!(r.reason, Refusal::NotFinite);
        let n = raw(
            &ATTITUDE_DATA {
                pitch: 2.0,
                ..Default::default()
            },
            &mut buf,
        );
        let r = interpret(&frame(30, 1, &buf[..n]), &cfg, &site).unwrap_err();
        assert_eq!(r.reason, Refusal::AngleOutOfRange);
        let n = raw(
            &GLOBAL_POSITION_INT_DATA {
                relative_alt: -5_000_000,
                ..Default::default()
            },
            &mut buf,
        );
        let r = interpret(&frame(33, 1, &buf[..n]), &cfg, &site).unwrap_err();
        assert_eq!((r.reason, r.value), (Refusal::DepthOutOfRange, 5000.0));
        let n = raw(
            &SCALED_PRESSURE2_DATA {
                temperature: 9000,
                ..Default::default()
            },
            &mut buf,
        );
        let r = interpret(&frame(137, 1, &buf[..n]), &cfg, &site).unwrap_err();
        assert_eq!(r.reason, Refusal::TemperatureOutOfRange);
        let only_1 = InputConfig {
            autopilot_system: Some(1),
            ..cfg
        };
        let r = interpret(&frame(137, 2, &buf[..n]), &only_1, &site).unwrap_err();
        assert_eq!(r.reason, Refusal::OtherSystem);
    }

    /// Audit: any system and component were trusted. Only the autopilot's
    /// (system, component) passes; before its system is known, only a
    /// HEARTBEAT (which may tell it).
    #[test]
    fn only_the_autopilot_passes_origin() {
        let cfg = InputConfig::default();
        let mut buf = [0u8; 255];
        let n = raw(&ATTITUDE_DATA::default(), &mut buf);
        let of = |system, component| RawFrame {
            component,
            ..frame(30, system, &buf[..n])
        };
        let why = |f: &RawFrame, learned| origin(f, &cfg, learned).map_err(|r| r.reason);
        assert_eq!(why(&of(1, 1), Some(1)), Ok(()));
        assert_eq!(why(&of(2, 1), Some(1)), Err(Refusal::OtherSystem));
        assert_eq!(why(&of(1, 190), Some(1)), Err(Refusal::OtherComponent));
        assert_eq!(why(&of(1, 1), None), Err(Refusal::AutopilotUnknown));
        let hb = RawFrame {
            msg_id: HEARTBEAT_DATA::ID,
            ..of(1, 1)
        };
        assert_eq!(why(&hb, None), Ok(()));
        // A configured system needs no HEARTBEAT; a configured component.
        let cfg = InputConfig {
            autopilot_system: Some(3),
            autopilot_component: 2,
            ..cfg
        };
        assert!(origin(&of(3, 2), &cfg, None).is_ok());
        let r = origin(&of(3, 1), &cfg, None).map_err(|r| r.reason);
        assert_eq!(r, Err(Refusal::OtherComponent));
    }

    /// Audit: a roll out of range was refused with the yaw's value, so
    /// STATUS's `last_error` showed a number that was within range.
    #[test]
    fn an_angle_out_of_range_is_refused_with_its_own_value() {
        let site = Site::new(Angle::ZERO, 3.0);
        let cfg = InputConfig::default();
        let mut buf = [0u8; 255];
        for (roll, pitch, yaw, bad) in [
            (4.0f32, 0.1f32, 0.5f32, 4.0f32),
            (-4.0, 0.1, 0.5, -4.0),
            (0.2, 0.1, 7.0, 7.0),
            (0.2, -1.7, 0.5, -1.7),
        ] {
            let n = raw(
                &ATTITUDE_DATA {
                    roll,
                    pitch,
                    yaw,
                    ..Default::default()
                },
                &mut buf,
            );
            let r = interpret(&frame(30, 1, &buf[..n]), &cfg, &site).unwrap_err();
            assert_eq!(
                (r.reason, r.value),
                (Refusal::AngleOutOfRange, bad as f64),
                "roll {roll} pitch {pitch} yaw {yaw}"
            );
        }
    }

    #[test]
    fn depth_comes_from_the_configured_message_only() {
        let site = Site::new(Angle::ZERO, 3.0);
        let mut buf = [0u8; 255];
        let n = raw(
            &GLOBAL_POSITION_INT_DATA {
                relative_alt: -2500,
                ..Default::default()
            },
            &mut buf,
        );
        let gpi = frame(33, 1, &buf[..n]);
        // GLOBAL_POSITION_INT is the default: −2500 mm is 2.5 m deep.
        assert_eq!(
            interpret(&gpi, &InputConfig::default(), &site),
            Ok(Input::Depth(DepthReading::new(0.5)))
        );
        let vfr = InputConfig {
            depth: DepthSource::VfrHud,
            ..InputConfig::default()
        };
        assert_eq!(interpret(&gpi, &vfr, &site), Ok(Input::Unused));
        let mut buf2 = [0u8; 255];
        let n = raw(
            &VFR_HUD_DATA {
                alt: -2.6,
                ..Default::default()
            },
            &mut buf2,
        );
        let hud = frame(74, 1, &buf2[..n]);
        assert_eq!(
            interpret(&hud, &InputConfig::default(), &site),
            Ok(Input::Unused)
        );
        let Ok(Input::Depth(d)) = interpret(&hud, &vfr, &site) else {
            panic!("VFR_HUD depth")
        };
        assert!((d.z - 0.4).abs() < 1e-6, "{}", d.z);
    }

    /// ArduSub's VFR_HUD.alt is exactly 0 without a depth sensor or an EKF
    /// origin: no depth, and taking it would put the vehicle at the
    /// beacon's depth. relative_alt 0 is the surface, a depth.
    #[test]
    fn a_vfr_hud_alt_of_exactly_zero_is_refused() {
        let site = Site::new(Angle::ZERO, 3.0);
        let vfr = InputConfig {
            depth: DepthSource::VfrHud,
            ..InputConfig::default()
        };
        let mut buf = [0u8; 255];
        for alt in [0.0f32, -0.0] {
            let n = raw(
                &VFR_HUD_DATA {
                    alt,
                    ..Default::default()
                },
                &mut buf,
            );
            let r = interpret(&frame(74, 1, &buf[..n]), &vfr, &site).unwrap_err();
            assert_eq!(r.reason, Refusal::VfrHudZero);
            assert_eq!(r.reason.as_str(), "vfr_hud_zero");
        }
        let n = raw(
            &VFR_HUD_DATA {
                alt: -0.01,
                ..Default::default()
            },
            &mut buf,
        );
        assert!(matches!(
            interpret(&frame(74, 1, &buf[..n]), &vfr, &site),
            Ok(Input::Depth(_))
        ));
        let n = raw(&GLOBAL_POSITION_INT_DATA::default(), &mut buf);
        assert_eq!(
            interpret(&frame(33, 1, &buf[..n]), &InputConfig::default(), &site),
            Ok(Input::Depth(DepthReading::new(3.0)))
        );
    }
}
