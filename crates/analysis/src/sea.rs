//! The trade table's open sea (spec v3, issue 40 item 5): every estimator
//! on a harbour approach with the beacon blinking or steady, at night or
//! by day, each case its own shipped scene and a calibration made from
//! that scene's sweeps (the steady ones at night, with the ambient
//! modelled by day: `[estimator.*.daylight]`).
//!
//! Why a section of its own and not more rows of the paper's: what
//! decides the open sea is not the ensemble's band at two instants but
//! whether a pose is given at all and whether its σ is honest, so each row
//! says how many poses were `ok` after the first second and judges only
//! those (p95 of |error|, ±2σ coverage, the share beyond 3σ), as the
//! held-out harbour test does (crates/pipeline/tests/harbour.rs). And a
//! blinking beacon's frame costs its demodulation, which the paper's
//! frames of counts never paid: its time per frame is the demodulator on
//! the frame's burst plus the estimator on what it gives.

use crate::axis::Axis;
use crate::bound::{crb_scene, track_bound_along};
use crate::montecarlo::{self, McConfig, McResult};
use crate::trade::{
    num, simulate_runs, time_per_frame, Case, Loaded, TradeError, TradeOptions, Z95,
};
use lightpose_core::samples::{Burst, Demodulated};
use lightpose_core::Estimator;
use lightpose_demod::{demodulator_for, Demodulator};
use lightpose_pipeline::model::crb::crb_along;
use lightpose_pipeline::{build_estimator, BuildError};
use lightpose_sim::{Scene, Simulator, Trajectory};
use std::fmt::Write as _;
use std::time::Instant;

pub use crate::sea_plot::plot_png;

/// The open sea's plot, in `lightpose bench --plot DIR`.
pub const PLOT_NAME: &str = "sea-p95.png";

const TRAJECTORY: &str = "config/trajectories/approach.csv";

/// The open sea's cases, night before day, blinking before steady.
pub const SEA_CASES: [Case; 4] = [
    Case {
        name: "approach-blinking-night",
        paper: None,
        scene: "config/scenes/sea-blinking-night.toml",
        trajectory: TRAJECTORY,
        calibration: "config/calibration/sea-blinking-night.toml",
    },
    Case {
        name: "approach-blinking-day",
        paper: None,
        scene: "config/scenes/sea-blinking-day.toml",
        trajectory: TRAJECTORY,
        calibration: "config/calibration/sea-blinking-day.toml",
    },
    Case {
        name: "approach-steady-night",
        paper: None,
        scene: "config/scenes/sea-steady-night.toml",
        trajectory: TRAJECTORY,
        calibration: "config/calibration/sea-steady.toml",
    },
    Case {
        name: "approach-steady-day",
        paper: None,
        scene: "config/scenes/sea-steady-day.toml",
        trajectory: TRAJECTORY,
        calibration: "config/calibration/sea-steady-day.toml",
    },
];

/// Poses of the first second are the estimators' start-up, not judged.
pub const SETTLE_S: f64 = 1.0;

/// The judged axes: x, y, z, pitch, yaw.
pub const JUDGED: [Axis; 5] = [Axis::X, Axis::Y, Axis::Z, Axis::Pitch, Axis::Yaw];

/// What the `ok` poses after the first second gave, over every run.
#[derive(Debug, Clone, PartialEq)]
pub struct Judged {
    /// Frames after the first second, all runs.
    pub frames: usize,
    /// Of those, the `ok` ones.
    pub ok: usize,
    /// p95 of |error| per judged axis (m, m, m, °, °); `None` without an
    /// `ok` pose.
    pub p95: [Option<f64>; 5],
    /// Share of `ok` poses within ±2σ on x, y, z.
    pub cover2: [Option<f64>; 3],
    /// Share of `ok` poses beyond 3σ on x, y or z.
    pub beyond3: Option<f64>,
}

/// p95 as the harbour test takes it: the value at rank ⌈0.95·n⌉.
pub(crate) fn p95(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len());
    Some(v[rank - 1])
}

/// Judge `mc`'s `ok` poses whose time is `SETTLE_S` or more past `t0`.
pub fn judge(mc: &McResult, t0: f64) -> Judged {
    let steps: Vec<usize> = (0..mc.times.len())
        .filter(|&j| mc.times[j] - t0 >= SETTLE_S)
        .collect();
    let mut errs: [Vec<f64>; 5] = Default::default();
    let (mut inside, mut with_std, mut beyond) = ([0usize; 3], [0usize; 3], 0usize);
    let mut ok = 0;
    for run in 0..mc.runs {
        for &j in &steps {
            if !mc.ok(run, j) {
                continue;
            }
            ok += 1;
            for (i, a) in JUDGED.into_iter().enumerate() {
                let Some(v) = mc.sample(run, j, a) else {
                    continue;
                };
                let mut e = v - mc.truth[j][a.index()];
                if a == Axis::Yaw {
                    e = (e + 180.0).rem_euclid(360.0) - 180.0;
                }
                errs[i].push(e.abs());
            }
            let z: Vec<Option<f64>> = JUDGED[..3].iter().map(|&a| mc.zscore(run, j, a)).collect();
            for (i, z) in z.iter().enumerate() {
                if let Some(z) = z {
                    with_std[i] += 1;
                    inside[i] += usize::from(*z <= 2.0);
                }
            }
            beyond += usize::from(z.iter().flatten().any(|z| *z > 3.0));
        }
    }
    let share = |n: usize, of: usize| (of > 0).then(|| n as f64 / of as f64);
    Judged {
        frames: mc.runs * steps.len(),
        ok,
        p95: errs.each_mut().map(|v| p95(v)),
        cover2: [0, 1, 2].map(|i| share(inside[i], with_std[i])),
        beyond3: share(beyond, ok),
    }
}

/// Pre-simulated bursts of `runs` realizations of a blinking scene (the
/// seeds of [`simulate_runs`]), for timing the demodulator on them.
fn simulate_bursts(scene: &Scene, traj: &Trajectory, runs: usize, seed: u64) -> Vec<Vec<Burst>> {
    let (n, sample_hz) = (scene.adc.samples_per_frame(), scene.adc.sample_hz);
    let count = traj.burst_count(scene.adc.rate_hz, n, sample_hz) as usize;
    let starts: Vec<f64> = traj.frame_times(scene.adc.rate_hz).take(count).collect();
    (0..runs)
        .map(|i| {
            let mut sim = Simulator::new(scene.clone(), seed.wrapping_add(1000 + i as u64));
            sim.set_report_roll(traj.has_roll());
            starts
                .iter()
                .enumerate()
                .map(|(j, &t)| {
                    let mut b = Burst::new(n);
                    sim.burst(j as u64, t, |t| traj.kinematics(t), &mut b);
                    b
                })
                .collect()
        })
        .collect()
}

/// Median wall time per frame, µs, of `replay` (which resets what it
/// times and goes through one run's bursts) over each run of `bursts`,
/// each replayed until 2 ms have passed, as [`time_per_frame`] does for
/// frames of counts.
fn time_bursts(bursts: &[Vec<Burst>], mut replay: impl FnMut(&[Burst])) -> f64 {
    let mut per: Vec<f64> = Vec::with_capacity(bursts.len());
    for run in bursts.iter().filter(|r| !r.is_empty()) {
        let (mut reps, start) = (0u32, Instant::now());
        loop {
            replay(run);
            reps += 1;
            if start.elapsed().as_secs_f64() >= 2e-3 {
                break;
            }
        }
        per.push(start.elapsed().as_secs_f64() * 1e6 / (reps as f64 * run.len() as f64));
    }
    per.sort_by(f64::total_cmp);
    per.get(per.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The demodulator of a blinking scene and what it writes into.
pub(crate) struct Demod {
    d: Demodulator,
    out: Demodulated,
}

impl Demod {
    fn step(&mut self, b: &Burst) -> Option<lightpose_core::Frame> {
        self.d.demodulate_burst(b, &mut self.out).ok()?;
        Some(self.out.to_frame())
    }
}

/// How a case's frames are timed: over frames of counts (a steady
/// beacon), or over bursts through the demodulator (a blinking one; a
/// station's too, [`crate::dock`]).
pub(crate) enum Timing {
    Counts(Vec<Vec<lightpose_core::Frame>>),
    Bursts {
        bursts: Vec<Vec<Burst>>,
        demod: Box<Demod>,
        /// The demodulator alone, µs per frame.
        demod_us: f64,
    },
}

impl Timing {
    fn new(l: &Loaded, o: &TradeOptions) -> Result<Timing, TradeError> {
        Timing::of(&l.scene, &l.trajectory, l.case.name, o)
    }

    /// `scene`'s frames along `traj` (`case` names it in an error).
    pub(crate) fn of(
        scene: &Scene,
        traj: &Trajectory,
        case: &'static str,
        o: &TradeOptions,
    ) -> Result<Timing, TradeError> {
        let runs = o.timing_runs.max(1);
        let demod = demodulator_for(&scene.log_header())
            .map_err(|err| TradeError::Demodulator { case, err })?;
        let Some(d) = demod else {
            return Ok(Timing::Counts(simulate_runs(scene, traj, runs, o.seed)));
        };
        let out = d.output();
        let mut demod = Box::new(Demod { d, out });
        let bursts = simulate_bursts(scene, traj, runs, o.seed);
        let demod_us = time_bursts(&bursts, |run| {
            demod.d.reset();
            for b in run {
                std::hint::black_box(demod.step(std::hint::black_box(b)));
            }
        });
        Ok(Timing::Bursts {
            bursts,
            demod,
            demod_us,
        })
    }

    /// The demodulator alone, µs per frame (None for a steady beacon).
    pub(crate) fn demod_us(&self) -> Option<f64> {
        match self {
            Timing::Counts(_) => None,
            Timing::Bursts { demod_us, .. } => Some(*demod_us),
        }
    }

    /// µs per frame of `est`, the demodulator included for bursts.
    pub(crate) fn per_frame(&mut self, est: &mut dyn Estimator) -> f64 {
        match self {
            Timing::Counts(frames) => time_per_frame(est, frames),
            Timing::Bursts { bursts, demod, .. } => time_bursts(bursts, |run| {
                demod.d.reset();
                est.reset();
                for b in run {
                    if let Some(f) = demod.step(std::hint::black_box(b)) {
                        std::hint::black_box(est.estimate(&f));
                    }
                }
            }),
        }
    }
}

/// One estimator's row of the open sea.
pub struct SeaRow {
    pub name: String,
    /// µs per frame, the demodulator included for a blinking beacon.
    pub us_per_frame: f64,
    pub judged: Judged,
    pub mc: McResult,
}

/// One case of the open sea: its rows, what it skipped, and the bounds
/// at the last frame (95 % half-widths of x, y, z; `model::bound_light`'s
/// reading of the scene's light).
pub struct SeaSection {
    pub case: &'static Case,
    pub blinking: bool,
    pub day: bool,
    pub runs: usize,
    /// The demodulator alone, µs per frame (a blinking beacon).
    pub demod_us: Option<f64>,
    pub rows: Vec<SeaRow>,
    pub skipped: Vec<String>,
    pub crb_end: Option<[f64; 3]>,
    pub track_end: Option<[f64; 3]>,
}

/// Run every estimator of `o` on the open-sea case `l`, the scene's own
/// sensors (its AHRS with roll); `progress` as for [`crate::trade::run_section`].
pub fn run_case(
    l: &Loaded,
    o: &TradeOptions,
    progress: &dyn Fn(u64) -> indicatif::ProgressBar,
) -> Result<SeaSection, TradeError> {
    let (scene, traj, case) = (&l.scene, &l.trajectory, l.case);
    let end = traj
        .frame_times(scene.adc.rate_hz)
        .last()
        .map(|t| traj.sample(t).0);
    let crb_end = end
        .and_then(|p| crb_along(&crb_scene(scene), &[p]).first().copied())
        .map(|b| [b.x, b.y, b.z].map(|s| Z95 * s));
    let settings = l.calibration.estimator.clone().unwrap_or_default();
    let track_end = track_bound_along(scene, traj, &settings.tracker)
        .ok()
        .and_then(|b| b.last().copied())
        .map(|b| [b.x, b.y, b.z].map(|s| Z95 * s));
    let mut timing = Timing::new(l, o)?;
    let cfg = McConfig {
        scene: scene.clone(),
        trajectory: traj.clone(),
        runs: o.runs,
        seed: o.seed,
    };
    let mut sec = SeaSection {
        case,
        blinking: scene.adc.samples_per_frame() > 1,
        day: scene.daylight.is_some(),
        runs: o.runs,
        demod_us: timing.demod_us(),
        rows: Vec::new(),
        skipped: Vec::new(),
        crb_end,
        track_end,
    };
    let mc = scene.montecarlo;
    let cal = l
        .calibration
        .in_water_known_to(mc.sigma_k_d, mc.sigma_temp_c);
    for name in &o.estimators {
        let build = || build_estimator(name, &cal);
        let mut est = match build() {
            Ok(e) => e,
            Err(e @ BuildError::NoPhysical { .. }) => {
                sec.skipped
                    .push(format!("{}: skipped: {e}", case.calibration));
                continue;
            }
            Err(err) => {
                return Err(TradeError::Build {
                    case: case.name,
                    name: name.clone(),
                    err,
                })
            }
        };
        let us = timing.per_frame(est.as_mut());
        let bar = progress(o.runs as u64);
        let mc = montecarlo::run(&cfg, build, &bar);
        bar.finish_and_clear();
        let mc = mc.map_err(|err| TradeError::MonteCarlo {
            case: case.name,
            name: name.clone(),
            err,
        })?;
        sec.rows.push(SeaRow {
            name: mc.estimator.clone(),
            us_per_frame: us,
            judged: judge(&mc, traj.t0()),
            mc,
        });
    }
    Ok(sec)
}

pub(crate) fn pct(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{:.0}", 100.0 * v))
}

fn triple(v: Option<[f64; 3]>) -> String {
    v.map_or("—".into(), |v| v.map(|x| num(Some(x))).join(" / "))
}

/// The open sea's Markdown table, every case's rows.
pub fn table(secs: &[SeaSection]) -> String {
    let mut o = String::new();
    let runs = secs.first().map_or(0, |s| s.runs);
    let _ = writeln!(
        o,
        "\n### The open sea: harbour approach, blinking or steady, night or day ({runs} runs)\n"
    );
    let _ = writeln!(
        o,
        "| case | beacon | light | estimator | µs/frame (demod + estimator) | ok after 1 s | p95 x (m) | y (m) | z (m) | pitch (°) | yaw (°) | ±2σ x / y / z | beyond 3σ (x, y or z) | CRB 95% end x / y / z | tracker bound 95% end x / y / z |"
    );
    let _ = writeln!(
        o,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for s in secs {
        let beacon = if s.blinking { "blinking" } else { "steady" };
        let light = if s.day { "day" } else { "night" };
        for r in &s.rows {
            let j = &r.judged;
            let us = match s.demod_us {
                // The demodulator alone, timed apart: on a loaded machine
                // the two timings do not subtract.
                Some(d) => format!(
                    "{} (demod alone {})",
                    num(Some(r.us_per_frame)),
                    num(Some(d))
                ),
                None => num(Some(r.us_per_frame)),
            };
            let cov = if j.cover2.iter().all(Option::is_none) {
                "—".to_string()
            } else {
                format!(
                    "{} / {} / {} %",
                    pct(j.cover2[0]),
                    pct(j.cover2[1]),
                    pct(j.cover2[2])
                )
            };
            let beyond = j
                .beyond3
                .map_or("—".into(), |b| format!("{:.1} %", 100.0 * b));
            let _ = writeln!(
                o,
                "| {} | {beacon} | {light} | {} | {us} | {}/{} | {} | {} | {} | {} | {} | {cov} | {beyond} | {} | {} |",
                s.case.name,
                r.name,
                j.ok,
                j.frames,
                num(j.p95[0]),
                num(j.p95[1]),
                num(j.p95[2]),
                num(j.p95[3]),
                num(j.p95[4]),
                triple(s.crb_end),
                triple(s.track_end),
            );
        }
    }
    let _ = writeln!(
        o,
        "\nµs/frame: median over the timing runs, one thread, the frames' samples simulated up front; for a blinking beacon the demodulator on the frame's burst (25 channels × its samples) plus the estimator on the amplitudes it gives, in brackets the demodulator alone, timed apart (on a shared machine the two do not subtract exactly). p95, ±2σ and beyond 3σ: the `ok` poses after the first second, all runs. Bounds (`model::bound_light`): a blinking beacon's amplitudes at the white-noise limit of its samples (the sun's shot noise in, no demodulator's search, no model error); a steady beacon's counts, by day with the sun's level unknown each frame and each detector's own flicker a noise."
    );
    for s in secs {
        for k in &s.skipped {
            let _ = writeln!(o, "\n{}: {k}", s.case.name);
        }
    }
    o
}
