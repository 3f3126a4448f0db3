//! The vehicle's own readings on a FRAME line (attitude, depth, velocity),
//! each taken apart by hand so that a malformed one costs that reading
//! (counted by the reader), never the frame's light.

use crate::frame::{AttitudeStd, DepthReading, VelocityReading};
use crate::{Angle, AttitudeReading, BodyVec};

/// The named numbers of a reading object (`{"z":..}`, `{"fwd":..,..}`),
/// with its optional `std` object, or why not.
fn reading_fields<const N: usize>(
    v: &serde_json::Value,
    what: &str,
    keys: [&str; N],
    frame_std: Option<&serde_json::Value>,
) -> Result<([f64; N], Option<[f64; N]>), String> {
    let obj = v
        .as_object()
        .ok_or_else(|| format!("{what} is not an object"))?;
    let mut vals = [0.0; N];
    for (slot, key) in vals.iter_mut().zip(keys) {
        *slot = obj
            .get(key)
            .and_then(|x| x.as_f64())
            .ok_or_else(|| format!("{what} has no number {key}"))?;
    }
    let std = match obj.get("std").or(frame_std) {
        None | Some(serde_json::Value::Null) => None,
        Some(sv) => {
            let so = sv
                .as_object()
                .ok_or_else(|| format!("{what} std is not an object"))?;
            let mut out = [0.0; N];
            let mut any = false;
            for (slot, key) in out.iter_mut().zip(keys) {
                match so.get(key) {
                    None | Some(serde_json::Value::Null) => *slot = f64::NAN,
                    Some(x) => {
                        *slot = x
                            .as_f64()
                            .ok_or_else(|| format!("{what} std.{key} is not a number"))?;
                        any = true;
                    }
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

pub(super) fn parse_attitude(
    v: &serde_json::Value,
    fs: Option<&serde_json::Value>,
) -> Result<AttitudeReading, String> {
    let ([p, y], std) = reading_fields(v, "attitude", ["pitch", "yaw"], fs)?;
    Ok(AttitudeReading {
        pitch: Angle::from_deg(p),
        yaw: Angle::from_deg(y),
        std: std.map(|[sp, sy]| AttitudeStd {
            pitch: Angle::from_deg(sp),
            yaw: Angle::from_deg(sy),
        }),
    })
}

pub(super) fn parse_depth(
    v: &serde_json::Value,
    fs: Option<&serde_json::Value>,
) -> Result<DepthReading, String> {
    let ([z], std) = reading_fields(v, "depth", ["z"], fs)?;
    Ok(DepthReading {
        z,
        std: std.map(|[s]| s),
    })
}

pub(super) fn parse_velocity(
    v: &serde_json::Value,
    fs: Option<&serde_json::Value>,
) -> Result<VelocityReading, String> {
    let (fwd, std) = reading_fields(v, "velocity", ["fwd", "right", "down"], fs)?;
    Ok(VelocityReading {
        v: BodyVec(fwd),
        std: std.map(BodyVec),
    })
}
