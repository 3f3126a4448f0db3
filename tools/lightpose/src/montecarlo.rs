//! `lightpose montecarlo`: the paper's Monte Carlo uncertainty (TPU) of an
//! estimator along a trajectory. Thin: the engine, tables and plots are
//! `lightpose_analysis`; this loads the inputs, names the paper's case,
//! writes the results and prints the speed.

use crate::guard;
use crate::stdout::outln;
use anyhow::Context;
use lightpose_analysis::montecarlo::{self, progress_bar, McConfig};
use lightpose_analysis::report::{self, RunInfo};
use lightpose_analysis::sensors;
use lightpose_analysis::PaperCase;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Trajectory};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct MontecarloArgs {
    /// Scene file (TOML): its temperature and K_D are the nominal values,
    /// its [montecarlo] table the spreads drawn around them.
    #[arg(long)]
    scene: PathBuf,
    /// Trajectory knots (CSV: t,x,y,z,pitch,yaw).
    #[arg(long)]
    trajectory: PathBuf,
    /// Calibration of the same scene (TOML).
    #[arg(long)]
    calibration: PathBuf,
    /// Realizations (the paper used 2000; at most 1000000, and at most
    /// 50000000 realizations × frames: each one's results are kept in
    /// memory).
    #[arg(long, default_value_t = 2000)]
    runs: usize,
    /// Estimator, any name the pipeline knows (the paper's is "moments").
    #[arg(long, default_value = "moments")]
    estimator: String,
    /// Seed of the realizations (each run's water, temperature and noise).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Directory for steps.csv, summary.md and the plots.
    #[arg(long, default_value = "montecarlo")]
    out: PathBuf,
    /// Paper case to compare with: auto (from the trajectory's name and the
    /// scene's K_D), none, dive-clear, zigzag-clear or zigzag-turbid
    /// (aliases: dive-tank, zigzag-tank, zigzag-harbour, as `bench --case`
    /// names them).
    #[arg(long, default_value = "auto")]
    case: String,
    /// The vehicle's own sensors: as the scene says, or none, attitude,
    /// depth, attitude+depth, all (a sensor the scene lacks gets MODEL.md's
    /// noise).
    #[arg(long, default_value = "scene")]
    sensors: String,
}

pub fn run(a: MontecarloArgs) -> anyhow::Result<()> {
    guard::at_most("runs", a.runs, guard::MAX_RUNS, guard::RUNS_WHY)?;
    let mut scene = Scene::load(&a.scene)?;
    sensors::apply_choice(&a.sensors, &mut scene)
        .with_context(|| format!("--sensors {}: {}", a.sensors, sensors::CHOICES))?;
    let trajectory = Trajectory::load(&a.trajectory)?;
    let frames = trajectory.frame_count(scene.adc.rate_hz);
    guard::run_frames(a.trajectory.display(), a.runs, frames)?;
    // Each run's water is drawn about the calibration's: the estimator is
    // told so (its K_D doubt, unless the calibration's settings say).
    let cal = Calibration::load(&a.calibration)?
        .in_water_known_to(scene.montecarlo.sigma_k_d, scene.montecarlo.sigma_temp_c);
    let case = match a.case.as_str() {
        "auto" => PaperCase::detect(&a.trajectory, scene.light.k_d),
        other => PaperCase::parse(other)?,
    };
    // Check the name before any thread starts, for a clean one-line error.
    build_estimator(&a.estimator, &cal)?;
    // The writer's own step, before the runs: an --out that cannot be a
    // directory fails now, not after every realization.
    report::create_dir(&a.out).context("writing results")?;
    let cfg = McConfig {
        scene,
        trajectory,
        runs: a.runs,
        seed: a.seed,
    };
    let bar = progress_bar(a.runs as u64);
    let result = montecarlo::run(&cfg, || build_estimator(&a.estimator, &cal), &bar);
    bar.finish_and_clear();
    let result = result?;
    let info = RunInfo {
        scene: a.scene.display().to_string(),
        trajectory: a.trajectory.display().to_string(),
        calibration: a.calibration.display().to_string(),
        case,
    };
    // The error names the file.
    report::write_all(&result, &info, &a.out).context("writing results")?;
    outln!(
        "montecarlo: {} realizations x {} frames ({}) in {:.2} s: {:.0} realizations/s on {} threads",
        result.runs,
        result.times.len(),
        result.estimator,
        result.elapsed.as_secs_f64(),
        result.rate(),
        result.threads
    );
    outln!(
        "case: {}; wrote {}/{{{},{},{}.png,{}.svg}}",
        case.map_or("none (no paper comparison)", |c| c.as_str()),
        a.out.display(),
        report::CSV_NAME,
        report::SUMMARY_NAME,
        report::PLOT_STEM,
        report::PLOT_STEM
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root(p: &str) -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join(p)
    }

    fn args(out: &std::path::Path) -> MontecarloArgs {
        MontecarloArgs {
            scene: root("config/scenes/tank.toml"),
            trajectory: root("config/trajectories/dive.csv"),
            calibration: root("config/calibration/tank.toml"),
            runs: 8,
            estimator: "moments".into(),
            seed: 3,
            out: out.to_path_buf(),
            case: "auto".into(),
            sensors: "scene".into(),
        }
    }

    type Edit = dyn Fn(&mut MontecarloArgs);

    /// Each bad argument gives one line that names what is wrong.
    #[test]
    fn bad_arguments_give_one_clear_line() {
        let dir = tempfile::tempdir().unwrap();
        let cases: Vec<(Box<Edit>, &str)> = vec![
            (
                Box::new(|a| a.estimator = "kalman".into()),
                "unknown estimator \"kalman\"",
            ),
            (Box::new(|a| a.runs = 0), "runs must be at least 1"),
            (
                Box::new(|a| a.case = "spiral".into()),
                "unknown case \"spiral\"",
            ),
            (
                Box::new(|a| a.scene = root("config/scenes/nope.toml")),
                "nope.toml",
            ),
            (
                Box::new(|a| a.trajectory = root("config/trajectories/nope.csv")),
                "nope.csv",
            ),
            (Box::new(|a| a.sensors = "sonar".into()), "--sensors sonar"),
        ];
        for (edit, want) in cases {
            let mut a = args(dir.path());
            edit(&mut a);
            let e = format!("{:#}", run(a).unwrap_err());
            assert!(e.contains(want), "{e:?} lacks {want:?}");
            assert!(!e.contains('\n'), "{e:?} is not one line");
        }
    }

    /// Audit: an --out that is a file failed only after every realization
    /// had run; now at once, before any.
    #[test]
    fn an_out_that_cannot_be_a_directory_fails_before_the_runs() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("taken");
        std::fs::write(&file, "x").unwrap();
        let mut a = args(&file);
        // Enough realizations that running them first would show.
        a.runs = 1_000_000;
        let t0 = std::time::Instant::now();
        let e = format!("{:#}", run(a).unwrap_err());
        assert!(e.starts_with("writing results: "), "{e}");
        assert!(e.contains(&file.display().to_string()), "{e}");
        assert!(t0.elapsed() < std::time::Duration::from_secs(20), "{e}");
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "x");
    }

    #[test]
    fn a_small_run_writes_its_results() {
        let dir = tempfile::tempdir().unwrap();
        run(args(dir.path())).unwrap();
        for f in [
            "steps.csv",
            "summary.md",
            "montecarlo.png",
            "montecarlo.svg",
        ] {
            let len = std::fs::metadata(dir.path().join(f)).unwrap().len();
            assert!(len > 100, "{f} is {len} bytes");
        }
        let summary = std::fs::read_to_string(dir.path().join("summary.md")).unwrap();
        assert!(summary.contains("Case I: dive"), "{summary}");
    }

    /// `bench`'s name of a case is taken as well.
    #[test]
    fn the_case_takes_benchs_spelling() {
        let dir = tempfile::tempdir().unwrap();
        let mut a = args(dir.path());
        a.case = "zigzag-harbour".into();
        run(a).unwrap();
        let summary = std::fs::read_to_string(dir.path().join("summary.md")).unwrap();
        assert!(summary.contains("turbid water"), "{summary}");
    }
}
