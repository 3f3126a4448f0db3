//! `lightpose bench`: the speed-for-accuracy trade table — every estimator
//! on the paper's three Monte Carlo cases, with each set of the vehicle's
//! own sensors, and on the open sea (spec v3: a harbour approach with the
//! beacon blinking or steady, at night or by day). Thin: the tables are
//! `lightpose_analysis::trade` and `lightpose_analysis::sea`.

use crate::guard;
use crate::stdout::out;
use anyhow::Context;
use lightpose_analysis::dock;
use lightpose_analysis::montecarlo::progress_bar;
use lightpose_analysis::sea::{self, SEA_CASES};
use lightpose_analysis::sensors::SensorSet;
use lightpose_analysis::trade::{self, Case, TradeOptions, CASES};
use std::path::PathBuf;

/// Most timing realizations: each one's frames are held in memory.
const MAX_TIMING_RUNS: usize = 1000;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Monte Carlo realizations per case and sensor set (the paper used
    /// 2000; at most 1000000: each one's results are kept in memory).
    #[arg(long, default_value_t = 200)]
    runs: usize,
    /// Seed of the realizations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Cases, comma separated (or the flag repeated): paper (the paper's
    /// three: dive-tank, zigzag-tank, zigzag-harbour, aliases dive-clear,
    /// zigzag-clear, zigzag-turbid as `montecarlo --case` names them), sea
    /// (the open sea's four: approach-blinking-night, approach-blinking-day,
    /// approach-steady-night, approach-steady-day), all (both), or any of
    /// those names; dock-approach (a docking station of four beacons,
    /// judged on all six axes over x 5 → 1.5 m). The open sea runs with
    /// its scenes' own sensors (an AHRS with roll): --sensors does not
    /// apply to it.
    #[arg(long = "case", default_value = "paper", value_delimiter = ',')]
    cases: Vec<String>,
    /// Estimators, comma separated.
    #[arg(long, default_value = "moments,model,tracker", value_delimiter = ',')]
    estimators: Vec<String>,
    /// The vehicle's own sensors, comma separated: none, attitude, depth,
    /// attitude+depth, all (attitude + depth + DVL), or any `+` of
    /// attitude, depth, dvl.
    #[arg(
        long,
        default_value = "none,attitude,depth,attitude+depth,all",
        value_delimiter = ','
    )]
    sensors: Vec<String>,
    /// Realizations the time per frame is measured over (median; 1 to
    /// 1000: their frames are simulated up front).
    #[arg(long, default_value_t = 15)]
    timing_runs: usize,
    /// Repository root the config/ paths are read from.
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Also write the tables (Markdown) here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the open sea's plots (PNG: p95 per estimator, blinking or
    /// steady, night or day) into this directory, and a docking station's
    /// approach (SVG: track from above and the side, ±2σ, beacons seen).
    #[arg(long)]
    plot: Option<PathBuf>,
}

const KNOWN_CASES: &str = "known: paper, sea, all, dive-tank, zigzag-tank, zigzag-harbour, their aliases dive-clear, zigzag-clear, zigzag-turbid, approach-blinking-night, approach-blinking-day, approach-steady-night, approach-steady-day, dock-approach";

/// The cases `words` name, in order (`paper`, `sea` and `all` stand for
/// their groups).
fn cases_named(words: &[String]) -> anyhow::Result<Vec<&'static Case>> {
    let mut cases: Vec<&'static Case> = Vec::new();
    for c in words {
        match c.as_str() {
            "paper" => cases.extend(CASES.iter()),
            "sea" => cases.extend(SEA_CASES.iter()),
            "all" => cases.extend(CASES.iter().chain(SEA_CASES.iter())),
            _ => cases.push(
                Case::named(c).with_context(|| format!("unknown case \"{c}\" ({KNOWN_CASES})"))?,
            ),
        }
    }
    Ok(cases)
}

/// `v` with each item's later repeats left out, in order.
fn once_each<T>(v: Vec<T>, same: impl Fn(&T, &T) -> bool) -> Vec<T> {
    let mut out: Vec<T> = Vec::with_capacity(v.len());
    for x in v {
        if !out.iter().any(|y| same(y, &x)) {
            out.push(x);
        }
    }
    out
}

/// The arguments checked: the cases, sensor sets and options to run, each
/// once; the output file and plot folder known writable before the runs.
fn checked(a: &BenchArgs) -> anyhow::Result<(Vec<&'static Case>, Vec<SensorSet>, TradeOptions)> {
    guard::at_most("runs", a.runs, guard::MAX_RUNS, guard::RUNS_WHY)?;
    guard::at_least_one(
        "timing-runs",
        a.timing_runs,
        "the realizations the time per frame is measured over",
    )?;
    guard::at_most(
        "timing-runs",
        a.timing_runs,
        MAX_TIMING_RUNS,
        "their frames are simulated up front",
    )?;
    let cases = cases_named(&a.cases)?;
    let sets = a
        .sensors
        .iter()
        .map(|s| {
            SensorSet::parse(s).with_context(|| {
                format!("--sensors {s}: none, attitude, depth, attitude+depth, all, or a + of attitude, depth, dvl")
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    // A case, set or estimator named twice (an alias beside its name,
    // `all` beside `attitude+depth+dvl`) is run once.
    let (cases, sets, estimators) = (
        once_each(cases, |a, b| std::ptr::eq(*a, *b)),
        once_each(sets, |a, b| a == b),
        once_each(a.estimators.clone(), |a, b| a == b),
    );
    // Where the tables go is checked before the runs, not after them.
    if let Some(p) = &a.out {
        guard::writable_file(p)?;
    }
    if let Some(d) = &a.plot {
        std::fs::create_dir_all(d)
            .with_context(|| format!("--plot {}: cannot create", d.display()))?;
    }
    let o = TradeOptions {
        runs: a.runs,
        seed: a.seed,
        timing_runs: a.timing_runs,
        estimators,
    };
    Ok((cases, sets, o))
}

pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    let (cases, sets, o) = checked(&a)?;
    let mut text = String::new();
    let mut sections = Vec::new();
    let mut seas = Vec::new();
    let mut docks = Vec::new();
    for case in cases {
        let loaded = trade::load(&a.root, case)?;
        let frames = loaded.trajectory.frame_count(loaded.scene.adc.rate_hz);
        guard::run_frames(format_args!("{}'s trajectory", case.name), a.runs, frames)?;
        if dock::is_dock(case) {
            let sec = dock::run_case(&loaded, &sets, &o, &progress_bar)?;
            for r in &sec.rows {
                let who = format!("{} {}, {}", case.name, r.sensors.label(), r.name);
                let (ok, n) = (r.judged.ok, r.judged.frames);
                tell(&who, &r.mc, r.us_per_frame, ok, n, "in the window");
            }
            if let Some(d) = &a.plot {
                let p = d.join(dock::PLOT_NAME);
                let n = dock::plot_approach(&loaded, a.seed, &p)?;
                eprintln!("bench: wrote {} ({n} frames)", p.display());
            }
            docks.push(sec);
            continue;
        }
        if case.paper.is_none() {
            let sec = sea::run_case(&loaded, &o, &progress_bar)?;
            for r in &sec.rows {
                let who = format!("{}, {}", case.name, r.name);
                let (ok, n) = (r.judged.ok, r.judged.frames);
                tell(&who, &r.mc, r.us_per_frame, ok, n, "after 1 s");
            }
            seas.push(sec);
            continue;
        }
        for &set in &sets {
            let sec = trade::run_section(&loaded, set, &o, &progress_bar)?;
            for r in &sec.rows {
                eprintln!(
                    "bench: {} {}, {}: {} runs in {:.1} s, {:.2} µs/frame",
                    case.name,
                    set.label(),
                    r.name,
                    r.mc.runs,
                    r.mc.elapsed.as_secs_f64(),
                    r.us_per_frame
                );
            }
            text.push_str(&trade::table(&sec));
            sections.push(sec);
        }
    }
    if !sections.is_empty() {
        text.push_str(&trade::summary(&sections));
    }
    if !seas.is_empty() {
        text.push_str(&sea::table(&seas));
    }
    for d in &docks {
        text.push_str(&dock::table(d));
    }
    if let (Some(d), false) = (&a.plot, seas.is_empty()) {
        let p = d.join(sea::PLOT_NAME);
        sea::plot_png(&seas, &p)?;
        eprintln!("bench: wrote {}", p.display());
    }
    // The file first: a reader of stdout that has gone ends the program.
    if let Some(p) = &a.out {
        std::fs::write(p, &text).with_context(|| format!("writing {}", p.display()))?;
    }
    out!("{text}");
    Ok(())
}

/// One row's progress line: runs, time, cost and `ok` frames `window`.
fn tell(
    who: &str,
    mc: &lightpose_analysis::montecarlo::McResult,
    us_per_frame: f64,
    ok: usize,
    frames: usize,
    window: &str,
) {
    eprintln!(
        "bench: {who}: {} runs in {:.1} s, {us_per_frame:.2} µs/frame, {ok} of {frames} ok {window}",
        mc.runs,
        mc.elapsed.as_secs_f64(),
    );
}
