//! A stand-in autopilot, for trying the link on a desk (`lightpose
//! fake-autopilot`): the messages an ArduSub autopilot would send for a
//! known vehicle pose, what comes back decoded, and how far that is from
//! the truth.

use crate::mav::inbound::DepthSource;
use crate::mav::outbound::{VisionPosition, VisionSpeed};
use crate::mav::scan::RawFrame;
use crate::ned::{wrap_pi, NedPose, NedVec, Site};
use lightpose_core::{Angle, Pose};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, ATTITUDE_DATA,
    GLOBAL_POSITION_INT_DATA, HEARTBEAT_DATA, SCALED_PRESSURE2_DATA, VFR_HUD_DATA,
};
use mavlink::Message;

/// What the autopilot's sensors read (already with whatever noise the
/// caller wants on them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorState {
    pub pitch: Angle,
    /// Compass heading of the bow.
    pub heading: Angle,
    /// Depth of the dome centre below the surface, m.
    pub depth_m: f64,
    pub temp_c: Option<f64>,
}

impl SensorState {
    /// The exact readings of a vehicle at `pose` in B.
    pub fn of(site: &Site, pose: &Pose, temp_c: Option<f64>) -> Self {
        SensorState {
            pitch: pose.pitch,
            heading: site.heading(pose.yaw),
            depth_m: site.depth_from_z(pose.z),
            temp_c,
        }
    }
}

/// ATTITUDE, the depth message and SCALED_PRESSURE2 as ArduSub sends them
/// (`VFR_HUD.alt` as with an EKF origin at sea level).
pub fn autopilot_messages(
    s: &SensorState,
    depth: DepthSource,
    time_boot_ms: u32,
) -> Vec<MavMessage> {
    let mut out = vec![MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms,
        roll: 0.0,
        pitch: s.pitch.rad() as f32,
        yaw: wrap_pi(s.heading).rad() as f32,
        ..Default::default()
    })];
    match depth {
        DepthSource::VfrHud => out.push(MavMessage::VFR_HUD(VFR_HUD_DATA {
            alt: -s.depth_m as f32,
            heading: (s.heading.deg().rem_euclid(360.0)) as i16,
            ..Default::default()
        })),
        DepthSource::GlobalPositionInt => {
            out.push(MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms,
                relative_alt: (-s.depth_m * 1000.0).round() as i32,
                ..Default::default()
            }))
        }
        DepthSource::Off => {}
    }
    if let Some(t) = s.temp_c {
        out.push(MavMessage::SCALED_PRESSURE2(SCALED_PRESSURE2_DATA {
            time_boot_ms,
            press_abs: (1013.25 + 98.1 * s.depth_m) as f32,
            temperature: (t * 100.0).round().clamp(-32768.0, 32767.0) as i16,
            ..Default::default()
        }));
    }
    out
}

/// An ArduSub autopilot's HEARTBEAT.
pub fn autopilot_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 19, // ArduSub MANUAL
        mavtype: MavType::MAV_TYPE_SUBMARINE,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// What a component sent back, decoded.
#[derive(Debug, Clone, PartialEq)]
pub enum Received {
    Position(VisionPosition),
    Speed(VisionSpeed),
    Heartbeat {
        system: u8,
        component: u8,
        mav_type: u32,
        status: u32,
    },
    Other(&'static str),
}

/// Decode a frame the stand-in received (None: it cannot be parsed).
pub fn decode(f: &RawFrame) -> Option<Received> {
    let m = MavMessage::parse(f.version, f.msg_id, f.payload).ok()?;
    let r = match m {
        MavMessage::VISION_POSITION_ESTIMATE(d) => Received::Position(VisionPosition {
            usec: d.usec,
            position: NedVec([d.x as f64, d.y as f64, d.z as f64]),
            roll: Angle::from_rad(d.roll as f64),
            pitch: Angle::from_rad(d.pitch as f64),
            heading: Angle::from_rad(d.yaw as f64),
            covariance: d.covariance.map(|v| v as f64),
            reset_counter: d.reset_counter,
        }),
        MavMessage::VISION_SPEED_ESTIMATE(d) => Received::Speed(VisionSpeed {
            usec: d.usec,
            velocity: NedVec([d.x as f64, d.y as f64, d.z as f64]),
            covariance: d.covariance.map(|v| v as f64),
            reset_counter: d.reset_counter,
        }),
        MavMessage::HEARTBEAT(d) => Received::Heartbeat {
            system: f.system,
            component: f.component,
            mav_type: d.mavtype as u32,
            status: d.system_status as u32,
        },
        other => Received::Other(other.message_name()),
    };
    Some(r)
}

/// Names of the error columns.
pub const ERROR_AXES: [&str; 5] = ["north", "east", "down", "pitch", "heading"];

/// Errors of the estimates against the truth: north, east, down (m),
/// pitch and heading (degrees, heading wrapped).
#[derive(Debug, Clone, Default)]
pub struct ErrorStats {
    cols: [Vec<f64>; 5],
}

impl ErrorStats {
    /// Add one estimate; returns its signed errors.
    pub fn push(&mut self, est: &NedPose, truth: &NedPose) -> [f64; 5] {
        let d = est.position.sub(&truth.position).0;
        let e = [
            d[0],
            d[1],
            d[2],
            (est.pitch - truth.pitch).deg(),
            wrap_pi(est.heading - truth.heading).deg(),
        ];
        for (c, v) in self.cols.iter_mut().zip(e) {
            c.push(v);
        }
        e
    }

    pub fn len(&self) -> usize {
        self.cols[0].len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// 95th percentile of the absolute error per axis (nearest rank).
    pub fn p95(&self) -> [f64; 5] {
        std::array::from_fn(|k| {
            let mut a: Vec<f64> = self.cols[k].iter().map(|v| v.abs()).collect();
            if a.is_empty() {
                return 0.0;
            }
            a.sort_by(f64::total_cmp);
            let rank = ((0.95 * a.len() as f64).ceil() as usize).clamp(1, a.len());
            a[rank - 1]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mav::inbound::{interpret, Input, InputConfig};
    use crate::mav::outbound::Encoder;
    use crate::mav::scan::{Framing, Scanned, Scanner};

    #[test]
    fn the_stand_in_says_what_the_reader_understands() {
        let site = Site::new(Angle::from_deg(75.0), 4.0);
        let pose = Pose::new(6.0, 0.3, -0.4, Angle::from_deg(5.0), Angle::from_deg(-12.0));
        let s = SensorState::of(&site, &pose, Some(9.5));
        let mut enc = Encoder::new(1, 1);
        for depth in [DepthSource::GlobalPositionInt, DepthSource::VfrHud] {
            let mut sc = Scanner::new(Framing::Stream);
            for m in autopilot_messages(&s, depth, 1000) {
                sc.push(enc.encode(&m));
            }
            let cfg = InputConfig {
                depth,
                ..InputConfig::default()
            };
            let mut got = Vec::new();
            while let Some(Scanned::Frame(f)) = sc.next_frame() {
                got.push(interpret(&f, &cfg, &site).unwrap());
            }
            let [Input::Attitude(a, _), Input::Depth(d), Input::Temperature(t)] = got[..] else {
                panic!("{got:?}")
            };
            assert!((a.yaw.deg() + 12.0).abs() < 1e-4 && (a.pitch.deg() - 5.0).abs() < 1e-5);
            assert!((d.z + 0.4).abs() < 1e-6, "{depth:?}: {}", d.z);
            assert_eq!(t, 9.5);
        }
    }

    #[test]
    fn p95_is_the_nearest_rank() {
        let mut e = ErrorStats::default();
        let site = Site::new(Angle::ZERO, 3.0);
        for k in 1..=100 {
            let truth = site.pose_ned(&Pose::default());
            let mut est = truth;
            est.position.0[0] += k as f64 * 0.01;
            e.push(&est, &truth);
        }
        assert!((e.p95()[0] - 0.95).abs() < 1e-9);
        assert_eq!(e.len(), 100);
    }
}
