//! Diagnostic: single simulated runs (as `lightpose simulate` writes them)
//! through estimators, p95 of |error| per axis over all frames and after
//! the first second, per seed, and the ratio of the first estimator to
//! the second — the "no worse than the paper's method" check of
//! docs/estimators.md.
//!
//!   cargo run --release -p lightpose-analysis --example fusion_diag -- \
//!       SCENE TRAJECTORY CALIBRATION SENSORS SEEDS [EST_A,EST_B]
//!
//! SENSORS: none, attitude, depth, attitude+depth, all (a table the scene
//! lacks gets MODEL.md's sensor). SEEDS: a count (1..=N) or a..b.
//! Environment: TRK = TOML of `[estimator.tracker]` settings to try;
//! MC = draw T and K_D per run as the Monte Carlo does (frames report T0);
//! QUIET = summary only; TRACE = one line per frame of the first seed;
//! COMMON = "after 1 s" only over frames where every estimator gave the
//! axis; TIME = the time per frame of each estimator on each run;
//! UNTOLD = with MC, leave the estimators unaware of the water's spread,
//! as the daemon is by default. A run whose estimator learned the water
//! (a bank, or the water check fired) says so on a line of its own.
// Axis loops index several per-axis arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_analysis::sensors::SensorSet;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Simulator, Trajectory};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn p95(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

type Errs = [Vec<f64>; 6];

/// Per frame and axis: |error| where the estimator gave the axis.
type FrameErrs = Vec<[Option<f64>; 6]>;

fn run_one(
    est: &mut dyn lightpose_core::Estimator,
    frames: &[lightpose_core::Frame],
    t0: f64,
    trace: bool,
) -> (Errs, Errs, FrameErrs) {
    let mut all: Errs = Default::default();
    let mut late: Errs = Default::default();
    let mut per: FrameErrs = Vec::new();
    est.reset();
    for f in frames {
        let e = est.estimate(f);
        let Some(tr) = f.truth else { continue };
        let truth = tr.pose.values_with_surge(tr.surge.unwrap_or(f64::NAN));
        if trace {
            let v = e.values();
            let s = e.std.values();
            let d: Vec<String> = (0..6)
                .map(|a| match (v[a], s[a]) {
                    (Some(v), Some(s)) => format!("{:+7.2}({:5.2})", v - truth[a], s),
                    (Some(v), None) => format!("{:+7.2}(  -  )", v - truth[a]),
                    _ => "      -       ".into(),
                })
                .collect();
            eprintln!(
                "{:5.1} {:12} {} {:?}",
                f.t,
                e.status.as_str(),
                d.join(" "),
                e.readings.all().map(|u| u.as_str())
            );
        }
        let mut row = [None; 6];
        for (a, v) in e.values().into_iter().enumerate() {
            if let Some(v) = v {
                let d = v - truth[a];
                if d.is_finite() {
                    all[a].push(d.abs());
                    if f.t >= t0 + 1.0 - 1e-9 {
                        late[a].push(d.abs());
                        row[a] = Some(d.abs());
                    }
                }
            }
        }
        per.push(row);
    }
    (all, late, per)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 6 {
        return Err("usage: fusion_diag SCENE TRAJECTORY CALIBRATION SENSORS SEEDS [A,B]".into());
    }
    let mut base = Scene::load(std::path::Path::new(&args[1]))?;
    let traj = Trajectory::load(std::path::Path::new(&args[2]))?;
    let mut cal = Calibration::load(std::path::Path::new(&args[3]))?;
    let set = SensorSet::parse(&args[4]).ok_or("unknown sensor set")?;
    set.apply(&mut base);
    let seeds: Vec<u64> = match args[5].split_once("..") {
        Some((a, b)) => (a.parse()?..=b.parse()?).collect(),
        None => (1..=args[5].parse()?).collect(),
    };
    let names: Vec<String> = args
        .get(6)
        .map_or("auto,moments", |s| s.as_str())
        .split(',')
        .map(String::from)
        .collect();
    if let Ok(t) = std::env::var("TRK") {
        let mut st = cal.estimator.clone().unwrap_or_default();
        st.tracker = toml::from_str(&t)?;
        cal.estimator = Some(st);
    }
    let quiet = std::env::var("QUIET").is_ok();
    let mc = std::env::var("MC").is_ok();
    if mc && std::env::var("UNTOLD").is_err() {
        cal = cal.in_water_known_to(base.montecarlo.sigma_k_d, base.montecarlo.sigma_temp_c);
    }
    let mut ests = names
        .iter()
        .map(|n| build_estimator(n, &cal))
        .collect::<Result<Vec<_>, _>>()?;
    let times: Vec<f64> = traj.frame_times(base.adc.rate_hz).collect();
    let t0 = times.first().copied().unwrap_or(0.0);
    let axes = ["x", "y", "z", "pitch", "yaw", "surge"];
    // Per estimator, per axis: p95 over runs (all frames, after 1 s).
    let mut summary: Vec<[Vec<(usize, f64)>; 2]> = vec![Default::default(); names.len()];
    let mut worst_ratio = [[f64::NEG_INFINITY; 6]; 2];
    let mut ratios: [[Vec<f64>; 6]; 2] = Default::default();
    for (si, &seed) in seeds.iter().enumerate() {
        let mut scene = base.clone();
        let mut sim = if mc {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let n1: f64 = StandardNormal.sample(&mut rng);
            let n2: f64 = StandardNormal.sample(&mut rng);
            scene.temp_c += scene.montecarlo.sigma_temp_c * n1;
            scene.light.k_d = (scene.light.k_d + scene.montecarlo.sigma_k_d * n2).max(0.0);
            let mut s = Simulator::new(scene, seed);
            s.set_reported_temp(Some(base.temp_c));
            s
        } else {
            Simulator::new(scene, seed)
        };
        let frames: Vec<_> = times
            .iter()
            .enumerate()
            .map(|(j, &t)| sim.frame_moving(j as u64, t, &traj.kinematics(t)))
            .collect();
        if std::env::var("TIME").is_ok() {
            for (ei, est) in ests.iter_mut().enumerate() {
                let us = lightpose_analysis::trade::time_per_frame(
                    est.as_mut(),
                    std::slice::from_ref(&frames),
                );
                println!("seed {seed:3} {:8} {us:.1} µs/frame", names[ei]);
            }
        }
        let mut p = Vec::new();
        let mut pers = Vec::new();
        for (ei, est) in ests.iter_mut().enumerate() {
            let trace = si == 0 && std::env::var("TRACE").is_ok();
            if trace {
                eprintln!("--- {} seed {seed}", names[ei]);
            }
            let (mut all, mut late, per) = run_one(est.as_mut(), &frames, t0, trace);
            if let Some(k) = est.water_k_d() {
                println!("seed {seed:3} {:8} water K_D {k:.4} learned", names[ei]);
            }
            let pa: Vec<f64> = all.iter_mut().map(|v| p95(v)).collect();
            let pl: Vec<f64> = late.iter_mut().map(|v| p95(v)).collect();
            p.push((pa, pl));
            pers.push(per);
        }
        // After 1 s, on the frames where every estimator gave the axis:
        // the like-for-like comparison (the paper's method gives surge
        // only once its window is full).
        if std::env::var("COMMON").is_ok() {
            for (ei, pe) in p.iter_mut().enumerate() {
                for a in 0..6 {
                    let mut v: Vec<f64> = (0..pers[ei].len())
                        .filter(|&j| pers.iter().all(|q| q[j][a].is_some()))
                        .filter_map(|j| pers[ei][j][a])
                        .collect();
                    pe.1[a] = p95(&mut v);
                }
            }
        }
        if !quiet {
            for (ei, (pa, pl)) in p.iter().enumerate() {
                let f = |v: &Vec<f64>| {
                    v.iter()
                        .map(|x| format!("{x:6.3}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                };
                println!(
                    "seed {seed:3} {:8} all {}  late {}",
                    names[ei],
                    f(pa),
                    f(pl)
                );
            }
        }
        for (ei, (pa, pl)) in p.iter().enumerate() {
            for a in 0..6 {
                summary[ei][0].push((a, pa[a]));
                summary[ei][1].push((a, pl[a]));
            }
        }
        if p.len() >= 2 {
            for w in 0..2 {
                let (a0, b0) = if w == 0 {
                    (&p[0].0, &p[1].0)
                } else {
                    (&p[0].1, &p[1].1)
                };
                for a in 0..6 {
                    let r = a0[a] / b0[a];
                    if r.is_finite() {
                        worst_ratio[w][a] = worst_ratio[w][a].max(r);
                        ratios[w][a].push(r);
                    }
                }
            }
        }
    }
    for (ei, n) in names.iter().enumerate() {
        for (w, label) in ["all", "after 1 s"].iter().enumerate() {
            let mut line = format!("{n:8} {label:9} median p95:");
            for a in 0..6 {
                let mut v: Vec<f64> = summary[ei][w]
                    .iter()
                    .filter(|(i, _)| *i == a)
                    .map(|(_, v)| *v)
                    .filter(|v| v.is_finite())
                    .collect();
                v.sort_by(f64::total_cmp);
                let med = v.get(v.len() / 2).copied().unwrap_or(f64::NAN);
                line += &format!(" {} {:.3}", axes[a], med);
            }
            println!("{line}");
        }
    }
    if names.len() >= 2 {
        for (w, label) in ["all", "after 1 s"].iter().enumerate() {
            let mut line = format!("ratio {}/{} {label:9}:", names[0], names[1]);
            for a in 0..6 {
                let mut v = ratios[w][a].clone();
                v.sort_by(f64::total_cmp);
                let med = v.get(v.len() / 2).copied().unwrap_or(f64::NAN);
                // The bar of docs/estimators.md: x, surge within 1.1×, y, z ≤ 1×.
                let bar = [1.1, 1.0, 1.0, f64::INFINITY, f64::INFINITY, 1.1][a];
                let ok = v.iter().filter(|r| **r <= bar).count();
                line += &format!(
                    " {} med {:.2} max {:.2} ({ok}/{} within);",
                    axes[a],
                    med,
                    worst_ratio[w][a],
                    v.len()
                );
            }
            println!("{line}");
        }
    }
    Ok(())
}
