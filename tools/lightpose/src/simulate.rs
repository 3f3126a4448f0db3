//! `lightpose simulate` and `lightpose sweep`: write intensity logs from the
//! simulator, deterministic for a given seed.

use crate::guard;
use anyhow::Context;
use lightpose_core::{Burst, LogWriter};
use lightpose_sim::{Scene, Simulator, SweepKind, SweepPlan, Trajectory};
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct SimulateArgs {
    /// Scene file (TOML, see scene-example.toml).
    #[arg(long)]
    scene: PathBuf,
    /// Trajectory knots (CSV: t,x,y,z,pitch,yaw[,roll]).
    #[arg(long)]
    trajectory: PathBuf,
    /// Intensity log to write.
    #[arg(long)]
    out: PathBuf,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Refuse a trajectory that would give more frames than this (its
    /// duration × the scene's rate): a typo in a knot's time must not fill
    /// the disk.
    #[arg(long, default_value_t = lightpose_sim::trajectory::DEFAULT_MAX_FRAMES)]
    max_frames: u64,
}

#[derive(clap::Args)]
pub struct SweepArgs {
    /// Scene file (TOML, see scene-example.toml): the tank swept.
    #[arg(long)]
    scene: PathBuf,
    /// The sweep's intensity log (JSON Lines), every frame with its true
    /// pose.
    #[arg(long)]
    out: PathBuf,
    /// Frames per pose (per sweep for dark frames). A scene of several
    /// samples per frame writes BURST lines, large: a few frames per pose
    /// serve.
    #[arg(long, default_value_t = 200)]
    samples: u32,
    /// all (translation + orientation), translation, orientation or dark.
    #[arg(long, default_value = "all")]
    kind: String,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Refuse a sweep of more frames than this (its poses × --samples): a
    /// typo in --samples must not fill the disk.
    #[arg(long, default_value_t = lightpose_sim::trajectory::DEFAULT_MAX_FRAMES)]
    max_frames: u64,
}

fn create(path: &PathBuf) -> anyhow::Result<BufWriter<File>> {
    let f = File::create(path).with_context(|| format!("{}: cannot create", path.display()))?;
    Ok(BufWriter::with_capacity(1 << 16, f))
}

pub fn simulate(a: SimulateArgs) -> anyhow::Result<()> {
    let scene = Scene::load(&a.scene)?;
    let traj = Trajectory::load(&a.trajectory)?;
    let rate = scene.adc.rate_hz;
    let n = scene.adc.samples_per_frame();
    // A frame's time is the middle of its samples, and a trajectory gives
    // frames while that is within it (MODEL.md); with one sample, as v2.
    let frames = if n > 1 {
        traj.burst_count(rate, n, scene.adc.sample_hz)
    } else {
        traj.frame_count(rate)
    };
    guard::max_frames(
        format_args!(
            "{}: {} s at {rate} Hz",
            a.trajectory.display(),
            traj.t_end() - traj.t0()
        ),
        frames,
        a.max_frames,
    )?;
    guard::not_an_input(
        &a.out,
        &[("scene", &a.scene), ("trajectory", &a.trajectory)],
    )?;
    let mut header = scene.log_header();
    header
        .extra
        .insert("scene".into(), a.scene.display().to_string().into());
    header.extra.insert(
        "trajectory".into(),
        a.trajectory.display().to_string().into(),
    );
    header.extra.insert("seed".into(), a.seed.into());
    let mut w = LogWriter::new(create(&a.out)?, &header)?;
    let mut sim = Simulator::new(scene.clone(), a.seed);
    sim.set_report_roll(traj.has_roll());
    let at = |t: f64| traj.kinematics(t);
    let mut burst = Burst::new(n);
    for (seq, t) in traj.frame_times(rate).take(frames as usize).enumerate() {
        let written = if n > 1 {
            // Spec v3: the raw samples, t the first one's time.
            sim.burst(seq as u64, t, at, &mut burst);
            w.write_burst(&burst)
        } else {
            w.write_frame(&sim.frame_at(seq as u64, t, at, &mut burst))
        };
        written.with_context(|| format!("{}: write failed", a.out.display()))?;
    }
    w.flush()
        .with_context(|| format!("{}: write failed", a.out.display()))?;
    eprintln!("{}: {} frames", a.out.display(), w.frames_written());
    Ok(())
}

pub fn sweep(a: SweepArgs) -> anyhow::Result<()> {
    let kind = SweepKind::parse(&a.kind).with_context(|| {
        format!(
            "--kind {}: must be all, translation, orientation or dark",
            a.kind
        )
    })?;
    if a.samples == 0 {
        anyhow::bail!("--samples 0: need at least one frame per pose");
    }
    let scene = Scene::load(&a.scene)?;
    let plan = SweepPlan::for_scene(kind, a.samples, &scene);
    let what = match kind {
        SweepKind::Dark => format!("--samples {}: the dark sweep", a.samples),
        _ => format!(
            "--samples {}: the {} sweep ({} poses)",
            a.samples,
            kind.as_str(),
            plan.poses.len()
        ),
    };
    guard::max_frames(what, plan.frames(), a.max_frames)?;
    guard::not_an_input(&a.out, &[("scene", &a.scene)])?;
    let n = plan
        .write(&scene, a.seed, create(&a.out)?)
        .with_context(|| format!("{}: write failed", a.out.display()))?;
    eprintln!(
        "{}: {} frames ({} sweep)",
        a.out.display(),
        n,
        kind.as_str()
    );
    Ok(())
}
