//! What the station's fit says of its survey: each beacon's residual χ²
//! with the survey as given, and — fitted as a diagnostic, everything else
//! free — the offset of its position and axis that would explain its
//! images best, with σ. The survey itself is never changed: a beacon whose
//! offset is beyond 3σ is named in the report, for the user to resurvey.

use super::problem::{Data, Fitted};
use super::StationFitOptions;
use crate::calibration::station::{CalibratedBeacon, Station, StationCalibration, SurveyCheck};
use crate::calibration::ParamEstimate;

/// How many σ an offset must be to call the survey off.
const SUSPECT_SIGMAS: f64 = 3.0;

/// The `[station]` table of fit `f`.
pub(super) fn calibration(
    data: &Data,
    station: &Station,
    f: &Fitted,
    o: &StationFitOptions,
) -> StationCalibration {
    let l = data.layout(f.scat);
    let deg = 180.0 / std::f64::consts::PI;
    // One diagnostic fit with every beacon's offsets free.
    let diag = o.survey_check.then(|| data.fit(f.scat, Some(&f.p), o));
    let beacons = station
        .beacons
        .iter()
        .enumerate()
        .map(|(b, s)| CalibratedBeacon {
            id: s.id.clone(),
            position_m: s.position_m,
            axis_yaw_deg: s.axis_yaw_deg,
            axis_pitch_deg: s.axis_pitch_deg,
            mod_hz: s.mod_hz,
            v1: Data::estimate(f, l.v1(b), 1.0),
            sigma_b_deg: Data::estimate(f, l.sigma_b(b), deg),
            survey_check: check(data, f, b, &s.id, diag.as_ref()),
            model_rel: super::model_error::model_rel(data, f, b),
        })
        .collect();
    StationCalibration {
        name: station.name.clone(),
        beacons,
        chi2_per_dof: f.chi2_per_dof,
        poses: data.poses(),
        frames: data.frames,
    }
}

/// Beacon `b`'s survey check.
fn check(
    data: &Data,
    f: &Fitted,
    b: usize,
    id: &str,
    diag: Option<&Result<Fitted, crate::calibration::CalibError>>,
) -> SurveyCheck {
    let (mut chi2, mut n) = (0.0, 0usize);
    for (i, ob) in data.obs.iter().enumerate() {
        if ob.beacon == b {
            chi2 += f.r[i] * f.r[i];
            n += 1;
        }
    }
    let chi2_per_n = chi2 / n.max(1) as f64;
    let mut out = SurveyCheck {
        chi2_per_n,
        n,
        position_offset_m: None,
        axis_offset_deg: None,
        suspect: false,
        note: format!("beacon {id}: residual χ²/n {chi2_per_n:.2}, survey not checked"),
    };
    let diag = match diag {
        None => return out,
        Some(Ok(d)) => d,
        Some(Err(e)) => {
            out.note = format!(
                "beacon {id}: residual χ²/n {chi2_per_n:.2}, its survey offset is not determined: {e}"
            );
            return out;
        }
    };
    let at = data.layout(f.scat).offsets(b);
    let deg = 180.0 / std::f64::consts::PI;
    let pos = [0, 1, 2].map(|a| Data::estimate(diag, at + a, 1.0));
    let axis = [3, 4].map(|a| Data::estimate(diag, at + a, deg));
    let beyond = |e: &ParamEstimate| e.value.abs() > SUSPECT_SIGMAS * e.std;
    out.suspect = pos.iter().chain(&axis).any(beyond);
    out.note = note(id, chi2_per_n, &pos, &axis, out.suspect);
    out.position_offset_m = Some(pos);
    out.axis_offset_deg = Some(axis);
    out
}

/// The check in words: "beacon port: residual χ²/n 4.80, the survey looks
/// off by (0.030, -0.010, 0.000) m ± 0.004, axis (yaw 2.9°, pitch 0.1°) ±
/// 0.2°" when suspect, else that it is consistent.
fn note(
    id: &str,
    chi2_per_n: f64,
    pos: &[ParamEstimate; 3],
    axis: &[ParamEstimate; 2],
    suspect: bool,
) -> String {
    let worst = |v: &[ParamEstimate]| v.iter().map(|e| e.std).fold(0.0, f64::max);
    let offsets = format!(
        "({:.3}, {:.3}, {:.3}) m ± {:.3}, axis (yaw {:.2}°, pitch {:.2}°) ± {:.2}°",
        pos[0].value,
        pos[1].value,
        pos[2].value,
        worst(pos),
        axis[0].value,
        axis[1].value,
        worst(axis)
    );
    if suspect {
        format!("beacon {id}: residual χ²/n {chi2_per_n:.2}, the survey looks off by {offsets}")
    } else {
        format!(
            "beacon {id}: residual χ²/n {chi2_per_n:.2}, survey consistent (offsets {offsets}, \
             none beyond {SUSPECT_SIGMAS}σ)"
        )
    }
}
