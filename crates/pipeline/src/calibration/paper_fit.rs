//! Fitting a [`Calibration`] from truth-labelled sweep logs (MODEL.md
//! "Calibration sweeps"; paper section 2.2.1), streamed frame by frame into
//! least-squares accumulators so that 61,600 frames never sit in memory.
//!
//! Which frames feed which fit follows the paper: x (eqs. 2–3) and y, z
//! (eqs. 6–7) from the translation grid (pitch = yaw = 0), pitch and yaw
//! (eqs. 4–5) from the orientation fans (y = z = 0). Every candidate
//! feature (each moment ratio, each first moment, each about the peak and
//! about the array centre) is fitted, and the data pick which one tracks
//! each quantity: that is how "M23/M33 for pitch or for yaw" is decided.
//!
//! The same two passes also feed the physical fitter (`physical_fit.rs`),
//! so one command gives both the paper's coefficients and the light model
//! the model-based estimators need; a sweep that cannot determine the light
//! model still gives the paper's coefficients.

use super::dark::{dark_levels, DarkAcc, DarkLevels};
pub use super::dark::{NOMINAL_OFFSET_V, NOMINAL_SIGMA_V, NO_LIGHT_SIGMAS};
use super::file::{
    Calibration, Coverage, Dark, Feature, Fits, Limits, LinearFit, Meta, RangeBasis, RangeFit,
    SceneFacts, FORMAT, MAX_SURGE_WINDOW, VERSION,
};
use super::least_squares::{FitError, Line, LineAcc};
use super::physical_fit::{CalibError, FitOptions, PhysicalFitter};
use super::sweep_logs::{header_of, header_v_ref, is_dark_sweep, stream, BadLines};
use crate::paper::steps;
use lightpose_core::{Frame, LogError, LogHeader, NDET};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// A log could not be opened or read on, or its header is refused.
    #[error(transparent)]
    Log(#[from] LogError),
    /// The data cannot give a calibration; says why.
    #[error("cannot calibrate: {0}")]
    Refused(String),
}

/// What to calibrate from, and the facts the logs do not carry.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    pub sweeps: Vec<PathBuf>,
    /// A log of beacon-off frames for the dark offsets.
    pub dark: Option<PathBuf>,
    /// ADC reference, volts (a log header's `v_ref` overrides it).
    pub v_ref: f64,
    /// Temperature assumed for frames that report none.
    pub default_temp_c: f64,
    /// Samples the surge slope is fitted over (paper: 10).
    pub surge_window: usize,
    /// Written into `meta.created_by`.
    pub created_by: String,
    /// Fit the light model too (`[physical]`), with these options (their
    /// `v_ref` is replaced by the logs'); `None` skips it.
    pub physical: Option<FitOptions>,
}

/// A calibration and, when its `[physical]` table was left out, why.
#[derive(Debug)]
pub struct Calibrated {
    pub cal: Calibration,
    pub physical_skipped: Option<CalibError>,
    /// What the user should know of the sweeps, one line each: a log cut
    /// short, frames the paper's fits did not use (by reason), a light
    /// model that fits its sweep poorly.
    pub notes: Vec<String>,
}

/// A light model's χ²/dof above this says the sweep's frames or truth
/// poses are not what the model can give (a fit of good data is ~1: the
/// shipped tank's 0.98, the harbour's 0.99).
const POOR_CHI2_PER_DOF: f64 = 3.0;

impl CalibrateOptions {
    /// MODEL.md's defaults: 5 V reference, 20 °C, a 10-sample window.
    pub fn new(sweeps: Vec<PathBuf>) -> Self {
        CalibrateOptions {
            sweeps,
            dark: None,
            v_ref: 5.0,
            default_temp_c: lightpose_core::light::T_REF_C,
            surge_window: 10,
            created_by: format!("lightpose-pipeline {}", env!("CARGO_PKG_VERSION")),
            physical: Some(FitOptions::default()),
        }
    }
}

/// Everything accumulated from the lit frames.
#[derive(Debug, Default)]
struct Accs {
    /// ln PD_max against x, translation frames.
    x: LineAcc,
    /// ln PD_max against x on the beam axis, facing the beacon (y = z = 0,
    /// level): the frames the range fit is taken from when there are two
    /// distances or more (see `RangeBasis`).
    x_axis: LineAcc,
    pitch: BTreeMap<Feature, LineAcc>,
    yaw: BTreeMap<Feature, LineAcc>,
    y: BTreeMap<Feature, LineAcc>,
    z: BTreeMap<Feature, LineAcc>,
    /// Ranges of truth over the frames used: x, y, z, pitch, yaw.
    cov: [Option<[f64; 2]>; 5],
    used: u64,
    skipped: BTreeMap<&'static str, u64>,
    translation: u64,
    orientation: u64,
}

fn widen(r: &mut Option<[f64; 2]>, v: f64) {
    *r = Some(match *r {
        None => [v, v],
        Some([lo, hi]) => [lo.min(v), hi.max(v)],
    });
}

/// A truth position of zero, to a carriage's precision (`TRUTH_TOL_M`).
fn zero_m(v: f64) -> bool {
    v.abs() <= super::TRUTH_TOL_M
}

/// A truth angle of zero, to a carriage's precision (`TRUTH_TOL_DEG`).
fn zero_deg(v: f64) -> bool {
    v.abs() <= super::TRUTH_TOL_DEG
}

impl Accs {
    fn push(
        &mut self,
        f: &Frame,
        v_ref: f64,
        dark: &[f64; NDET],
        default_temp_c: f64,
        no_light_v: f64,
    ) {
        let Some(truth) = f.truth else {
            *self.skipped.entry("no truth").or_default() += 1;
            return;
        };
        let p = match steps::prepare(f, v_ref, dark, default_temp_c, no_light_v) {
            Ok(p) => p,
            Err(st) => {
                *self.skipped.entry(st.as_str()).or_default() += 1;
                return;
            }
        };
        let pose = truth.pose;
        let (pitch, yaw) = (pose.pitch.deg(), pose.yaw.deg());
        let level = zero_deg(pitch) && zero_deg(yaw);
        let centred = zero_m(pose.y) && zero_m(pose.z);
        if !level && !centred {
            // Neither a translation nor an orientation calibration pose.
            *self.skipped.entry("mixed pose").or_default() += 1;
            return;
        }
        self.used += 1;
        if level {
            self.translation += 1;
            self.x.push(pose.x, p.peak.value.ln());
            if centred {
                self.x_axis.push(pose.x, p.peak.value.ln());
            }
            for f in Feature::FIRST {
                if let Some(v) = steps::feature_value(f, &p.moments) {
                    self.y.entry(f).or_default().push(v, pose.y);
                    self.z.entry(f).or_default().push(v, pose.z);
                }
            }
            widen(&mut self.cov[0], pose.x);
            widen(&mut self.cov[1], pose.y);
            widen(&mut self.cov[2], pose.z);
        }
        if centred {
            self.orientation += 1;
            for f in Feature::RATIOS {
                if let Some(v) = steps::feature_value(f, &p.moments) {
                    self.pitch.entry(f).or_default().push(v, pitch);
                    self.yaw.entry(f).or_default().push(v, yaw);
                }
            }
            widen(&mut self.cov[0], pose.x);
            widen(&mut self.cov[3], pitch);
            widen(&mut self.cov[4], yaw);
        }
    }
}

impl Accs {
    /// What was skipped and why, for a refusal.
    fn skipped_text(&self) -> String {
        if self.skipped.is_empty() {
            // A sweep of a header alone, or of no frames at all.
            return "none (the sweep has no frames)".into();
        }
        self.skipped
            .iter()
            .map(|(k, v)| format!("{v} {k}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Refuse sweeps without translation or without orientation frames.
    fn check_usable(&self) -> Result<(), CalibrateError> {
        if self.translation == 0 {
            return Err(CalibrateError::Refused(format!(
                "no usable translation frames (pitch = yaw = 0 with light and no saturation); skipped: {}",
                self.skipped_text()
            )));
        }
        if self.orientation == 0 {
            return Err(CalibrateError::Refused(format!(
                "no usable orientation frames (y = z = 0 with pitch or yaw swept); skipped: {}",
                self.skipped_text()
            )));
        }
        Ok(())
    }

    /// The poses covered, [min, max] per quantity ([0, 0] where none).
    fn coverage(&self) -> Coverage {
        let cov = |i: usize| self.cov[i].unwrap_or([0.0, 0.0]);
        Coverage {
            x_m: cov(0),
            y_m: cov(1),
            z_m: cov(2),
            pitch_deg: cov(3),
            yaw_deg: cov(4),
        }
    }
}

/// The best of `cands` for one quantity, by R².
fn fitted(cands: &BTreeMap<Feature, LineAcc>) -> BTreeMap<Feature, Line> {
    cands
        .iter()
        .filter_map(|(f, a)| a.solve().ok().map(|l| (*f, l)))
        .collect()
}

/// Choose features for two quantities that must use different moments
/// (pitch and yaw; y and z), maximising the sum of R².
fn assign(
    a: &BTreeMap<Feature, Line>,
    b: &BTreeMap<Feature, Line>,
) -> Option<((Feature, Line), (Feature, Line))> {
    let mut best: Option<((Feature, Line), (Feature, Line))> = None;
    for (fa, la) in a {
        for (fb, lb) in b {
            if fa.moment == fb.moment {
                continue;
            }
            let better = best
                .as_ref()
                .is_none_or(|(x, y)| la.r2 + lb.r2 > x.1.r2 + y.1.r2);
            if better {
                best = Some(((*fa, *la), (*fb, *lb)));
            }
        }
    }
    best
}

fn linear(f: Feature, l: Line) -> LinearFit {
    LinearFit {
        feature: f,
        a: l.slope,
        b: l.intercept,
        r2: l.r2,
        sigma: l.sigma,
        n: l.n,
    }
}

/// Fit a calibration. Refused lines are handed to `on_bad_line` and skipped.
/// The `[physical]` table is included when the sweeps determine it; see
/// [`calibrate_full`] for the reason when they do not.
pub fn calibrate(
    opts: &CalibrateOptions,
    on_bad_line: impl FnMut(&LogError),
) -> Result<Calibration, CalibrateError> {
    calibrate_full(opts, on_bad_line).map(|c| c.cal)
}

/// The physical fitter, fed the same frames as the paper's fit; its first
/// error stops it (and is kept as the reason), since a refused frame would
/// bias the fit.
struct PhysicalFeed {
    fitter: Option<PhysicalFitter>,
    err: Option<CalibError>,
}

impl PhysicalFeed {
    fn new(opts: &CalibrateOptions) -> Self {
        PhysicalFeed {
            fitter: opts.physical.as_ref().map(|_| PhysicalFitter::new()),
            err: None,
        }
    }

    /// Feed one frame.
    fn feed(&mut self, r: impl FnOnce(&mut PhysicalFitter) -> Result<(), CalibError>) {
        if let Some(f) = self.fitter.as_mut() {
            if let Err(e) = r(f) {
                self.err = Some(e);
                self.fitter = None;
            }
        }
    }

    /// `cal` with the `[physical]` table when the fit gives a usable model,
    /// else without it and with the reason.
    fn finish(self, cal: Calibration, opts: &CalibrateOptions, v_ref: f64) -> Calibrated {
        let mut out = Calibrated {
            cal,
            physical_skipped: self.err,
            notes: Vec::new(),
        };
        if let (Some(fitter), Some(o)) = (self.fitter, &opts.physical) {
            let o = FitOptions { v_ref, ..o.clone() };
            match fitter.fit(&o) {
                Ok(p) => {
                    let mut with = out.cal.clone();
                    with.physical = Some(p);
                    // A fit that gives an unusable model is the same as none.
                    match with.check() {
                        Ok(()) => out.cal = with,
                        Err((_, _, m)) => {
                            out.physical_skipped = Some(CalibError::NoConvergence(m));
                        }
                    }
                }
                Err(e) => out.physical_skipped = Some(e),
            }
        }
        out
    }
}

/// Refuse options no calibration can come from.
fn check_options(opts: &CalibrateOptions) -> Result<(), CalibrateError> {
    if opts.sweeps.is_empty() {
        return Err(CalibrateError::Refused("no sweep log given".into()));
    }
    if !(2..=MAX_SURGE_WINDOW).contains(&opts.surge_window) {
        return Err(CalibrateError::Refused(format!(
            "surge window {} must be 2..{}",
            opts.surge_window, MAX_SURGE_WINDOW
        )));
    }
    Ok(())
}

/// Pass 1: the dark frames, from the dark log or from dark sweeps, with the
/// names of the logs they came from.
fn dark_pass(
    opts: &CalibrateOptions,
    phys: &mut PhysicalFeed,
    bad: &mut BadLines,
) -> Result<(DarkAcc, Vec<String>), CalibrateError> {
    let mut dark = DarkAcc::default();
    let mut sources = Vec::new();
    let mut add = |p: &Path, bad: &mut BadLines| -> Result<(), CalibrateError> {
        let v_ref = header_v_ref(&header_of(p)?, opts.v_ref, p).map_err(CalibrateError::Refused)?;
        stream(
            p,
            |f, _| {
                dark.push(f, v_ref);
                phys.feed(|p| p.add_dark(f));
            },
            bad,
        )?;
        sources.push(p.display().to_string());
        Ok(())
    };
    if let Some(p) = &opts.dark {
        add(p, bad)?;
    }
    for p in &opts.sweeps {
        if is_dark_sweep(&header_of(p)?) {
            add(p, bad)?;
        }
    }
    Ok((dark, sources))
}

/// What pass 2 gathered: the accumulators, the first lit sweep's header,
/// the name of every sweep, and the ADC reference of the last lit one.
struct LitPass {
    accs: Accs,
    header: LogHeader,
    sweeps: Vec<String>,
    v_ref: f64,
}

/// Pass 2: the lit, truth-labelled frames.
fn lit_pass(
    opts: &CalibrateOptions,
    levels: &DarkLevels,
    phys: &mut PhysicalFeed,
    bad: &mut BadLines,
) -> Result<LitPass, CalibrateError> {
    let mut accs = Accs::default();
    let mut first_header = None;
    let mut sweeps = Vec::new();
    let mut v_ref = opts.v_ref;
    for p in &opts.sweeps {
        let h = header_of(p)?;
        sweeps.push(p.display().to_string());
        if is_dark_sweep(&h) {
            continue;
        }
        v_ref = header_v_ref(&h, opts.v_ref, p).map_err(CalibrateError::Refused)?;
        let header = stream(
            p,
            |f, _| {
                // Both fits see the same frames: one the paper's fits
                // skip as impossible must not reach the light model.
                if let Some(why) = super::sweep_frame_fault(f) {
                    *accs.skipped.entry(why).or_default() += 1;
                    return;
                }
                accs.push(
                    f,
                    v_ref,
                    &levels.offsets,
                    opts.default_temp_c,
                    levels.no_light_v,
                );
                phys.feed(|p| p.add_frame(f));
            },
            bad,
        )?;
        first_header.get_or_insert(header);
    }
    let Some(header) = first_header else {
        return Err(CalibrateError::Refused(
            "every sweep given is a dark sweep: no lit frames".into(),
        ));
    };
    Ok(LitPass {
        accs,
        header,
        sweeps,
        v_ref,
    })
}

/// x: ln PD = ln a1 − b1·x, from the on-axis frames where the sweep has
/// them at two distances or more. The paper's tank results (≤ 0.02 m on
/// the axis at the start, 0.5 m at a 0.6/0.8 m offset) fit a range law
/// taken on the axis; a fit over the whole y/z grid instead reads every
/// on-axis distance about 0.9 m short at 4.5 m, because off-axis frames
/// dim the peak by up to half (docs/pipeline.md).
fn range_fit(accs: &Accs) -> Result<RangeFit, CalibrateError> {
    let (basis, x_acc) = match accs.x_axis.solve() {
        Ok(_) => (RangeBasis::Axis, &accs.x_axis),
        Err(_) => (RangeBasis::Grid, &accs.x),
    };
    let x_line = x_acc.solve().map_err(|e| {
        CalibrateError::Refused(match e {
            FitError::InputConstant => format!(
                "the translation frames cover only x = {} m: the range fit needs at least two distances",
                accs.cov[0].map_or(f64::NAN, |r| r[0])
            ),
            e => format!("range fit (x from PD_max): {e}"),
        })
    })?;
    // The fit is ln PD against x; swap roles: u = x, v = ln PD.
    // (A NaN slope is refused too.)
    if x_line.slope.is_nan() || x_line.slope >= 0.0 {
        return Err(CalibrateError::Refused(format!(
            "the peak does not fall with distance (d ln PD/dx = {:.4}): not a beacon sweep",
            x_line.slope
        )));
    }
    let b1 = -x_line.slope;
    // The σ the estimator reports for x: residuals of every translation
    // frame about the law, so that off-axis dimming the on-axis law does
    // not model is counted as uncertainty, not hidden.
    let sigma_ln = match basis {
        RangeBasis::Axis => accs.x.rms_about(x_line.slope, x_line.intercept),
        RangeBasis::Grid => x_line.sigma,
    };
    Ok(RangeFit {
        a1: x_line.intercept.exp(),
        b1,
        r2: x_line.r2,
        sigma_ln,
        sigma_m: sigma_ln / b1,
        n: x_line.n,
        basis,
    })
}

/// Refuse a quantity the sweep never varied.
fn check_varies(acc: &BTreeMap<Feature, LineAcc>, what: &str) -> Result<(), CalibrateError> {
    match acc.values().next().map(|a| a.solve()) {
        Some(Err(FitError::TargetConstant)) => Err(CalibrateError::Refused(format!(
            "{what} never varies in the sweep: the fit needs it swept"
        ))),
        _ => Ok(()),
    }
}

/// The pitch, yaw, y and z lines, each on the feature the data say tracks
/// it best, and every candidate's R² (the calibration's `selection`).
fn feature_fits(x: RangeFit, accs: &Accs) -> Result<(Fits, Selection), CalibrateError> {
    let (pitch_c, yaw_c) = (fitted(&accs.pitch), fitted(&accs.yaw));
    check_varies(&accs.pitch, "pitch (orientation frames)")?;
    check_varies(&accs.yaw, "yaw (orientation frames)")?;
    check_varies(&accs.y, "y (translation frames)")?;
    check_varies(&accs.z, "z (translation frames)")?;
    let ((fp, lp), (fy, ly)) = assign(&pitch_c, &yaw_c).ok_or_else(|| {
        CalibrateError::Refused("no moment ratio could be fitted to pitch and yaw".into())
    })?;
    let (y_c, z_c) = (fitted(&accs.y), fitted(&accs.z));
    let ((fyy, lyy), (fz, lz)) = assign(&y_c, &z_c).ok_or_else(|| {
        CalibrateError::Refused("no first moment could be fitted to y and z".into())
    })?;

    let mut selection = Selection::new();
    for (q, c) in [
        ("pitch", &pitch_c),
        ("yaw", &yaw_c),
        ("y", &y_c),
        ("z", &z_c),
    ] {
        selection.insert(
            q.into(),
            c.iter().map(|(f, l)| (f.to_string(), l.r2)).collect(),
        );
    }
    let fits = Fits {
        x,
        pitch: linear(fp, lp),
        yaw: linear(fy, ly),
        y: linear(fyy, lyy),
        z: linear(fz, lz),
    };
    Ok((fits, selection))
}

/// R² of every candidate feature per quantity.
type Selection = BTreeMap<String, BTreeMap<String, f64>>;

/// The thresholds the status word and the surge smoothing use.
fn limits(opts: &CalibrateOptions, no_light_v: f64, rate_hz: f64) -> Limits {
    Limits {
        no_light_v,
        surge_window: opts.surge_window,
        // The paper's requirements (x ±0.5 m, y, z ±0.2 m, angles ±5°):
        // an estimate that far outside the covered range is beyond
        // what the sweep can vouch for.
        margin_x_m: 0.5,
        margin_yz_m: 0.2,
        margin_angle_deg: 5.0,
        // Ten frames at the paper's 5 Hz.
        max_gap_s: 10.0 / rate_hz,
    }
}

/// Below this R² a fit of the paper's explains less of the sweep's spread
/// than it leaves: the paper's method reads that quantity little better
/// than its mean (the shipped harbour's pitch and yaw: 0.34 and 0.35, in
/// water whose scattering washes the spot out; the tank's are above 0.8).
const WEAK_R2: f64 = 0.5;

/// One note per fit of the paper's below `WEAK_R2`, with its σ (an R² that
/// is no number is weak too: hence `!(r2 >= …)`).
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn weak_fits(f: &Fits) -> Vec<String> {
    [
        ("x", f.x.r2, f.x.sigma_m, "m"),
        ("pitch", f.pitch.r2, f.pitch.sigma, "°"),
        ("yaw", f.yaw.r2, f.yaw.sigma, "°"),
        ("y", f.y.r2, f.y.sigma, "m"),
        ("z", f.z.r2, f.z.sigma, "m"),
    ]
    .into_iter()
    .filter(|(_, r2, _, _)| !(*r2 >= WEAK_R2))
    .map(|(q, r2, sigma, unit)| {
        format!(
            "the paper's {q} fit explains little of the sweep (R2 {r2:.2}, sigma {sigma:.3} {unit}): the paper's method reads {q} poorly here"
        )
    })
    .collect()
}

/// [`calibrate`], also saying why `[physical]` was left out.
pub fn calibrate_full(
    opts: &CalibrateOptions,
    mut on_bad_line: impl FnMut(&LogError),
) -> Result<Calibrated, CalibrateError> {
    check_options(opts)?;
    let mut bad = BadLines {
        count: 0,
        report: &mut on_bad_line,
        cuts: Vec::new(),
    };
    let mut phys = PhysicalFeed::new(opts);
    let (dark, dark_sources) = dark_pass(opts, &mut phys, &mut bad)?;
    let levels = dark_levels(&dark, &dark_sources)?;
    let LitPass {
        accs,
        header,
        sweeps,
        v_ref,
    } = lit_pass(opts, &levels, &mut phys, &mut bad)?;
    accs.check_usable()?;
    let (fits, selection) = feature_fits(range_fit(&accs)?, &accs)?;
    let cal = Calibration {
        meta: Meta {
            format: FORMAT.into(),
            version: VERSION,
            created_by: opts.created_by.clone(),
            sweeps,
            dark_source: levels.source,
            frames: accs.used,
            bad_lines: bad.count,
        },
        scene: SceneFacts {
            adc_bits: header.adc_bits,
            v_ref,
            t_ref_c: lightpose_core::light::T_REF_C,
            default_temp_c: opts.default_temp_c,
            rate_hz: header.rate_hz,
        },
        dark: Dark {
            offset_v: levels.offsets.to_vec(),
            sigma_v: levels.sigma,
            frames: dark.n,
        },
        fits,
        coverage: accs.coverage(),
        limits: limits(opts, levels.no_light_v, header.rate_hz),
        selection,
        physical: None,
        estimator: None,
        station: None,
    };
    cal.check()
        .map_err(|(t, k, m)| CalibrateError::Refused(format!("the fit gave {t}.{k}: {m}")))?;
    let mut out = phys.finish(cal, opts, v_ref);
    out.notes = bad.cuts;
    if !accs.skipped.is_empty() {
        out.notes.push(format!(
            "frames the paper's fits did not use: {}",
            accs.skipped_text()
        ));
    }
    out.notes.extend(weak_fits(&out.cal.fits));
    if let Some(p) = out.cal.physical.as_ref() {
        if p.chi2_per_dof > POOR_CHI2_PER_DOF {
            out.notes.push(format!(
                "the light model fits the sweep poorly (chi2/dof {:.1}, a good sweep's is ~1): are its truth poses the frames'?",
                p.chi2_per_dof
            ));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(name: &str) -> Calibration {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/calibration")
            .join(name);
        Calibration::load(&p).expect("shipped calibration")
    }

    /// The harbour's pitch and yaw fits (R² 0.34 and 0.35) are told, with
    /// their σ; none of the tank's (R² 0.80 or more).
    #[test]
    fn weak_fits_of_the_paper_s_are_told() {
        let notes = weak_fits(&shipped("harbour.toml").fits);
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(notes[0].contains("pitch fit") && notes[0].contains("R2 0.34"));
        assert!(notes[1].contains("yaw fit") && notes[1].contains("R2 0.35"));
        assert!(weak_fits(&shipped("tank.toml").fits).is_empty());
    }
}
