//! Calibration of a docking station (spec v3, issue 41): from
//! truth-labelled sweeps of the station (every beacon on, demodulated
//! frames or BURST ones demodulated on the way), fit each beacon's V1 and
//! σ_b, the array's 25 gains (their mean fixed to 1: gain·V1 is
//! degenerate), K_D and σ_R, and the scattering term when the data demand
//! it, against the surveyed placements of the station file.
//!
//! Why its own fit beside `physical_fit`: that one fits one beacon at D's
//! origin on counts; a station's images are amplitudes, one per beacon,
//! each from its own place. The survey stays as it is — a survey error is
//! reported, not absorbed: each beacon's residual χ² and the position and
//! axis offset that would explain it (fitted as a diagnostic, with σ) are
//! in the result (`station::SurveyCheck`).
//!
//! Frames are grouped by truth pose as they stream (a sweep never sits in
//! memory) and the fit runs on the per-pose means, weighted by the
//! demodulator's σ and the amplitude model's error
//! (`measurement::AMPLITUDE_MODEL_REL` of the mean).

use lightpose_core::light::temperature_gain;
use lightpose_core::{Frame, Pose, NDET};

use super::physical_fit::{CalibError, ScatterFit};
use super::station::{Station, StationCalibration};
use crate::model::measurement::AMPLITUDE_MODEL_REL;

mod model_error;
mod problem;
mod survey;

/// The fit's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct StationFitOptions {
    pub scattering: ScatterFit,
    pub v_ref: f64,
    pub geometry: lightpose_core::ArrayGeometry,
    pub max_iter: usize,
    /// Poses with fewer frames than this are ignored.
    pub min_samples: u64,
    /// The amplitude model's relative error added to each mean's σ.
    pub model_rel: f64,
    /// Whether to fit each beacon's survey offset as a diagnostic.
    pub survey_check: bool,
}

impl Default for StationFitOptions {
    fn default() -> Self {
        StationFitOptions {
            scattering: ScatterFit::Auto,
            v_ref: 5.0,
            geometry: lightpose_core::ArrayGeometry::paper(),
            max_iter: 60,
            min_samples: 2,
            model_rel: AMPLITUDE_MODEL_REL,
            survey_check: true,
        }
    }
}

/// Why a station's sweeps could not be fitted.
#[derive(Debug, thiserror::Error)]
pub enum StationFitError {
    #[error(transparent)]
    Fit(#[from] CalibError),
    #[error(
        "frame {seq} carries counts, not one image per beacon: a station is calibrated from \
         demodulated or BURST sweeps of its blinking beacons"
    )]
    NotDemodulated { seq: u64 },
    #[error("{log}: {err}")]
    Log {
        log: String,
        err: lightpose_core::LogError,
    },
    /// The log's beacons are not the station file's (an id missing, a
    /// frequency that differs), or the survey's frequencies break MODEL.md's
    /// rules at the log's ADC.
    #[error("{0}")]
    Survey(String),
}

/// Fit `station` (its file's `text`, named `file` in errors) from the lit
/// sweeps at `sweeps`, streamed one frame at a time; lines a log refuses
/// are skipped and counted (the paper's pass has told them), returned
/// with the fit. Each log's header beacons are matched to the station's
/// by id, their frequencies compared, and MODEL.md's rules checked at the
/// log's rate and sample rate.
pub fn fit_station_sweeps(
    sweeps: &[std::path::PathBuf],
    station: &Station,
    text: &str,
    file: &str,
    o: &StationFitOptions,
) -> Result<(StationFitted, u64), StationFitError> {
    let mut fitter = StationFitter::new(station.beacons.len());
    let mut ignore = |_: &lightpose_core::LogError| {};
    let mut bad = super::sweep_logs::BadLines {
        count: 0,
        report: &mut ignore,
        cuts: Vec::new(),
    };
    let log_err = |p: &std::path::Path| {
        let log = p.display().to_string();
        move |err| StationFitError::Log { log, err }
    };
    for path in sweeps {
        let header = super::sweep_logs::header_of(path).map_err(log_err(path))?;
        if super::sweep_logs::is_dark_sweep(&header) {
            continue;
        }
        let map = beacon_map(station, &header, path, text, file)?;
        let mut failed = None;
        super::sweep_logs::stream(
            path,
            |f, _| {
                if failed.is_none() && super::sweep_frame_fault(f).is_none() {
                    failed = fitter.add_frame(f, &map).err();
                }
            },
            &mut bad,
        )
        .map_err(log_err(path))?;
        if let Some(e) = failed {
            return Err(e);
        }
    }
    Ok((fitter.fit(station, o)?, bad.count))
}

/// Which station beacon each of the log's header beacons is; every
/// station beacon must be in the log at its surveyed frequency.
fn beacon_map(
    station: &Station,
    header: &lightpose_core::LogHeader,
    path: &std::path::Path,
    text: &str,
    file: &str,
) -> Result<Vec<Option<usize>>, StationFitError> {
    let sample_hz = header.sample_hz.unwrap_or(header.rate_hz);
    station
        .check_frequencies(header.rate_hz, sample_hz, text, file)
        .map_err(|e| StationFitError::Survey(e.to_string()))?;
    for b in &station.beacons {
        match header.beacons.iter().find(|h| h.id == b.id) {
            None => {
                return Err(StationFitError::Survey(format!(
                    "{}: the log has no beacon {:?} of station {} (its beacons: {})",
                    path.display(),
                    b.id,
                    station.name,
                    header
                        .beacons
                        .iter()
                        .map(|h| h.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )))
            }
            Some(h) if (h.mod_hz - b.mod_hz).abs() > 1e-9 * b.mod_hz => {
                return Err(StationFitError::Survey(format!(
                    "{}: beacon {:?} blinks at {} Hz in the log, {} Hz in the station file",
                    path.display(),
                    b.id,
                    h.mod_hz,
                    b.mod_hz
                )))
            }
            Some(_) => {}
        }
    }
    Ok(header
        .beacons
        .iter()
        .map(|h| station.beacons.iter().position(|b| b.id == h.id))
        .collect())
}

/// One beacon's image of a pose, summed over the pose's frames.
#[derive(Debug, Clone, Copy)]
struct Image {
    n: [u64; NDET],
    sum: [f64; NDET],
    /// The demodulator's variance of each amplitude, summed.
    var: [f64; NDET],
    clipped: [bool; NDET],
}

impl Default for Image {
    fn default() -> Self {
        Image {
            n: [0; NDET],
            sum: [0.0; NDET],
            var: [0.0; NDET],
            clipped: [false; NDET],
        }
    }
}

#[derive(Debug, Clone)]
struct Group {
    pose: Pose,
    n: u64,
    gt_sum: f64,
    /// One per station beacon.
    images: Vec<Image>,
}

/// Streams a station's sweep frames in, grouping consecutive frames of one
/// truth pose.
#[derive(Debug, Clone)]
pub struct StationFitter {
    beacons: usize,
    groups: Vec<Group>,
    bits: Option<u8>,
    frames: u64,
}

impl StationFitter {
    /// A fitter for a station of `beacons` beacons.
    pub fn new(beacons: usize) -> Self {
        StationFitter {
            beacons,
            groups: Vec::new(),
            bits: None,
            frames: 0,
        }
    }

    /// Add one sweep frame; `map[i]` is the station's beacon that the log's
    /// header beacon `i` is (`None`: not one of the station's). Frames
    /// without truth are skipped.
    pub fn add_frame(&mut self, f: &Frame, map: &[Option<usize>]) -> Result<(), StationFitError> {
        let Some(truth) = f.truth else { return Ok(()) };
        let Some(amps) = f.amplitudes.as_ref() else {
            return Err(StationFitError::NotDemodulated { seq: f.seq });
        };
        match self.bits {
            None => self.bits = Some(f.adc_bits),
            Some(b) if b != f.adc_bits => return Err(CalibError::MixedBits(b, f.adc_bits).into()),
            _ => {}
        }
        self.frames += 1;
        let same = self
            .groups
            .last()
            .is_some_and(|g| super::same_pose(&g.pose, &truth.pose));
        if !same {
            self.groups.push(Group {
                pose: truth.pose,
                n: 0,
                gt_sum: 0.0,
                images: vec![Image::default(); self.beacons],
            });
        }
        let Some(g) = self.groups.last_mut() else {
            return Ok(());
        };
        g.n += 1;
        g.gt_sum += f.temp_c.map_or(1.0, temperature_gain);
        for img in amps.beacons() {
            let Some(Some(b)) = map.get(usize::from(img.beacon)) else {
                continue;
            };
            let Some(acc) = g.images.get_mut(*b) else {
                continue;
            };
            for k in 0..NDET {
                let (a, s) = (img.amplitude[k], img.std[k]);
                if amps.clipped[k] > 0 || !a.is_finite() || !s.is_finite() {
                    acc.clipped[k] = true;
                    continue;
                }
                acc.n[k] += 1;
                acc.sum[k] += a;
                acc.var[k] += s * s;
            }
        }
        Ok(())
    }

    /// The sweeps' span of x (m) over the poses added, widened by a
    /// tenth each way (see [`StationFitted::x_span`]).
    fn x_span(&self) -> [f64; 2] {
        let [lo, hi] = self
            .groups
            .iter()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], g| {
                [lo.min(g.pose.x), hi.max(g.pose.x)]
            });
        [lo / 1.1, hi * 1.1]
    }

    /// Fit the station's light to everything added, against `station`'s
    /// survey: the `[station]` table, and the `[physical]` one the
    /// estimators build their sensor model from (the shared water and
    /// array, and the first beacon's V1 and σ_b).
    pub fn fit(
        &self,
        station: &Station,
        o: &StationFitOptions,
    ) -> Result<StationFitted, StationFitError> {
        let bits = self.bits.ok_or(CalibError::NoTruth)?;
        let data = problem::Data::build(self, station, o, bits)?;
        let fit = match o.scattering {
            ScatterFit::Off => data.fit(false, None, o)?,
            ScatterFit::On => data.fit(true, None, o)?,
            ScatterFit::Auto => {
                let off = data.fit(false, None, o)?;
                // Kept when it lowers χ² by more than 25 (two parameters,
                // far beyond chance), as the physical fit does.
                match data.fit(true, None, o) {
                    Ok(on) if off.cost - on.cost > 25.0 => on,
                    _ => off,
                }
            }
        };
        Ok(StationFitted {
            station: survey::calibration(&data, station, &fit, o),
            physical: data.physical_of(&fit, o),
            x_span: self.x_span(),
        })
    }
}

/// What a station's fit gives the calibration file.
#[derive(Debug, Clone, PartialEq)]
pub struct StationFitted {
    pub station: StationCalibration,
    pub physical: super::PhysicalCalibration,
    /// The estimators' `x_range` (m): the nearest and farthest distance
    /// along the station's axis that the sweeps covered, where the fitted
    /// light is known, widened by a tenth each way so that an approach
    /// that starts or ends at a sweep's edge does not flicker
    /// `out_of_range` on its noise (a docking ends far inside a single
    /// beacon's default 3 m).
    pub x_span: [f64; 2],
}

impl StationFitted {
    /// The estimators' settings for this station, from `base` (the
    /// calibration's, or the defaults): `x_range` the sweeps' span
    /// ([`Self::x_span`]), so that they are `ok` where the light was
    /// calibrated (a docking ends far inside a single beacon's default
    /// [3, 12] m).
    pub fn estimator_settings(
        &self,
        mut base: crate::settings::EstimatorSettings,
    ) -> crate::settings::EstimatorSettings {
        base.model.x_range = self.x_span;
        base.tracker.x_range = self.x_span;
        base
    }
}
