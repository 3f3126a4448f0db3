//! The Monte Carlo engine (paper section 3.1, MODEL.md "Monte Carlo
//! uncertainty"): each realization draws its own water temperature and K_D,
//! fixed over the run, simulates the trajectory with fresh electronic noise
//! while the frames report the nominal temperature, and runs an estimator
//! over it. The ensemble of estimates per time step is the paper's TPU.
//!
//! Realizations run in parallel with rayon, yet the result depends only on
//! the seed: realization `i` draws everything from ChaCha8 seeded with
//! `seed` on stream `i`, writes into its own slot of a preallocated buffer,
//! and every reduction runs afterwards in index order.

pub use crate::axis::{Axis, AXES, NAXES};
use crate::stats::{self, Coverage, StepStats};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use lightpose_core::Estimator;
use lightpose_sim::{EstimatorFrames, Kinematics, Scene, Simulator, Trajectory};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[derive(Debug, thiserror::Error)]
pub enum McError {
    #[error("runs must be at least 1")]
    NoRuns,
    #[error("the trajectory gives no frame at {rate_hz} Hz")]
    NoFrames { rate_hz: f64 },
    #[error("scene: {0}")]
    Scene(String),
    #[error("estimator: {0}")]
    Estimator(String),
    // The I/O error is in the message, not chained as a source, so that a
    // one-line `{:#}` report does not say it twice.
    #[error("{path}: {err}")]
    Io { path: String, err: std::io::Error },
    #[error("{path}: cannot plot: {msg}")]
    Plot { path: String, msg: String },
    #[error("unknown case \"{0}\" (known: auto, none, dive-clear, zigzag-clear, zigzag-turbid, or their aliases dive-tank, zigzag-tank, zigzag-harbour)")]
    UnknownCase(String),
}

/// What to simulate.
#[derive(Debug, Clone)]
pub struct McConfig {
    /// The nominal scene: `temp_c` and `light.k_d` are T0 and K_D0, and
    /// `montecarlo` gives the spreads drawn around them.
    pub scene: Scene,
    pub trajectory: Trajectory,
    pub runs: usize,
    pub seed: u64,
}

/// What one realization drew.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Draw {
    /// True water temperature of the run, °C.
    pub temp_c: f64,
    /// K_D of the run, 1/m.
    pub k_d: f64,
}

/// The ensemble and its statistics.
#[derive(Debug, Clone)]
pub struct McResult {
    pub runs: usize,
    pub seed: u64,
    /// Name the estimator gives itself.
    pub estimator: String,
    /// Frame times, s.
    pub times: Vec<f64>,
    /// True value per step and axis.
    pub truth: Vec<[f64; NAXES]>,
    /// Per realization, in index order.
    pub draws: Vec<Draw>,
    /// Per step, in time order.
    pub steps: Vec<StepStats>,
    /// Per axis: how often truth lay within ±2 of the estimator's own σ
    /// (`None` where the estimator reports no σ for that axis).
    pub coverage: [Option<Coverage>; NAXES],
    /// Every estimate, run-major (`[run][step][axis]`), NaN where the
    /// estimator gave none: kept for trade tables and tests.
    samples: Vec<f64>,
    /// Per estimate (`[run][step]`): its status was `ok`. The open sea's
    /// rows judge only the poses the estimator vouched for.
    oks: Vec<bool>,
    /// Per estimate and axis (`[run][step][axis]`): |error| / the
    /// estimator's own σ, NaN where it gave no value or no σ (∞ for an
    /// error with σ 0). The open sea's rows count poses beyond 3σ.
    zscores: Vec<f64>,
    /// Wall time of the realizations (not of the statistics).
    pub elapsed: Duration,
    pub threads: usize,
}

impl McResult {
    /// The estimate of `axis` at `step` in realization `run`, if it gave one.
    pub fn sample(&self, run: usize, step: usize, axis: Axis) -> Option<f64> {
        let n = self.times.len();
        self.samples
            .get((run * n + step) * NAXES + axis.index())
            .copied()
            .filter(|v| v.is_finite())
    }

    /// Whether the estimate at `step` of realization `run` had status
    /// `ok` (false for a step or run out of range).
    pub fn ok(&self, run: usize, step: usize) -> bool {
        let n = self.times.len();
        step < n && self.oks.get(run * n + step).copied().unwrap_or(false)
    }

    /// |error| / σ of `axis` at `step` in realization `run`, if the
    /// estimate gave both a value and a σ.
    pub fn zscore(&self, run: usize, step: usize, axis: Axis) -> Option<f64> {
        let n = self.times.len();
        if step >= n {
            return None;
        }
        self.zscores
            .get((run * n + step) * NAXES + axis.index())
            .copied()
            .filter(|v| !v.is_nan())
    }

    /// The axes its tables show: every one of [`AXES`] but roll, and roll
    /// when some estimate gave it (a station's): one beacon's results read
    /// as they always did.
    pub fn axes(&self) -> Vec<Axis> {
        let has_roll = self
            .steps
            .iter()
            .any(|s| s.axes[Axis::Roll.index()].is_some());
        AXES.into_iter()
            .filter(|&a| a != Axis::Roll || has_roll)
            .collect()
    }

    /// Realizations per second of wall time.
    pub fn rate(&self) -> f64 {
        self.runs as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    /// True when two results hold bit-identical numbers (timing aside):
    /// what "independent of the thread count" means.
    pub fn same_numbers(&self, o: &McResult) -> bool {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        self.runs == o.runs
            && self.estimator == o.estimator
            && self.draws == o.draws
            && bits(&self.samples) == bits(&o.samples)
            && self.oks == o.oks
            && bits(&self.zscores) == bits(&o.zscores)
            && self.steps == o.steps
            && self.coverage == o.coverage
    }
}

/// A progress bar for `len` realizations on stderr, drawn only when stderr
/// is a terminal so that logs and pipes stay clean.
pub fn progress_bar(len: u64) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("montecarlo [{bar:30}] {pos}/{len} ({per_sec}, eta {eta})")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// Per-step outcome codes of the coverage check, one byte per axis.
const COV_NONE: u8 = 0;
const COV_IN: u8 = 1;
const COV_OUT: u8 = 2;

/// What every realization shares: the frame times (of a frame of several
/// samples, its middle, MODEL.md) and the first sample's, the true motion
/// and the truth rows there.
struct Track {
    times: Vec<f64>,
    starts: Vec<f64>,
    truth: Vec<[f64; NAXES]>,
}

/// The track of `cfg`, or why it cannot be run.
fn track_of(cfg: &McConfig) -> Result<Track, McError> {
    if cfg.runs == 0 {
        return Err(McError::NoRuns);
    }
    let rate = cfg.scene.adc.rate_hz;
    let (n, sample_hz) = (cfg.scene.adc.samples_per_frame(), cfg.scene.adc.sample_hz);
    let frames = cfg.trajectory.burst_count(rate, n, sample_hz) as usize;
    let starts: Vec<f64> = cfg.trajectory.frame_times(rate).take(frames).collect();
    let mid = (n - 1) as f64 / (2.0 * sample_hz);
    let times: Vec<f64> = starts.iter().map(|&t| t + mid).collect();
    if times.is_empty() || rate.is_nan() || rate <= 0.0 {
        return Err(McError::NoFrames { rate_hz: rate });
    }
    let spread = cfg.scene.montecarlo;
    if !(spread.sigma_temp_c >= 0.0 && spread.sigma_k_d >= 0.0) {
        return Err(McError::Scene(format!(
            "montecarlo spreads must be ≥ 0 (sigma_temp_c = {}, sigma_k_d = {})",
            spread.sigma_temp_c, spread.sigma_k_d
        )));
    }
    // A blinking scene's demodulator, checked once here so that no
    // realization meets an error.
    EstimatorFrames::new(Simulator::new(cfg.scene.clone(), 0))
        .map_err(|e| McError::Scene(format!("demodulator: {e}")))?;
    let kinematics: Vec<Kinematics> = times
        .iter()
        .map(|&t| cfg.trajectory.kinematics(t))
        .collect();
    let truth = kinematics
        .iter()
        .map(|k| {
            let [x, y, z, pitch, yaw, surge] = k.pose.values_with_surge(k.surge());
            [x, y, z, pitch, yaw, surge, k.pose.roll.deg()]
        })
        .collect();
    Ok(Track {
        times,
        starts,
        truth,
    })
}

/// Run the ensemble. `factory` makes one estimator per rayon worker (it is
/// reset before every realization, so state never leaks between runs);
/// `progress` advances once per realization (pass `ProgressBar::hidden()`
/// for none).
pub fn run<F, E>(cfg: &McConfig, factory: F, progress: &ProgressBar) -> Result<McResult, McError>
where
    F: Fn() -> Result<Box<dyn Estimator>, E> + Sync,
    E: std::fmt::Display,
{
    let Track {
        times,
        starts,
        truth,
    } = track_of(cfg)?;
    // One probe both names the estimator and turns a factory error into a
    // clean error before any thread starts.
    let name = factory()
        .map_err(|e| McError::Estimator(e.to_string()))?
        .name()
        .to_string();
    let nsteps = times.len();
    let per_run = nsteps * NAXES;

    // Flat buffers, one slot per run: nothing is allocated per realization.
    let mut samples = vec![f64::NAN; cfg.runs * per_run];
    let mut ok = vec![false; cfg.runs * nsteps];
    let mut cov = vec![COV_NONE; cfg.runs * per_run];
    let mut zscores = vec![f64::NAN; cfg.runs * per_run];
    let mut draws = vec![Draw::default(); cfg.runs];
    let failure: Mutex<Option<String>> = Mutex::new(None);

    let start = Instant::now();
    samples
        .par_chunks_mut(per_run)
        .zip(ok.par_chunks_mut(nsteps))
        .zip(cov.par_chunks_mut(per_run))
        .zip(zscores.par_chunks_mut(per_run))
        .zip(draws.par_iter_mut())
        .enumerate()
        // Few, long jobs: each rayon job builds one estimator.
        .with_min_len(8)
        .for_each_init(
            || factory().map_err(|e| e.to_string()),
            |est, (i, ((((vals, oks), covs), zs), draw))| {
                match est {
                    Ok(est) => {
                        *draw = realization(
                            cfg,
                            i as u64,
                            &starts,
                            &truth,
                            est.as_mut(),
                            Slots {
                                vals,
                                oks,
                                covs,
                                zs,
                            },
                        );
                    }
                    Err(msg) => {
                        if let Ok(mut f) = failure.lock() {
                            f.get_or_insert_with(|| msg.clone());
                        }
                    }
                }
                progress.inc(1);
            },
        );
    let elapsed = start.elapsed();
    if let Some(msg) = failure.into_inner().ok().flatten() {
        return Err(McError::Estimator(msg));
    }

    let steps = stats::per_step(&samples, &ok, &times, cfg.runs);
    let coverage = stats::coverage(&cov, |c| match c {
        COV_IN => Some(true),
        COV_OUT => Some(false),
        _ => None,
    });
    Ok(McResult {
        runs: cfg.runs,
        seed: cfg.seed,
        estimator: name,
        times,
        truth,
        draws,
        steps,
        coverage,
        samples,
        oks: ok,
        zscores,
        elapsed,
        threads: rayon::current_num_threads(),
    })
}

/// One realization's slots of the ensemble's buffers.
struct Slots<'a> {
    vals: &'a mut [f64],
    oks: &'a mut [bool],
    covs: &'a mut [u8],
    zs: &'a mut [f64],
}

/// One realization, written into its own slots. Everything random comes
/// from ChaCha8(seed, stream = index), drawn in a fixed order: T, K_D, then
/// the simulator's seed.
fn realization(
    cfg: &McConfig,
    index: u64,
    starts: &[f64],
    truth: &[[f64; NAXES]],
    est: &mut dyn Estimator,
    out: Slots<'_>,
) -> Draw {
    let Slots {
        vals,
        oks,
        covs,
        zs,
    } = out;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    rng.set_stream(index);
    let nominal = &cfg.scene;
    let spread = nominal.montecarlo;
    let n1: f64 = StandardNormal.sample(&mut rng);
    let n2: f64 = StandardNormal.sample(&mut rng);
    let draw = Draw {
        // Liquid water as the estimators take it: a wide spread had drawn
        // 26.65 ± 45.49 °C, a third of the runs in no water at all.
        temp_c: (nominal.temp_c + spread.sigma_temp_c * n1).clamp(
            *lightpose_core::light::WATER_TEMP_C.start(),
            *lightpose_core::light::WATER_TEMP_C.end(),
        ),
        // Water cannot amplify light: a (very unlikely) negative draw is
        // clear water, not a gain.
        k_d: (nominal.light.k_d + spread.sigma_k_d * n2).max(0.0),
    };
    let sim_seed = rng.next_u64();

    let mut scene = nominal.clone();
    scene.temp_c = draw.temp_c;
    scene.light.k_d = draw.k_d;
    let mut sim = Simulator::new(scene, sim_seed);
    // The vehicle's sensor is believed: the frames report T0 exactly, so
    // the temperature spread is an error source (MODEL.md, as the paper).
    sim.set_reported_temp(Some(nominal.temp_c));
    sim.set_report_roll(cfg.trajectory.has_roll());
    // `run` checked the scene: its demodulator, if it needs one, is made.
    let Ok(mut frames) = EstimatorFrames::new(sim) else {
        return draw;
    };
    let at = |t: f64| cfg.trajectory.kinematics(t);

    est.reset();
    for (j, (&t, tr)) in starts.iter().zip(truth).enumerate() {
        let frame = frames.frame(j as u64, t, at);
        let e = est.estimate(&frame);
        oks[j] = e.status == lightpose_core::Status::Ok;
        for a in AXES {
            let k = j * NAXES + a.index();
            let v = a.of(&e).filter(|v| v.is_finite());
            vals[k] = v.unwrap_or(f64::NAN);
            covs[k] = match (v, a.std_of(&e).filter(|s| s.is_finite() && *s >= 0.0)) {
                (Some(v), Some(s)) => {
                    let mut err = v - tr[a.index()];
                    if matches!(a, Axis::Yaw | Axis::Roll) {
                        // An angle: an error of 359° is −1°.
                        err = (err + 180.0).rem_euclid(360.0) - 180.0;
                    }
                    zs[k] = if err == 0.0 { 0.0 } else { err.abs() / s };
                    if err.abs() <= 2.0 * s {
                        COV_IN
                    } else {
                        COV_OUT
                    }
                }
                _ => COV_NONE,
            };
        }
    }
    draw
}
