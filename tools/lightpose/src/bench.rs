//! `lightpose bench`: the speed-for-accuracy trade table. Every estimator
//! runs on the paper's three Monte Carlo cases (dive and zigzag in the tank,
//! zigzag in harbour water), each with and without the attitude sensor,
//! through the analysis crate's engine; beside each axis stand the paper's
//! published half-widths and the Cramér–Rao bound at the start and end
//! poses, so that "better" is measured against both what was published and
//! what the photodiodes allow.
//!
//! Time per frame is measured apart from the Monte Carlo, on one thread over
//! pre-simulated frames: the engine runs realizations in parallel with the
//! simulator inside the loop, so its wall time says nothing about one
//! estimator's cost.

use crate::cells::{num, Z95};
use anyhow::Context;
use lightpose_analysis::bound::crb_scene;
use lightpose_analysis::montecarlo::{self, Axis, McConfig, McResult, AXES};
use lightpose_analysis::report::headline;
use lightpose_analysis::PaperCase;
use lightpose_core::{Estimator, Frame};
use lightpose_pipeline::model::crb::{crb_along, CrbBound};
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{AttitudeNoise, Scene, Simulator, Trajectory};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Monte Carlo realizations per case (the paper used 2000).
    #[arg(long, default_value_t = 200)]
    runs: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Cases: all, or any of dive-tank, zigzag-tank, zigzag-harbour.
    #[arg(long = "case", default_value = "all")]
    cases: Vec<String>,
    /// Estimators, comma separated.
    #[arg(long, default_value = "moments,model,tracker", value_delimiter = ',')]
    estimators: Vec<String>,
    /// With the attitude sensor: both, on or off.
    #[arg(long, default_value = "both", value_parser = ["both", "on", "off"])]
    attitude: String,
    /// Realizations the time per frame is measured over (median).
    #[arg(long, default_value_t = 15)]
    timing_runs: usize,
    /// Repository root the config/ paths are read from.
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Also write the table (Markdown) here.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// One of the paper's cases and its files under config/.
struct Case {
    name: &'static str,
    paper: PaperCase,
    scene: &'static str,
    trajectory: &'static str,
    calibration: &'static str,
}

const CASES: [Case; 3] = [
    Case {
        name: "dive-tank",
        paper: PaperCase::DiveClear,
        scene: "config/scenes/tank.toml",
        trajectory: "config/trajectories/dive.csv",
        calibration: "config/calibration/tank.toml",
    },
    Case {
        name: "zigzag-tank",
        paper: PaperCase::ZigzagClear,
        scene: "config/scenes/tank.toml",
        trajectory: "config/trajectories/zigzag.csv",
        calibration: "config/calibration/tank.toml",
    },
    Case {
        name: "zigzag-harbour",
        paper: PaperCase::ZigzagTurbid,
        scene: "config/scenes/harbour.toml",
        trajectory: "config/trajectories/zigzag.csv",
        calibration: "config/calibration/harbour.toml",
    },
];

/// Median wall time per frame of `est` over `runs` simulated realizations
/// of the nominal scene, microseconds. Each realization is replayed until
/// at least 2 ms have passed, so the clock's resolution does not matter.
fn time_per_frame(est: &mut dyn Estimator, frames: &[Vec<Frame>]) -> f64 {
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

fn simulate_runs(scene: &Scene, traj: &Trajectory, runs: usize, seed: u64) -> Vec<Vec<Frame>> {
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    (0..runs)
        .map(|i| {
            let mut sim = Simulator::new(scene.clone(), seed.wrapping_add(1000 + i as u64));
            times
                .iter()
                .enumerate()
                .map(|(j, &t)| {
                    let (p, s) = traj.sample(t);
                    sim.frame(j as u64, t, &p, Some(s))
                })
                .collect()
        })
        .collect()
}

fn crb_of(b: &CrbBound, a: Axis) -> Option<f64> {
    match a {
        Axis::X => Some(b.x),
        Axis::Y => Some(b.y),
        Axis::Z => Some(b.z),
        Axis::Pitch => Some(b.pitch_deg),
        Axis::Yaw => Some(b.yaw_deg),
        Axis::Surge => None,
    }
}

/// One estimator's row set of a case.
struct Row {
    name: String,
    us_per_frame: f64,
    mc: McResult,
}

/// The Markdown table of one case with or without the attitude sensor.
fn table(
    case: &Case,
    ahrs: bool,
    rows: &[Row],
    skipped: &[String],
    crb: &[CrbBound],
    runs: usize,
) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "\n### {} — {} attitude sensor ({} runs)\n",
        case.name,
        if ahrs { "with" } else { "without" },
        runs
    );
    let _ = writeln!(
        o,
        "| estimator | µs/frame | axis | final nominal error | 95% start | 95% end | paper 95% start → end | ±2σ coverage | CRB 95% start | CRB 95% end |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|---|---|");
    let fig = case.paper.figures();
    for r in rows {
        for a in AXES {
            let h = headline(&r.mc, a);
            let cov = r.mc.coverage[a.index()].map(|c| format!("{:.1}%", 100.0 * c.fraction()));
            let paper = if a.index() < 5 {
                let i = a.index();
                let f = |x: Option<lightpose_analysis::paper::Figure>| {
                    x.map_or("—".to_string(), |f| format!("±{f}"))
                };
                format!("{} → {}", f(fig.ci_start[i]), f(fig.ci_end[i]))
            } else {
                "—".into()
            };
            let c0 = crb.first().and_then(|b| crb_of(b, a)).map(|s| Z95 * s);
            let c1 = crb.last().and_then(|b| crb_of(b, a)).map(|s| Z95 * s);
            let _ = writeln!(
                o,
                "| {} | {} | {} ({}) | {} | {} | {} | {} | {} | {} | {} |",
                r.name,
                num(Some(r.us_per_frame)),
                a.name(),
                a.unit(),
                num(h.map(|h| h.0)),
                num(h.map(|h| h.1)),
                num(h.map(|h| h.2)),
                paper,
                cov.unwrap_or_else(|| "—".into()),
                num(c0),
                num(c1),
            );
        }
    }
    for s in skipped {
        let _ = writeln!(o, "\n{s}");
    }
    o
}

fn load_case(root: &Path, c: &Case) -> anyhow::Result<(Scene, Trajectory, Calibration)> {
    let scene = Scene::load(&root.join(c.scene))?;
    let traj = Trajectory::load(&root.join(c.trajectory))?;
    let cal = Calibration::load(&root.join(c.calibration))?;
    Ok((scene, traj, cal))
}

pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    let all = a.cases.iter().any(|c| c == "all");
    for c in &a.cases {
        if c != "all" && !CASES.iter().any(|k| k.name == c) {
            anyhow::bail!(
                "unknown case \"{c}\" (known: all, dive-tank, zigzag-tank, zigzag-harbour)"
            );
        }
    }
    let modes: &[bool] = match a.attitude.as_str() {
        "on" => &[true],
        "off" => &[false],
        _ => &[false, true],
    };
    let mut text = String::new();
    for case in CASES
        .iter()
        .filter(|k| all || a.cases.iter().any(|c| c == k.name))
    {
        let (base, traj, cal) =
            load_case(&a.root, case).with_context(|| format!("case {}", case.name))?;
        for &ahrs in modes {
            let mut scene = base.clone();
            // MODEL.md's attitude sensor (1σ pitch 0.3°, yaw 1.5°).
            scene.attitude = ahrs.then(AttitudeNoise::default);
            // The bound at the ends of the trajectory, with the engine's
            // K_D and temperature spreads and the sensor when present.
            let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
            let ends: Vec<_> = [times.first(), times.last()]
                .into_iter()
                .flatten()
                .map(|&t| traj.sample(t).0)
                .collect();
            let crb_scene = crb_scene(&scene);
            let crb = crb_along(&crb_scene, &ends);
            let timing = simulate_runs(&scene, &traj, a.timing_runs.max(1), a.seed);
            let cfg = McConfig {
                scene: scene.clone(),
                trajectory: traj.clone(),
                runs: a.runs,
                seed: a.seed,
            };
            let mut rows = Vec::new();
            let mut skipped = Vec::new();
            for name in &a.estimators {
                let mut est = match build_estimator(name, &cal) {
                    Ok(e) => e,
                    Err(e @ lightpose_pipeline::BuildError::NoPhysical { .. }) => {
                        skipped.push(format!("{}: skipped: {e}", case.calibration));
                        continue;
                    }
                    Err(e) => return Err(e.into()),
                };
                let us = time_per_frame(est.as_mut(), &timing);
                let bar = montecarlo::progress_bar(a.runs as u64);
                let mc = montecarlo::run(&cfg, || build_estimator(name, &cal), &bar);
                bar.finish_and_clear();
                let mc = mc.with_context(|| format!("case {} estimator {name}", case.name))?;
                eprintln!(
                    "bench: {} {} attitude sensor, {}: {} runs in {:.1} s, {:.2} µs/frame",
                    case.name,
                    if ahrs { "with" } else { "without" },
                    mc.estimator,
                    mc.runs,
                    mc.elapsed.as_secs_f64(),
                    us
                );
                rows.push(Row {
                    name: mc.estimator.clone(),
                    us_per_frame: us,
                    mc,
                });
            }
            text.push_str(&table(case, ahrs, &rows, &skipped, &crb, a.runs));
        }
    }
    print!("{text}");
    if let Some(p) = &a.out {
        std::fs::write(p, &text).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}
