//! The Monte Carlo's written results: a CSV with one row per time step
//! (truth, ensemble mean, percentiles, 95 % half-width per axis, and the
//! fraction of runs with status ok), and `summary.md` with the paper's
//! headline numbers (final nominal error, 95 % half-width at start and end)
//! beside the paper's own where the run is one of its cases. Both are
//! deterministic for a seed: no timing goes into them.

use crate::montecarlo::{Axis, McError, McResult};
use crate::paper::{factor, Figure, PaperCase};
use crate::stats::AxisStats;
use std::fmt::Write as _;
use std::path::Path;

/// Where a run came from, for the summary's header.
#[derive(Debug, Clone, Default)]
pub struct RunInfo {
    pub scene: String,
    pub trajectory: String,
    pub calibration: String,
    pub case: Option<PaperCase>,
}

/// Files written by [`write_all`].
pub const CSV_NAME: &str = "steps.csv";
pub const SUMMARY_NAME: &str = "summary.md";
pub const PLOT_STEM: &str = "montecarlo";

/// The CSV's columns, in order, for a result showing `axes`
/// ([`McResult::axes`]: roll only for a station).
pub fn csv_header(axes: &[Axis]) -> String {
    let mut h = String::from("t,ok_fraction");
    for &a in axes {
        for col in ["truth", "mean", "p025", "p975", "hw95", "std", "n"] {
            let _ = write!(h, ",{}_{col}", a.name());
        }
    }
    h
}

/// The per-step CSV as text. An axis that no run estimated at a step has
/// empty fields (never NaN).
pub fn csv_text(r: &McResult) -> String {
    let axes = r.axes();
    let mut out = csv_header(&axes);
    out.push('\n');
    for (s, truth) in r.steps.iter().zip(&r.truth) {
        let _ = write!(out, "{},{}", s.t, s.ok_fraction);
        for &a in &axes {
            let _ = write!(out, ",{}", truth[a.index()]);
            match &s.axes[a.index()] {
                Some(st) => {
                    let _ = write!(
                        out,
                        ",{},{},{},{},{},{}",
                        st.mean,
                        st.p025,
                        st.p975,
                        st.half_width(),
                        st.std,
                        st.n
                    );
                }
                None => out.push_str(",,,,,,0"),
            }
        }
        out.push('\n');
    }
    out
}

fn decimals(a: Axis) -> usize {
    match a {
        Axis::Pitch | Axis::Yaw | Axis::Roll => 2,
        _ => 3,
    }
}

/// The stats of `axis` at the first and the last step that have any.
fn ends(r: &McResult, a: Axis) -> Option<((usize, AxisStats), (usize, AxisStats))> {
    let at = |j: usize| r.steps[j].axes[a.index()].map(|st| (j, st));
    let idx = 0..r.steps.len();
    let first = idx.clone().find_map(at)?;
    let last = idx.rev().find_map(at)?;
    Some((first, last))
}

/// Final nominal error |mean − truth| at the last step, 95 % half-width at
/// the first and last step, per axis (`None` where no estimate).
pub fn headline(r: &McResult, a: Axis) -> Option<(f64, f64, f64)> {
    let ((_, s0), (jl, sl)) = ends(r, a)?;
    let err = (sl.mean - r.truth[jl][a.index()]).abs();
    Some((err, s0.half_width(), sl.half_width()))
}

fn fig(f: Option<Figure>) -> String {
    f.map_or_else(|| "—".to_string(), |f| format!("{f}"))
}

/// `summary.md` as text.
pub fn summary_text(r: &McResult, info: &RunInfo) -> String {
    let mut o = String::new();
    write_run_facts(&mut o, r, info);
    let far = write_headline_table(&mut o, r, info);
    if info.case.is_some() {
        write_far_from_paper(&mut o, &far);
    }
    write_coverage(&mut o, r);
    o
}

/// The title and what the run was: estimator, realizations, files, the
/// spreads drawn per run, and how often the status was ok.
fn write_run_facts(o: &mut String, r: &McResult, info: &RunInfo) {
    let title = info.case.map_or("Monte Carlo uncertainty", |c| c.title());
    let _ = writeln!(o, "# {title}\n");
    let (t0, t1) = (
        r.times.first().copied().unwrap_or(0.0),
        r.times.last().copied().unwrap_or(0.0),
    );
    let _ = writeln!(
        o,
        "- estimator `{}`, {} realizations, seed {}, {} frames per run (t = {t0} … {t1} s)",
        r.estimator,
        r.runs,
        r.seed,
        r.times.len()
    );
    let _ = writeln!(
        o,
        "- scene `{}`, trajectory `{}`, calibration `{}`",
        info.scene, info.trajectory, info.calibration
    );
    let n = r.draws.len().max(1) as f64;
    let mean_sd = |f: &dyn Fn(&crate::Draw) -> f64| {
        let m = r.draws.iter().map(f).sum::<f64>() / n;
        let v = r.draws.iter().map(|d| (f(d) - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        (m, v.sqrt())
    };
    let (tm, ts) = mean_sd(&|d| d.temp_c);
    let (km, ks) = mean_sd(&|d| d.k_d);
    let _ = writeln!(
        o,
        "- drawn per run: water temperature {tm:.2} ± {ts:.2} °C, K_D {km:.4} ± {ks:.4} 1/m (mean ± sd); frames report the nominal temperature"
    );
    let okf: Vec<f64> = r.steps.iter().map(|s| s.ok_fraction).collect();
    let ok_min = okf.iter().copied().fold(f64::INFINITY, f64::min);
    let ok_mean = okf.iter().sum::<f64>() / okf.len().max(1) as f64;
    let _ = writeln!(
        o,
        "- status ok: {:.1} % of estimates (worst step {:.1} %)\n",
        100.0 * ok_mean,
        100.0 * ok_min
    );
}

/// The headline table, per axis ours beside the paper's (where the run is
/// one of its cases); returns each figure more than a factor of two from
/// the paper's, as a line.
fn write_headline_table(o: &mut String, r: &McResult, info: &RunInfo) -> Vec<String> {
    let figs = info.case.map(|c| c.figures());
    let _ = writeln!(
        o,
        "Final nominal error = |ensemble mean − truth| at the last step; 95 % HW = half the distance between the 2.5 and 97.5 % percentiles of the ensemble.\n"
    );
    let _ = writeln!(
        o,
        "| axis | final nominal error | paper | 95 % HW start | paper | 95 % HW end | paper |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|");
    let mut far = Vec::new();
    for a in r.axes() {
        let d = decimals(a);
        let unit = a.unit();
        let pf = |sel: fn(&crate::paper::PaperFigures) -> [Option<Figure>; 5]| {
            figs.as_ref()
                .and_then(|f| sel(f).get(a.index()).copied().flatten())
        };
        let (pe, ps, pe2) = (pf(|f| f.final_error), pf(|f| f.ci_start), pf(|f| f.ci_end));
        match headline(r, a) {
            Some((err, hw0, hw1)) => {
                let _ = writeln!(
                    o,
                    "| {} ({unit}) | {err:.d$} | {} | ±{hw0:.d$} | {} | ±{hw1:.d$} | {} |",
                    a.name(),
                    fig(pe),
                    fig(ps),
                    fig(pe2),
                );
                for (what, ours, p) in [
                    ("final nominal error", err, pe),
                    ("95 % HW at start", hw0, ps),
                    ("95 % HW at end", hw1, pe2),
                ] {
                    if let Some(k) = factor(ours, p).filter(|k| *k > 2.0) {
                        far.push(format!(
                            "{} {what}: ours {ours:.d$} {unit}, paper {} {unit} ({k:.1}×)",
                            a.name(),
                            fig(p)
                        ));
                    }
                }
            }
            None => {
                let _ = writeln!(
                    o,
                    "| {} ({unit}) | no estimate | {} | — | {} | — | {} |",
                    a.name(),
                    fig(pe),
                    fig(ps),
                    fig(pe2)
                );
            }
        }
    }
    far
}

/// The figures more than a factor of two from the paper's, or "none".
fn write_far_from_paper(o: &mut String, far: &[String]) {
    let _ = writeln!(
        o,
        "\nDifferences from the paper larger than a factor of two:\n"
    );
    if far.is_empty() {
        let _ = writeln!(o, "- none");
    }
    for f in far {
        let _ = writeln!(o, "- {f}");
    }
}

/// How often the truth lies within ±2σ of the estimate, per axis.
fn write_coverage(o: &mut String, r: &McResult) {
    let _ = writeln!(o, "\n## Coverage of the estimator's own σ\n");
    if r.coverage.iter().all(Option::is_none) {
        let _ = writeln!(o, "The estimator reports no σ.");
        return;
    }
    let _ = writeln!(
        o,
        "Fraction of estimates (all runs, all steps) whose truth lies within ±2σ of the estimate; about 95 % is honest.\n"
    );
    let _ = writeln!(o, "| axis | estimates with σ | within ±2σ |");
    let _ = writeln!(o, "|---|---|---|");
    for a in r.axes() {
        match &r.coverage[a.index()] {
            Some(c) => {
                let _ = writeln!(
                    o,
                    "| {} | {} | {:.1} % |",
                    a.name(),
                    c.n,
                    100.0 * c.fraction()
                );
            }
            None => {
                let _ = writeln!(o, "| {} | 0 | — |", a.name());
            }
        }
    }
}

fn write_file(path: &Path, text: &str) -> Result<(), McError> {
    std::fs::write(path, text).map_err(|err| McError::Io {
        path: path.display().to_string(),
        err,
    })
}

/// The directory [`write_all`] writes into, created if missing; an error
/// if it cannot be (a file of that name). A caller makes it before a long
/// run, so that such an `--out` fails at once, not after every run.
pub fn create_dir(dir: &Path) -> Result<(), McError> {
    std::fs::create_dir_all(dir).map_err(|err| McError::Io {
        path: dir.display().to_string(),
        err,
    })
}

/// Write `steps.csv`, `summary.md`, `montecarlo.png` and `montecarlo.svg`
/// into `dir` (created if missing).
pub fn write_all(r: &McResult, info: &RunInfo, dir: &Path) -> Result<(), McError> {
    create_dir(dir)?;
    write_file(&dir.join(CSV_NAME), &csv_text(r))?;
    write_file(&dir.join(SUMMARY_NAME), &summary_text(r, info))?;
    let title = match info.case {
        Some(c) => format!("{} — {} runs, {}", c.title(), r.runs, r.estimator),
        None => format!("Monte Carlo, {} runs, {}", r.runs, r.estimator),
    };
    crate::plot::render_png(r, &title, &dir.join(format!("{PLOT_STEM}.png")))?;
    crate::plot::render_svg(r, &title, &dir.join(format!("{PLOT_STEM}.svg")))?;
    Ok(())
}
