//! `lightpose crb`: the Cramér–Rao bound of a scene along a trajectory, one
//! row per frame — the limit every estimator is held against (docs/
//! estimators.md). Thin: the bound is `lightpose_analysis::bound`.

use crate::cells::{num, Z95};
use lightpose_analysis::bound::along_trajectory;
use lightpose_sim::{AttitudeNoise, Scene, Trajectory};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CrbArgs {
    /// Scene file (TOML): its sensor, its [montecarlo] spreads (K_D and
    /// temperature the estimator does not know) and its [attitude] sensor.
    #[arg(long)]
    scene: PathBuf,
    /// Trajectory knots (CSV: t,x,y,z,pitch,yaw); one row per frame at the
    /// scene's ADC rate.
    #[arg(long)]
    trajectory: PathBuf,
    /// Attitude sensor: as the scene says, on (MODEL.md's 0.3° pitch, 1.5°
    /// yaw when the scene has none) or off.
    #[arg(long, default_value = "scene", value_parser = ["scene", "on", "off"])]
    attitude: String,
    /// Print the 95 % half-width (1.96σ) instead of 1σ.
    #[arg(long)]
    half_width: bool,
    /// Print every n-th frame (the first and last always).
    #[arg(long, default_value_t = 1)]
    every: usize,
}

pub fn run(a: CrbArgs) -> anyhow::Result<()> {
    let mut scene = Scene::load(&a.scene)?;
    let traj = Trajectory::load(&a.trajectory)?;
    match a.attitude.as_str() {
        "off" => scene.attitude = None,
        "on" if scene.attitude.is_none() => scene.attitude = Some(AttitudeNoise::default()),
        _ => {}
    }
    let steps = along_trajectory(&scene, &traj);
    let every = a.every.max(1);
    let (k, what) = if a.half_width {
        (Z95, "95 % half-width (1.96σ)")
    } else {
        (1.0, "1σ")
    };
    let sensor = match scene.attitude {
        Some(n) => format!(
            "attitude sensor {:.2}° pitch, {:.2}° yaw",
            n.sigma_pitch.deg(),
            n.sigma_yaw.deg()
        ),
        None => "no attitude sensor".into(),
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Cramér–Rao bound, {what}, one frame: {}; K_D spread {} 1/m, temperature spread {} °C; {sensor}",
        a.scene.display(),
        scene.montecarlo.sigma_k_d,
        scene.montecarlo.sigma_temp_c,
    );
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "| t (s) | x (m) | y (m) | z (m) | pitch (°) | yaw (°) | bound x (m) | bound y (m) | bound z (m) | bound pitch (°) | bound yaw (°) |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|---|---|");
    let last = steps.len().saturating_sub(1);
    for (i, s) in steps.iter().enumerate() {
        if i % every != 0 && i != last {
            continue;
        }
        let b = &s.bound;
        let _ = writeln!(
            out,
            "| {:.2} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} | {} | {} | {} | {} | {} |",
            s.t,
            s.pose.x,
            s.pose.y,
            s.pose.z,
            s.pose.pitch.deg(),
            s.pose.yaw.deg(),
            num(Some(k * b.x)),
            num(Some(k * b.y)),
            num(Some(k * b.z)),
            num(Some(k * b.pitch_deg)),
            num(Some(k * b.yaw_deg)),
        );
    }
    print!("{out}");
    Ok(())
}
