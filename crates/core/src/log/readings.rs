//! The vehicle's own readings on a FRAME line (attitude, depth, velocity),
//! each taken apart by hand so that a malformed one costs that reading
//! (counted by the reader), never the frame's light.

use super::rawline::{Num, Reading, Std};
use crate::frame::{AttitudeStd, DepthReading, VelocityReading};
use crate::{Angle, AttitudeReading, BodyVec};

/// The named numbers of a reading object (`{"z":..}`, `{"fwd":..,..}`),
/// with its optional `std` object (else the frame's), or why not.
fn reading_fields<const N: usize>(
    v: &Reading,
    what: &str,
    keys: [&str; N],
    frame_std: Option<&Std>,
) -> Result<([f64; N], Option<[f64; N]>), String> {
    let Reading::Object { fields, std } = v else {
        return Err(format!("{what} is not an object"));
    };
    let mut vals = [0.0; N];
    for (slot, key) in vals.iter_mut().zip(keys) {
        *slot = match fields.get(key) {
            Num::Number(x) => x,
            _ => return Err(format!("{what} has no number {key}")),
        };
    }
    // The reading's own `std`, even null, stands before the frame's.
    let std = match std {
        Std::Absent => frame_std,
        own => Some(own),
    };
    let std = match std {
        None | Some(Std::Absent | Std::Null) => None,
        Some(Std::NotObject) => return Err(format!("{what} std is not an object")),
        Some(Std::Object(so)) => {
            let mut out = [0.0; N];
            let mut any = false;
            for (slot, key) in out.iter_mut().zip(keys) {
                match so.get(key) {
                    Num::Absent | Num::Null => *slot = f64::NAN,
                    Num::Number(x) => {
                        *slot = x;
                        any = true;
                    }
                    Num::Other => return Err(format!("{what} std.{key} is not a number")),
                }
            }
            // A frame-level std that names none of this reading's keys is
            // about another reading; a partial one is refused below.
            if !any {
                None
            } else if out.iter().any(|x| x.is_nan()) {
                return Err(format!("{what} std must give all of {}", keys.join(", ")));
            } else {
                Some(out)
            }
        }
    };
    Ok((vals, std))
}

/// An angle as a log line gives it back: written in degrees, read with
/// `Angle::from_deg`. That round trip can move an angle by an ulp, so the
/// live path takes its fixed point before the estimator sees a reading
/// ([`as_logged`]); a recording then replays to the same poses, bit for
/// bit. Found in a few round trips; should one cycle instead, the last is
/// kept (off by an ulp, as before).
fn angle_as_logged(a: Angle) -> Angle {
    let mut r = a;
    for _ in 0..4 {
        let back = Angle::from_deg(r.deg());
        if back.rad().to_bits() == r.rad().to_bits() || !back.rad().is_finite() {
            return back;
        }
        r = back;
    }
    r
}

/// The frame's readings as its log line reads back: the attitude and its
/// std at the fixed point of the degrees round trip (depth and velocity
/// are written as they are, exactly). Called on the live path before the
/// estimator and the recorder see a frame.
pub fn as_logged(frame: &mut crate::Frame) {
    if let Some(a) = frame.attitude.as_mut() {
        a.pitch = angle_as_logged(a.pitch);
        a.yaw = angle_as_logged(a.yaw);
        a.roll = a.roll.map(angle_as_logged);
        if let Some(s) = a.std.as_mut() {
            s.pitch = angle_as_logged(s.pitch);
            s.yaw = angle_as_logged(s.yaw);
        }
    }
}

pub(super) fn parse_attitude(v: &Reading, fs: Option<&Std>) -> Result<AttitudeReading, String> {
    let ([p, y], std) = reading_fields(v, "attitude", ["pitch", "yaw"], fs)?;
    // Spec v3: roll is optional; absent or null is not measured.
    let roll = match v {
        Reading::Object { fields, .. } => match fields.get("roll") {
            Num::Absent | Num::Null => None,
            Num::Number(r) => Some(Angle::from_deg(r)),
            Num::Other => return Err("attitude roll is not a number".into()),
        },
        Reading::NotObject => None,
    };
    Ok(AttitudeReading {
        pitch: Angle::from_deg(p),
        yaw: Angle::from_deg(y),
        roll,
        std: std.map(|[sp, sy]| AttitudeStd {
            pitch: Angle::from_deg(sp),
            yaw: Angle::from_deg(sy),
        }),
    })
}

pub(super) fn parse_depth(v: &Reading, fs: Option<&Std>) -> Result<DepthReading, String> {
    let ([z], std) = reading_fields(v, "depth", ["z"], fs)?;
    Ok(DepthReading {
        z,
        std: std.map(|[s]| s),
    })
}

pub(super) fn parse_velocity(v: &Reading, fs: Option<&Std>) -> Result<VelocityReading, String> {
    let (fwd, std) = reading_fields(v, "velocity", ["fwd", "right", "down"], fs)?;
    Ok(VelocityReading {
        v: BodyVec(fwd),
        std: std.map(BodyVec),
    })
}
