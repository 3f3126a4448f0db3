//! A Water Linked DVL (A50/A125) on its TCP JSON protocol (port 16171,
//! one JSON object per line; Water Linked's "DVL A50/A125 TCP JSON API",
//! `json_v3.1`/`json_v3.2`).
//!
//! A velocity report carries `vx, vy, vz` (m/s), `covariance` (3×3,
//! (m/s)²), `velocity_valid`, `time_of_validity` and
//! `time_of_transmission` (Unix µs), `status`, `tracking_mode` and more.
//! Its axes are the DVL's vehicle frame: x forward, y right, z down, which
//! is MODEL.md's V (FRD) when the DVL is mounted with its LED forward or
//! its `mounting_rotation_offset` says how it is turned. The velocity is
//! over the ground (bottom tracking); water-tracking reports
//! (`velocity_water`) are refused, being relative to the water.
//!
//! The reading is stamped at its time of validity: the DVL's own
//! transmission − validity delay (one clock, so no offset) is taken off
//! the moment the line arrived.

pub mod client;

use lightpose_core::{BodyVec, VelocityReading};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::Duration;

/// Why a line from the DVL was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DvlRefusal {
    /// Not a JSON object (or longer than a report can be).
    Garbage,
    /// A velocity report without lock on the bottom (`velocity_valid`
    /// false).
    Invalid,
    /// Velocity relative to the water, not the ground.
    WaterTrack,
    /// A component larger than the configured maximum speed.
    OutOfRange,
    /// A covariance that is not 3×3 with finite, positive variances (a
    /// velocity known exactly is no measurement).
    BadCovariance,
    /// `time_of_validity` after `time_of_transmission`, or more than
    /// [`MAX_LATENCY`] before it: how old the velocity is, is not known.
    BadTime,
    /// JSON, but not a report this reader understands (no `type`, no
    /// `vx`, …).
    Malformed,
}

impl DvlRefusal {
    pub const ALL: [DvlRefusal; 7] = [
        DvlRefusal::Garbage,
        DvlRefusal::Invalid,
        DvlRefusal::WaterTrack,
        DvlRefusal::OutOfRange,
        DvlRefusal::BadCovariance,
        DvlRefusal::Malformed,
        DvlRefusal::BadTime,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            DvlRefusal::Garbage => "garbage",
            DvlRefusal::Invalid => "velocity_invalid",
            DvlRefusal::WaterTrack => "water_track",
            DvlRefusal::OutOfRange => "out_of_range",
            DvlRefusal::BadCovariance => "bad_covariance",
            DvlRefusal::Malformed => "malformed",
            DvlRefusal::BadTime => "bad_time",
        }
    }
    pub fn index(self) -> usize {
        self as usize
    }
}

/// A usable velocity report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvlVelocity {
    pub reading: VelocityReading,
    /// The DVL's own delay from validity to transmission.
    pub latency: Option<Duration>,
    /// Status bit 0: the DVL is hot and will soon shut down.
    pub high_temperature: bool,
}

/// What one line was.
#[derive(Debug, Clone, PartialEq)]
pub enum DvlLine {
    Velocity(DvlVelocity),
    /// A report of another type (dead reckoning, a command response).
    Other,
}

#[derive(Deserialize)]
struct Report {
    #[serde(rename = "type")]
    kind: Option<String>,
    vx: Option<f64>,
    vy: Option<f64>,
    vz: Option<f64>,
    covariance: Option<Vec<Vec<f64>>>,
    velocity_valid: Option<bool>,
    #[serde(default, deserialize_with = "lenient_u64")]
    status: Option<u64>,
    #[serde(default, deserialize_with = "lenient_u64")]
    time_of_validity: Option<u64>,
    #[serde(default, deserialize_with = "lenient_u64")]
    time_of_transmission: Option<u64>,
    tracking_mode: Option<String>,
}

/// The longest delay from a velocity's validity to its transmission that
/// is taken as the DVL's own (tens of ms in practice); a larger one, or a
/// negative one, says the report's times are wrong.
pub const MAX_LATENCY: Duration = Duration::from_secs(5);

/// A field the velocity does not need (the status, the times), of the
/// wrong type or sign, is taken as absent: a firmware that sends its
/// times as floats, or a status of -1, costs no velocity (an audit: each
/// such report was refused whole as garbage and the connection dropped
/// for silence).
fn lenient_u64<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    let v = serde_json::Value::deserialize(d)?;
    let Some(n) = v.as_number() else {
        return Ok(None);
    };
    Ok(n.as_u64().or_else(|| {
        n.as_f64()
            .filter(|f| (0.0..1.8e19).contains(f))
            .map(|f| f.round() as u64)
    }))
}

/// 1σ per axis from the covariance's diagonal (off-diagonal terms are
/// dropped: a frame carries one std per component).
fn std_of(cov: &[Vec<f64>]) -> Result<BodyVec, DvlRefusal> {
    if cov.len() != 3 || cov.iter().any(|r| r.len() != 3) {
        return Err(DvlRefusal::BadCovariance);
    }
    let d = [cov[0][0], cov[1][1], cov[2][2]];
    if d.iter().any(|v| !v.is_finite() || *v <= 0.0) {
        return Err(DvlRefusal::BadCovariance);
    }
    Ok(BodyVec(d.map(f64::sqrt)))
}

/// Read one line of the DVL's stream.
pub fn parse_line(line: &[u8], max_speed_mps: f64) -> Result<DvlLine, DvlRefusal> {
    let r: Report = serde_json::from_slice(line).map_err(|_| DvlRefusal::Garbage)?;
    match r.kind.as_deref() {
        Some("velocity") => {}
        Some("velocity_water") => return Err(DvlRefusal::WaterTrack),
        Some(_) => return Ok(DvlLine::Other),
        None => return Err(DvlRefusal::Malformed),
    }
    if r.tracking_mode.as_deref() == Some("water") {
        return Err(DvlRefusal::WaterTrack);
    }
    if r.velocity_valid != Some(true) {
        return Err(if r.velocity_valid == Some(false) {
            DvlRefusal::Invalid
        } else {
            DvlRefusal::Malformed
        });
    }
    let (Some(vx), Some(vy), Some(vz)) = (r.vx, r.vy, r.vz) else {
        return Err(DvlRefusal::Malformed);
    };
    if [vx, vy, vz]
        .iter()
        .any(|v| !v.is_finite() || v.abs() > max_speed_mps)
    {
        return Err(DvlRefusal::OutOfRange);
    }
    let std = r.covariance.as_deref().map(std_of).transpose()?;
    let latency = match (r.time_of_validity, r.time_of_transmission) {
        (Some(v), Some(t)) => match t.checked_sub(v).map(Duration::from_micros) {
            Some(l) if l <= MAX_LATENCY => Some(l),
            // Taken as just measured, a report that says it is old was
            // fused as fresh.
            _ => return Err(DvlRefusal::BadTime),
        },
        _ => None,
    };
    Ok(DvlLine::Velocity(DvlVelocity {
        reading: VelocityReading {
            v: BodyVec([vx, vy, vz]),
            std,
        },
        latency,
        high_temperature: r.status.is_some_and(|s| s & 1 == 1),
    }))
}

/// What the DVL client did, for STATUS.
#[derive(Default)]
pub struct DvlCounters {
    pub(crate) connects: AtomicU64,
    pub(crate) connect_failures: AtomicU64,
    pub(crate) drops: AtomicU64,
    pub(crate) silences: AtomicU64,
    pub(crate) reports: AtomicU64,
    pub(crate) other: AtomicU64,
    pub(crate) high_temperature: AtomicU64,
    pub(crate) refused: [AtomicU64; DvlRefusal::ALL.len()],
    pub(crate) last_error: Mutex<Option<String>>,
    /// Core's rule for repeated lines: failed connects, refused lines,
    /// lost connections (their closing lines: `client::settle`, between connect attempts
    /// and once a second in a session).
    pub(crate) connect_log: Mutex<lightpose_core::ratelog::RateLog>,
    pub(crate) refuse_log: Mutex<lightpose_core::ratelog::RateLog>,
    /// Connections lost: a DVL that closes each one at once.
    pub(crate) drop_log: Mutex<lightpose_core::ratelog::RateLog>,
}

/// STATUS figures of the DVL client.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DvlStatus {
    pub connects: u64,
    pub connect_failures: u64,
    /// Connections lost (closed by the DVL, or an error).
    pub drops: u64,
    /// Connections given up because the DVL fell silent.
    pub silences: u64,
    /// Velocity reports used.
    pub reports: u64,
    /// Lines of other report types.
    pub other: u64,
    pub high_temperature: u64,
    #[serde(serialize_with = "crate::counts_as_map")]
    pub refused: Vec<(&'static str, u64)>,
    pub last_error: Option<String>,
}

impl DvlCounters {
    pub fn refused(&self, r: DvlRefusal) -> u64 {
        self.refused[r.index()].load(Relaxed)
    }

    pub fn reports(&self) -> u64 {
        self.reports.load(Relaxed)
    }

    pub fn connects(&self) -> u64 {
        self.connects.load(Relaxed)
    }

    pub fn drops(&self) -> u64 {
        self.drops.load(Relaxed)
    }

    pub(crate) fn set_error(&self, line: String) {
        if let Ok(mut g) = self.last_error.lock() {
            *g = Some(line);
        }
    }

    pub fn status(&self) -> DvlStatus {
        DvlStatus {
            connects: self.connects.load(Relaxed),
            connect_failures: self.connect_failures.load(Relaxed),
            drops: self.drops.load(Relaxed),
            silences: self.silences.load(Relaxed),
            reports: self.reports.load(Relaxed),
            other: self.other.load(Relaxed),
            high_temperature: self.high_temperature.load(Relaxed),
            refused: DvlRefusal::ALL
                .iter()
                .map(|r| (r.as_str(), self.refused(*r)))
                .filter(|(_, n)| *n > 0)
                .collect(),
            last_error: self.last_error.lock().ok().and_then(|g| g.clone()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vendor's example report (json_v3.2), on one line.
    const REPORT: &str = r#"{"time": 106.39, "vx": -3.7e-05, "vy": 5.7e-05, "vz": 2.5e-05, "fom": 0.00016, "covariance": [[2.4e-08, -3.4e-09, -1.7e-09], [-3.4e-09, 1.5e-08, 4.0e-10], [-1.7e-09, 4.0e-10, 1.6e-09]], "altitude": 0.49, "transducers": [{"id": 0, "velocity": 0.0001, "distance": 0.56, "rssi": -30.5, "nsd": -88.7, "beam_valid": true}], "velocity_valid": true, "status": 0, "tracking_mode": "bottom", "format": "json_v3.2", "type": "velocity", "time_of_validity": 1638191471563017, "time_of_transmission": 1638191471752336}"#;

    #[test]
    fn the_vendors_example_is_read() {
        let DvlLine::Velocity(v) = parse_line(REPORT.as_bytes(), 5.0).unwrap() else {
            panic!()
        };
        assert_eq!(v.reading.v.0, [-3.7e-05, 5.7e-05, 2.5e-05]);
        let s = v.reading.std.unwrap().0;
        assert!((s[0] - 2.4e-08f64.sqrt()).abs() < 1e-15);
        assert_eq!(v.latency, Some(Duration::from_micros(189_319)));
        assert!(!v.high_temperature);
    }

    #[test]
    fn lines_that_cannot_be_used_say_why() {
        let with = |from: &str, to: &str| REPORT.replace(from, to);
        for (line, why) in [
            ("garbage".to_string(), DvlRefusal::Garbage),
            (REPORT[..40].to_string(), DvlRefusal::Garbage),
            (
                with("\"velocity_valid\": true", "\"velocity_valid\": false"),
                DvlRefusal::Invalid,
            ),
            (
                with("\"type\": \"velocity\"", "\"type\": \"velocity_water\""),
                DvlRefusal::WaterTrack,
            ),
            (
                with("\"vx\": -3.7e-05", "\"vx\": 50.0"),
                DvlRefusal::OutOfRange,
            ),
            (with("[[2.4e-08", "[[-2.4e-08"), DvlRefusal::BadCovariance),
            // Exactly known is no measurement (the tracker refused each
            // such reading, unseen in the DVL's own counts).
            (with("[[2.4e-08", "[[0.0"), DvlRefusal::BadCovariance),
            // Says it is 6 s old, and was taken as just measured.
            (
                with("1638191471752336", "1638191477563017"),
                DvlRefusal::BadTime,
            ),
            // Valid after it was sent.
            (
                with("1638191471563017", "1638191471852336"),
                DvlRefusal::BadTime,
            ),
            (with("\"vy\": 5.7e-05,", ""), DvlRefusal::Malformed),
            ("{}".to_string(), DvlRefusal::Malformed),
        ] {
            assert_eq!(parse_line(line.as_bytes(), 5.0), Err(why), "{line}");
        }
        let dr = r#"{"ts": 49056.8, "x": 12.4, "y": 64.6, "z": 1.7, "std": 0.002, "roll": 0.6, "pitch": 0.6, "yaw": 0.6, "type": "position_local", "status": 0, "format": "json_v3.1"}"#;
        assert_eq!(parse_line(dr.as_bytes(), 5.0), Ok(DvlLine::Other));
        let no_cov = with("\"covariance\": [[2.4e-08, -3.4e-09, -1.7e-09], [-3.4e-09, 1.5e-08, 4.0e-10], [-1.7e-09, 4.0e-10, 1.6e-09]], ", "");
        let Ok(DvlLine::Velocity(v)) = parse_line(no_cov.as_bytes(), 5.0) else {
            panic!()
        };
        assert_eq!(v.reading.std, None);
    }

    /// A field the velocity does not need, of the wrong type or sign,
    /// costs no velocity: it is taken as absent.
    #[test]
    fn odd_optional_fields_cost_no_velocity() {
        let with = |from: &str, to: &str| REPORT.replace(from, to);
        for (line, latency, hot) in [
            (
                with("\"status\": 0", "\"status\": -1"),
                Some(189_319),
                false,
            ),
            (
                with("\"status\": 0", "\"status\": \"ok\""),
                Some(189_319),
                false,
            ),
            (
                with("\"status\": 0", "\"status\": 1.0"),
                Some(189_319),
                true,
            ),
            (
                with("1638191471563017", "1638191471563017.0"),
                Some(189_319),
                false,
            ),
            (with("1638191471563017", "-5"), None, false),
            (with("1638191471752336", "null"), None, false),
        ] {
            let Ok(DvlLine::Velocity(v)) = parse_line(line.as_bytes(), 5.0) else {
                panic!("{line}")
            };
            assert_eq!(v.latency, latency.map(Duration::from_micros), "{line}");
            assert_eq!(v.high_temperature, hot, "{line}");
            assert_eq!(v.reading.v.0[0], -3.7e-05);
        }
    }
}
