//! The speed-for-accuracy trade table (`lightpose bench`): every estimator
//! on the paper's three Monte Carlo cases (dive and zigzag in the tank,
//! zigzag in harbour water), each with a set of the vehicle's own sensors
//! (none, attitude, depth, attitude + depth, attitude + depth + DVL);
//! beside each axis the paper's published half-widths and the Cramér–Rao
//! bound at the start and end poses, so that "better" is measured against
//! both what was published and what the photodiodes allow.
//!
//! Why here and not in the tool: the table is analysis (it runs the Monte
//! Carlo engine, the bound and the timing), and the tool stays a thin
//! parser of arguments.
//!
//! Time per frame is measured apart from the Monte Carlo, on one thread over
//! pre-simulated frames: the engine runs realizations in parallel with the
//! simulator inside the loop, so its wall time says nothing about one
//! estimator's cost.

use crate::axis::{Axis, AXES};
use crate::bound::{crb_scene, track_bound_along};
use crate::montecarlo::{self, McConfig, McError, McResult};
use crate::paper::{Figure, PaperCase};
use crate::report::headline;
use crate::sensors::SensorSet;
use lightpose_core::{Estimator, Frame};
use lightpose_pipeline::model::crb::{crb_along, CrbBound};
use lightpose_pipeline::model::tracker::TrackBound;
use lightpose_pipeline::{build_estimator, BuildError, Calibration};
use lightpose_sim::{EstimatorFrames, Scene, Simulator, Trajectory};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// z of a 95 % two-sided interval: σ → half-width.
pub const Z95: f64 = 1.959964;

/// A case and its files under config/: one of the paper's (its figures
/// beside the rows), or one it never ran (the open sea, [`crate::sea`]).
#[derive(Debug)]
pub struct Case {
    pub name: &'static str,
    pub paper: Option<PaperCase>,
    pub scene: &'static str,
    pub trajectory: &'static str,
    pub calibration: &'static str,
}

pub const CASES: [Case; 3] = [
    Case {
        name: PaperCase::DiveClear.scene_name(),
        paper: Some(PaperCase::DiveClear),
        scene: "config/scenes/tank.toml",
        trajectory: "config/trajectories/dive.csv",
        calibration: "config/calibration/tank.toml",
    },
    Case {
        name: PaperCase::ZigzagClear.scene_name(),
        paper: Some(PaperCase::ZigzagClear),
        scene: "config/scenes/tank.toml",
        trajectory: "config/trajectories/zigzag.csv",
        calibration: "config/calibration/tank.toml",
    },
    Case {
        name: PaperCase::ZigzagTurbid.scene_name(),
        paper: Some(PaperCase::ZigzagTurbid),
        scene: "config/scenes/harbour.toml",
        trajectory: "config/trajectories/zigzag.csv",
        calibration: "config/calibration/harbour.toml",
    },
];

impl Case {
    /// The case called `name`: a paper case in either spelling
    /// (`dive-tank` or the paper case's `dive-clear`,
    /// [`PaperCase::named`]), or an open-sea case by its name.
    pub fn named(name: &str) -> Option<&'static Case> {
        if let Some(paper) = PaperCase::named(name) {
            return CASES.iter().find(|c| c.paper == Some(paper));
        }
        crate::sea::SEA_CASES
            .iter()
            .chain(crate::dock::DOCK_CASES.iter())
            .find(|c| c.name == name)
    }
}

// Each cause is in the message, not chained as a source as well, so that
// a one-line `{:#}` report says it once (the causes' own messages name
// the file and why).
#[derive(Debug, thiserror::Error)]
pub enum TradeError {
    #[error("case {case}: {err}")]
    Scene {
        case: &'static str,
        err: lightpose_sim::SceneError,
    },
    #[error("case {case}: {err}")]
    Trajectory {
        case: &'static str,
        err: lightpose_sim::TrajectoryError,
    },
    #[error("case {case}: {err}")]
    Calibration {
        case: &'static str,
        err: lightpose_pipeline::CalError,
    },
    #[error("case {case}, estimator {name}: {err}")]
    Build {
        case: &'static str,
        name: String,
        err: BuildError,
    },
    #[error("case {case}: {err}")]
    Demodulator {
        case: &'static str,
        err: lightpose_demod::ConfigError,
    },
    #[error("case {case}, estimator {name}: {err}")]
    MonteCarlo {
        case: &'static str,
        name: String,
        err: McError,
    },
}

/// A case's files, loaded.
pub struct Loaded {
    pub case: &'static Case,
    pub scene: Scene,
    pub trajectory: Trajectory,
    pub calibration: Calibration,
}

/// Load `case`'s scene, trajectory and calibration from under `root`.
pub fn load(root: &Path, case: &'static Case) -> Result<Loaded, TradeError> {
    let c = case.name;
    Ok(Loaded {
        case,
        scene: Scene::load(&root.join(case.scene))
            .map_err(|err| TradeError::Scene { case: c, err })?,
        trajectory: Trajectory::load(&root.join(case.trajectory))
            .map_err(|err| TradeError::Trajectory { case: c, err })?,
        calibration: Calibration::load(&root.join(case.calibration))
            .map_err(|err| TradeError::Calibration { case: c, err })?,
    })
}

/// What to run.
#[derive(Debug, Clone)]
pub struct TradeOptions {
    /// Monte Carlo realizations per case and sensor set.
    pub runs: usize,
    pub seed: u64,
    /// Realizations the time per frame is measured over (median).
    pub timing_runs: usize,
    pub estimators: Vec<String>,
}

/// One estimator's rows of a section.
pub struct Row {
    pub name: String,
    pub us_per_frame: f64,
    pub mc: McResult,
}

/// One case with one sensor set: its rows, the estimators it had to skip
/// (with why), and the single-frame bound at the first and last frame.
pub struct Section {
    pub case: &'static Case,
    pub sensors: SensorSet,
    pub runs: usize,
    pub rows: Vec<Row>,
    pub skipped: Vec<String>,
    pub crb: Vec<CrbBound>,
    /// The bound for a tracker (the tracker's motion model, the whole
    /// track) at the last frame, when the calibration has a light model.
    pub track_end: Option<TrackBound>,
}

/// Median wall time per frame of `est` over the simulated realizations
/// `frames`, microseconds. Each realization is replayed until at least
/// 2 ms have passed, so the clock's resolution does not matter.
pub fn time_per_frame(est: &mut dyn Estimator, frames: &[Vec<Frame>]) -> f64 {
    let mut per: Vec<f64> = Vec::with_capacity(frames.len());
    for run in frames {
        if run.is_empty() {
            continue;
        }
        let mut reps = 0u32;
        let start = Instant::now();
        loop {
            est.reset();
            for f in run {
                std::hint::black_box(est.estimate(std::hint::black_box(f)));
            }
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

/// `runs` realizations of the nominal scene along `traj`, the whole motion
/// read by the scene's sensors.
/// A blinking scene's frames are its bursts demodulated
/// ([`EstimatorFrames`]); a scene whose beacons cannot be demodulated (its
/// validation refuses such scenes) gives no runs.
pub fn simulate_runs(scene: &Scene, traj: &Trajectory, runs: usize, seed: u64) -> Vec<Vec<Frame>> {
    let (n, sample_hz) = (scene.adc.samples_per_frame(), scene.adc.sample_hz);
    let count = traj.burst_count(scene.adc.rate_hz, n, sample_hz) as usize;
    let starts: Vec<f64> = traj.frame_times(scene.adc.rate_hz).take(count).collect();
    (0..runs)
        .filter_map(|i| {
            let mut sim = Simulator::new(scene.clone(), seed.wrapping_add(1000 + i as u64));
            sim.set_report_roll(traj.has_roll());
            let mut frames = EstimatorFrames::new(sim).ok()?;
            Some(
                starts
                    .iter()
                    .enumerate()
                    .map(|(j, &t)| frames.frame(j as u64, t, |t| traj.kinematics(t)))
                    .collect(),
            )
        })
        .collect()
}

/// Run every estimator of `o` on `l`'s case with the sensor set `set`;
/// One estimator's Monte Carlo of a case, behind `bar` (cleared after).
pub(crate) fn monte_carlo<F, E>(
    cfg: &McConfig,
    build: F,
    bar: indicatif::ProgressBar,
    case: &'static str,
    name: &str,
) -> Result<McResult, TradeError>
where
    F: Fn() -> Result<Box<dyn Estimator>, E> + Sync,
    E: std::fmt::Display,
{
    let mc = montecarlo::run(cfg, build, &bar);
    bar.finish_and_clear();
    mc.map_err(|err| TradeError::MonteCarlo {
        case,
        name: name.to_string(),
        err,
    })
}

/// `progress` is called with the number of realizations before each
/// Monte Carlo and must return the bar to advance.
pub fn run_section(
    l: &Loaded,
    set: SensorSet,
    o: &TradeOptions,
    progress: &dyn Fn(u64) -> indicatif::ProgressBar,
) -> Result<Section, TradeError> {
    let mut scene = l.scene.clone();
    set.apply(&mut scene);
    let traj = &l.trajectory;
    let case = l.case;
    // The bound at the ends of the trajectory, with the engine's K_D and
    // temperature spreads and the sensors of the set.
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let ends: Vec<_> = [times.first(), times.last()]
        .into_iter()
        .flatten()
        .map(|&t| traj.sample(t).0)
        .collect();
    let crb = crb_along(&crb_scene(&scene), &ends);
    let settings = l.calibration.estimator.clone().unwrap_or_default();
    let track_end = track_bound_along(&scene, traj, &settings.tracker)
        .ok()
        .and_then(|b| b.last().copied());
    let timing = simulate_runs(&scene, traj, o.timing_runs.max(1), o.seed);
    let cfg = McConfig {
        scene,
        trajectory: traj.clone(),
        runs: o.runs,
        seed: o.seed,
    };
    let mut sec = Section {
        case,
        sensors: set,
        runs: o.runs,
        rows: Vec::new(),
        skipped: Vec::new(),
        crb,
        track_end,
    };
    // Each run's water is drawn about the calibration's: the estimators
    // are told so (their K_D doubt), as an operator in such water would.
    let mc = cfg.scene.montecarlo;
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
        let us = time_per_frame(est.as_mut(), &timing);
        let mc = monte_carlo(&cfg, build, progress(o.runs as u64), case.name, name)?;
        sec.rows.push(Row {
            name: mc.estimator.clone(),
            us_per_frame: us,
            mc,
        });
    }
    Ok(sec)
}

/// Three significant-ish digits, `1.2e3` from 1000 up, ∞ for a bound with
/// no information, — for nothing.
pub fn num(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() && v >= 1e3 => format!("{v:.1e}"),
        Some(v) if v.is_finite() && v >= 10.0 => format!("{v:.1}"),
        Some(v) if v.is_finite() => format!("{v:.3}"),
        Some(v) if v.is_infinite() => "∞".into(),
        _ => "—".into(),
    }
}

fn track_of(b: &TrackBound, a: Axis) -> Option<f64> {
    match a {
        Axis::X => Some(b.x),
        Axis::Y => Some(b.y),
        Axis::Z => Some(b.z),
        Axis::Pitch => Some(b.pitch_deg),
        Axis::Yaw => Some(b.yaw_deg),
        Axis::Surge => Some(b.surge),
        // The single-beacon track bound has no roll (one beacon cannot see it).
        Axis::Roll => None,
    }
}

fn crb_of(b: &CrbBound, a: Axis) -> Option<f64> {
    match a {
        Axis::X => Some(b.x),
        Axis::Y => Some(b.y),
        Axis::Z => Some(b.z),
        Axis::Pitch => Some(b.pitch_deg),
        Axis::Yaw => Some(b.yaw_deg),
        Axis::Surge => None,
        Axis::Roll => Some(b.roll_deg),
    }
}

/// The paper's published 95 % half-widths of `a`, "start → end" (— for
/// a case the paper did not run).
fn paper_cell(case: Option<PaperCase>, a: Axis) -> String {
    let Some(case) = case.filter(|_| !matches!(a, Axis::Surge | Axis::Roll)) else {
        return "—".into();
    };
    let fig = case.figures();
    let i = a.index();
    let f = |x: Option<Figure>| x.map_or("—".to_string(), |f| format!("±{f}"));
    format!("{} → {}", f(fig.ci_start[i]), f(fig.ci_end[i]))
}

/// What the CRB column is computed with when the set has a DVL: the set's
/// other sensors, named (the DVL measures velocity, which one frame's bound
/// has no place for). Empty without a DVL: the set is the heading's.
fn crb_sensors_note(set: SensorSet) -> String {
    if !set.dvl {
        return String::new();
    }
    let rest: Vec<&str> = [(set.attitude, "attitude"), (set.depth, "depth")]
        .into_iter()
        .filter_map(|(on, n)| on.then_some(n))
        .collect();
    let with = if rest.is_empty() {
        "no own sensor".to_string()
    } else {
        rest.join(" and ")
    };
    format!(" (with {with}: the DVL adds nothing to one frame)")
}

/// The Markdown table of one section.
pub fn table(sec: &Section) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "\n### {} — {} ({} runs)\n",
        sec.case.name,
        sec.sensors.label(),
        sec.runs
    );
    let _ = writeln!(
        o,
        "| estimator | µs/frame | axis | final nominal error | 95% start | 95% end | paper 95% start → end | ±2σ coverage | CRB 95% start | CRB 95% end | tracker bound 95% end |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &sec.rows {
        for a in r.mc.axes() {
            let h = headline(&r.mc, a);
            let cov = r.mc.coverage[a.index()].map(|c| format!("{:.1}%", 100.0 * c.fraction()));
            let c0 = sec.crb.first().and_then(|b| crb_of(b, a)).map(|s| Z95 * s);
            let c1 = sec.crb.last().and_then(|b| crb_of(b, a)).map(|s| Z95 * s);
            let tb = sec.track_end.and_then(|b| track_of(&b, a)).map(|s| Z95 * s);
            let _ = writeln!(
                o,
                "| {} | {} | {} ({}) | {} | {} | {} | {} | {} | {} | {} | {} |",
                r.name,
                num(Some(r.us_per_frame)),
                a.name(),
                a.unit(),
                num(h.map(|h| h.0)),
                num(h.map(|h| h.1)),
                num(h.map(|h| h.2)),
                paper_cell(sec.case.paper, a),
                cov.unwrap_or_else(|| "—".into()),
                num(c0),
                num(c1),
                num(tb),
            );
        }
    }
    let _ = writeln!(
        o,
        "\nCRB: one frame's bound{}. Tracker bound: the posterior bound along the whole track for an estimator that believes the tracker's motion model (a smoother vehicle can be tracked better).",
        crb_sensors_note(sec.sensors)
    );
    for s in &sec.skipped {
        let _ = writeln!(o, "\n{s}");
    }
    o
}

/// The summary table of a whole run: per section and estimator, time per
/// frame, the end 95 % half-width and the ±2σ coverage of every axis —
/// the rows docs/estimators.md quotes.
pub fn summary(sections: &[Section]) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "\n### Summary: end 95 % half-width (±2σ coverage)\n");
    let mut head = "| case | sensors | estimator | µs/frame |".to_string();
    let mut rule = "|---|---|---|---|".to_string();
    // Roll only when some row gave it (a station's).
    let axes: Vec<Axis> = AXES
        .into_iter()
        .filter(|&a| {
            a != Axis::Roll
                || sections
                    .iter()
                    .flat_map(|s| &s.rows)
                    .any(|r| r.mc.axes().contains(&Axis::Roll))
        })
        .collect();
    for &a in &axes {
        let _ = write!(head, " {} ({}) |", a.name(), a.unit());
        rule.push_str("---|");
    }
    let _ = writeln!(o, "{head}\n{rule}");
    for sec in sections {
        for r in &sec.rows {
            let _ = write!(
                o,
                "| {} | {} | {} | {} |",
                sec.case.name,
                sec.sensors.name(),
                r.name,
                num(Some(r.us_per_frame))
            );
            for &a in &axes {
                let h = headline(&r.mc, a).map(|h| h.2);
                let c = r.mc.coverage[a.index()].map_or("—".to_string(), |c| {
                    format!("{:.1}%", 100.0 * c.fraction())
                });
                let _ = write!(o, " {} ({c}) |", num(h));
            }
            let _ = writeln!(o);
        }
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_print_as_the_tables_want() {
        assert_eq!(num(Some(0.12345)), "0.123");
        assert_eq!(num(Some(12.345)), "12.3");
        assert_eq!(num(Some(1234.0)), "1.2e3");
        assert_eq!(num(Some(f64::INFINITY)), "∞");
        assert_eq!(num(None), "—");
        assert_eq!(num(Some(f64::NAN)), "—");
        assert!(Case::named("dive-tank").is_some() && Case::named("spiral").is_none());
    }

    /// A case's missing file is said once in a report of the chain: the
    /// cause is in the message and not chained as well.
    #[test]
    fn a_missing_case_file_is_said_once() {
        let dir = tempfile::tempdir().expect("tempdir");
        let Err(e) = load(dir.path(), &CASES[0]) else {
            panic!("loaded from an empty directory")
        };
        let line = e.to_string();
        assert!(line.starts_with("case dive-tank: "), "{line}");
        assert_eq!(line.matches("tank.toml").count(), 1, "{line}");
        assert!(std::error::Error::source(&e).is_none(), "{e:?}");
    }

    #[test]
    fn the_crb_note_names_the_sensors_of_the_set() {
        let note = |s: &str| crb_sensors_note(SensorSet::parse(s).expect("a set"));
        assert_eq!(
            note("all"),
            " (with attitude and depth: the DVL adds nothing to one frame)"
        );
        assert_eq!(
            note("attitude+dvl"),
            " (with attitude: the DVL adds nothing to one frame)"
        );
        assert_eq!(
            note("depth+dvl"),
            " (with depth: the DVL adds nothing to one frame)"
        );
        assert_eq!(
            note("dvl"),
            " (with no own sensor: the DVL adds nothing to one frame)"
        );
        assert_eq!(note("attitude+depth"), "");
    }

    #[test]
    fn cases_take_montecarlos_spelling_too() {
        for c in &CASES {
            let paper = c.paper.expect("a paper case");
            assert_eq!(c.name, paper.scene_name());
            let by_paper = Case::named(paper.as_str()).map(|k| k.name);
            assert_eq!(by_paper, Some(c.name));
        }
        for c in &crate::sea::SEA_CASES {
            assert!(c.paper.is_none());
            assert_eq!(Case::named(c.name).map(|k| k.name), Some(c.name));
        }
        assert_eq!(
            Case::named("zigzag-turbid").map(|c| c.name),
            Some("zigzag-harbour")
        );
    }
}
