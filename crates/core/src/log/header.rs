//! The log's first line: what the frames after it are (ADC, rates, spec
//! v3's sampling and beacons), checked when read, and everything else it
//! carries passed through.

use super::{excerpt, FORMAT, HEADER_RATE_HZ, VERSION};
use crate::samples::{BeaconInfo, MAX_BEACONS, MAX_SAMPLES_PER_FRAME};
use crate::{COLS, ROWS};

/// The first line of a log. Fields this reader does not know are kept and
/// written back, so a log passes through unchanged.
#[derive(Debug, Clone, PartialEq)]
pub struct LogHeader {
    pub adc_bits: u8,
    pub rate_hz: f64,
    /// Spec v3: samples per second of every channel (absent: one sample
    /// per frame, `rate_hz`).
    pub sample_hz: Option<f64>,
    /// Spec v3: time between two consecutive channels' conversions, s
    /// (absent: 0).
    pub channel_skew_s: Option<f64>,
    /// Spec v3: the beacons a demodulator looks for (empty: one steady
    /// beacon).
    pub beacons: Vec<BeaconInfo>,
    /// Everything else the header carried (scene, board, date, notes).
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl LogHeader {
    pub fn new(adc_bits: u8, rate_hz: f64) -> Self {
        LogHeader {
            adc_bits,
            rate_hz,
            sample_hz: None,
            channel_skew_s: None,
            beacons: Vec::new(),
            extra: serde_json::Map::new(),
        }
    }

    /// Samples per channel per frame, N: 1 unless `sample_hz` says more
    /// (checked whole when the header was read).
    pub fn samples_per_frame(&self) -> usize {
        self.sample_hz
            .and_then(|s| crate::modulation::whole(s / self.rate_hz))
            .map_or(1, |n| n as usize)
    }

    /// The place of beacon `id` in `beacons`; with none named, the one
    /// steady beacon is "beacon" (MODEL.md's `[beacon]` id).
    pub fn beacon_index(&self, id: &str) -> Option<usize> {
        if self.beacons.is_empty() {
            return (id == DEFAULT_BEACON_ID).then_some(0);
        }
        self.beacons.iter().position(|b| b.id == id)
    }

    /// The id of beacon `i` (see [`LogHeader::beacon_index`]).
    pub fn beacon_id(&self, i: usize) -> &str {
        self.beacons
            .get(i)
            .map_or(DEFAULT_BEACON_ID, |b| b.id.as_str())
    }

    pub(super) fn to_json(&self) -> serde_json::Value {
        let mut m = serde_json::Map::new();
        m.insert("class".into(), "HEADER".into());
        m.insert("format".into(), FORMAT.into());
        m.insert("version".into(), VERSION.into());
        m.insert("rows".into(), ROWS.into());
        m.insert("cols".into(), COLS.into());
        m.insert("adc_bits".into(), self.adc_bits.into());
        m.insert(
            "rate_hz".into(),
            crate::finite(self.rate_hz).map_or(serde_json::Value::Null, Into::into),
        );
        // Spec v3's fields only where they say something, so that a v1/v2
        // header is written as before.
        if let Some(s) = self.sample_hz.and_then(crate::finite) {
            m.insert("sample_hz".into(), s.into());
        }
        if let Some(s) = self.channel_skew_s.and_then(crate::finite) {
            m.insert("channel_skew_s".into(), s.into());
        }
        if !self.beacons.is_empty() {
            let list = self
                .beacons
                .iter()
                .map(|b| {
                    let mut o = serde_json::Map::new();
                    o.insert("id".into(), b.id.clone().into());
                    o.insert(
                        "mod_hz".into(),
                        crate::finite(b.mod_hz).map_or(serde_json::Value::Null, Into::into),
                    );
                    serde_json::Value::Object(o)
                })
                .collect();
            m.insert("beacons".into(), serde_json::Value::Array(list));
        }
        for (k, v) in &self.extra {
            m.entry(k.clone()).or_insert_with(|| v.clone());
        }
        serde_json::Value::Object(m)
    }

    pub(super) fn parse(v: serde_json::Value) -> Result<Self, String> {
        let serde_json::Value::Object(mut m) = v else {
            return Err("header is not a JSON object".into());
        };
        let class = m.remove("class");
        if class.as_ref().and_then(|c| c.as_str()) != Some("HEADER") {
            return Err(format!(
                "first line must be class HEADER, found {}",
                class.map_or("no class".to_string(), |c| excerpt(&c.to_string(), 40))
            ));
        }
        let format = m.remove("format");
        if format.as_ref().and_then(|c| c.as_str()) != Some(FORMAT) {
            return Err(format!("header format must be \"{FORMAT}\""));
        }
        // The spec's header says 1 and its v2 added only optional fields,
        // so a writer that calls such a log version 2 is read alike (we
        // write 1: every v1 reader passes over the fields it does not know).
        match m.remove("version").and_then(|v| v.as_u64()) {
            Some(1 | 2) => {}
            Some(v) => return Err(format!("header version {v} is not supported (only 1 or 2)")),
            None => return Err("header has no integer version".into()),
        }
        for (key, want) in [("rows", ROWS), ("cols", COLS)] {
            match m.remove(key).and_then(|v| v.as_u64()) {
                Some(v) if v as usize == want => {}
                Some(v) => {
                    return Err(format!(
                        "header {key} = {v}: only a 5 × 5 array is supported"
                    ))
                }
                None => return Err(format!("header has no integer {key}")),
            }
        }
        let adc_bits = match m.remove("adc_bits").and_then(|v| v.as_u64()) {
            Some(b @ 1..=16) => b as u8,
            Some(b) => return Err(format!("header adc_bits = {b}: must be 1..16")),
            None => return Err("header has no integer adc_bits".into()),
        };
        let rate_hz = match m.remove("rate_hz").and_then(|v| v.as_f64()) {
            Some(r) if HEADER_RATE_HZ.contains(&r) => r,
            Some(r) => {
                return Err(format!(
                    "header rate_hz = {r}: must be in {}..={} Hz",
                    HEADER_RATE_HZ.start(),
                    HEADER_RATE_HZ.end()
                ))
            }
            None => return Err("header has no number rate_hz".into()),
        };
        let v3 = parse_v3_header(&mut m, rate_hz)?;
        Ok(LogHeader {
            adc_bits,
            rate_hz,
            sample_hz: v3.0,
            channel_skew_s: v3.1,
            beacons: v3.2,
            extra: m,
        })
    }
}

/// The id of the one beacon of a `[beacon]` scene (MODEL.md).
pub const DEFAULT_BEACON_ID: &str = "beacon";

/// A header's `sample_hz` (a whole multiple of `rate_hz`, at most
/// [`MAX_SAMPLES_PER_FRAME`] per frame), `channel_skew_s` (0 up to a frame
/// period) and `beacons` (at most [`MAX_BEACONS`], ids unique, frequencies
/// by MODEL.md's rules), taken out of `m`.
#[allow(clippy::type_complexity)]
fn parse_v3_header(
    m: &mut serde_json::Map<String, serde_json::Value>,
    rate_hz: f64,
) -> Result<(Option<f64>, Option<f64>, Vec<BeaconInfo>), String> {
    use crate::modulation::{check_beacons, BeaconFreq};
    let sample_hz = sample_hz_of(m.remove("sample_hz"), rate_hz)?;
    let channel_skew_s = skew_of(m.remove("channel_skew_s"), rate_hz)?;
    let beacons = beacons_of(m.remove("beacons"))?;
    if !beacons.is_empty() || sample_hz.is_some() {
        let freqs: Vec<BeaconFreq> = beacons
            .iter()
            .map(|b| BeaconFreq {
                id: &b.id,
                mod_hz: b.mod_hz,
            })
            .collect();
        // No list is one steady beacon; a fast sample rate then needs one.
        let one = [BeaconFreq {
            id: DEFAULT_BEACON_ID,
            mod_hz: 0.0,
        }];
        let list = if freqs.is_empty() {
            &one[..]
        } else {
            &freqs[..]
        };
        check_beacons(rate_hz, sample_hz.unwrap_or(rate_hz), list)
            .map_err(|e| format!("header: {e}"))?;
    }
    Ok((sample_hz, channel_skew_s, beacons))
}

/// `sample_hz`: absent, or a whole multiple of `rate_hz` within
/// [`MAX_SAMPLES_PER_FRAME`] per frame.
fn sample_hz_of(v: Option<serde_json::Value>, rate_hz: f64) -> Result<Option<f64>, String> {
    let v = match v {
        None | Some(serde_json::Value::Null) => return Ok(None),
        Some(v) => v,
    };
    let s = v
        .as_f64()
        .filter(|s| s.is_finite() && *s > 0.0)
        .ok_or_else(|| {
            format!(
                "header sample_hz = {}: must be a positive number",
                excerpt(&v.to_string(), 40)
            )
        })?;
    let n = crate::modulation::samples_per_frame(s, rate_hz).map_err(|e| format!("header {e}"))?;
    if n as usize > MAX_SAMPLES_PER_FRAME {
        return Err(format!(
            "header sample_hz = {s}: {n} samples per frame, more than {MAX_SAMPLES_PER_FRAME}"
        ));
    }
    Ok(Some(s))
}

/// `channel_skew_s`: absent, or seconds up to a frame period.
fn skew_of(v: Option<serde_json::Value>, rate_hz: f64) -> Result<Option<f64>, String> {
    match v {
        None | Some(serde_json::Value::Null) => Ok(None),
        Some(v) => v
            .as_f64()
            .filter(|s| (0.0..=1.0 / rate_hz).contains(s))
            .map(Some)
            .ok_or_else(|| {
                format!(
                    "header channel_skew_s = {}: must be a number of seconds in 0..=1 / rate_hz",
                    excerpt(&v.to_string(), 40)
                )
            }),
    }
}

/// `beacons`: absent, or at most [`MAX_BEACONS`] of `{id, mod_hz}` with
/// unique, non-empty ids.
fn beacons_of(v: Option<serde_json::Value>) -> Result<Vec<BeaconInfo>, String> {
    let list = match v {
        None | Some(serde_json::Value::Null) => return Ok(Vec::new()),
        Some(serde_json::Value::Array(list)) => list,
        Some(_) => return Err("header beacons is not an array".into()),
    };
    if list.len() > MAX_BEACONS {
        return Err(format!(
            "header beacons: {} beacons, at most {MAX_BEACONS}",
            list.len()
        ));
    }
    let mut beacons: Vec<BeaconInfo> = Vec::with_capacity(list.len());
    for (i, b) in list.iter().enumerate() {
        let id = b
            .get("id")
            .and_then(|v| v.as_str())
            .filter(|s| !s.is_empty())
            .ok_or_else(|| format!("header beacons[{i}] has no id (a non-empty string)"))?;
        let mod_hz = b
            .get("mod_hz")
            .and_then(|v| v.as_f64())
            .filter(|f| f.is_finite() && *f >= 0.0)
            .ok_or_else(|| {
                format!(
                    "header beacons[{i}] (\"{}\") has no mod_hz ≥ 0",
                    excerpt(id, 40)
                )
            })?;
        if beacons.iter().any(|o| o.id == id) {
            return Err(format!(
                "header beacons[{i}]: id \"{}\" repeats",
                excerpt(id, 40)
            ));
        }
        beacons.push(BeaconInfo {
            id: id.to_string(),
            mod_hz,
        });
    }
    Ok(beacons)
}
