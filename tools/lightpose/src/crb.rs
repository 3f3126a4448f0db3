//! `lightpose crb`: the Cramér–Rao bound of a scene along a trajectory, one
//! row per frame — the limit every estimator is held against (docs/
//! estimators.md). Thin: the bound is `lightpose_analysis::bound`.

use crate::guard;
use crate::stdout::out;
use anyhow::Context;
use lightpose_analysis::bound::{
    along_trajectory, bound_light, crb_scene, describe_light, describe_station, track_bound_along,
};
use lightpose_analysis::sensors;
use lightpose_analysis::trade::{num, Z95};
use lightpose_pipeline::settings::TrackerConfig;
use lightpose_sim::{Scene, Trajectory};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CrbArgs {
    /// Scene file (TOML): its sensor, its [montecarlo] spreads (K_D and
    /// temperature the estimator does not know) and its own sensors
    /// ([attitude], [depth], [dvl]).
    #[arg(long)]
    scene: PathBuf,
    /// Trajectory knots (CSV: t,x,y,z,pitch,yaw); one row per frame at the
    /// scene's ADC rate.
    #[arg(long)]
    trajectory: PathBuf,
    /// The vehicle's own sensors: as the scene says, or none, attitude,
    /// depth, attitude+depth, all (a sensor the scene lacks gets MODEL.md's
    /// noise). A DVL adds nothing to one frame's bound.
    #[arg(long, default_value = "scene")]
    sensors: String,
    /// Print the 95 % half-width (1.96σ) instead of 1σ.
    #[arg(long)]
    half_width: bool,
    /// Print every n-th frame (the first and last always); at least 1.
    #[arg(long, default_value_t = 1)]
    every: usize,
    /// Also the bound for a tracker: the posterior bound along the whole
    /// trajectory for an estimator with the tracker's (default) motion
    /// model, where a DVL counts; with surge.
    #[arg(long)]
    track: bool,
}

/// The scene's own sensors, in words.
fn own_sensors(scene: &Scene) -> String {
    let mut own = Vec::new();
    if let Some(n) = scene.attitude {
        own.push(format!(
            "attitude sensor {:.2}° pitch, {:.2}° yaw",
            n.sigma_pitch.deg(),
            n.sigma_yaw.deg()
        ));
    }
    if let Some(d) = scene.depth {
        own.push(format!("depth sensor {} m", d.sigma_m));
    }
    if scene.dvl.is_some() {
        own.push("DVL (adds nothing to one frame; see --track)".into());
    }
    if own.is_empty() {
        "no own sensor".to_string()
    } else {
        own.join(", ")
    }
}

pub fn run(a: CrbArgs) -> anyhow::Result<()> {
    guard::at_least_one("every", a.every, "print every n-th frame")?;
    let mut scene = Scene::load(&a.scene)?;
    let traj = Trajectory::load(&a.trajectory)?;
    sensors::apply_choice(&a.sensors, &mut scene)
        .with_context(|| format!("--sensors {}: {}", a.sensors, sensors::CHOICES))?;
    let steps = along_trajectory(&scene, &traj);
    let track = if a.track {
        Some(track_bound_along(&scene, &traj, &TrackerConfig::default())?)
    } else {
        None
    };
    let every = a.every;
    let (k, what) = if a.half_width {
        (Z95, "95 % half-width (1.96σ)")
    } else {
        (1.0, "1σ")
    };
    let mut out = heading(&a, &scene, what, track.is_some());
    let roll = crb_scene(&scene).roll_sigma.is_some();
    let _ = writeln!(out);
    let mut head = vec!["t (s)", "x (m)", "y (m)", "z (m)", "pitch (°)", "yaw (°)"];
    if roll {
        head.push("roll (°)");
    }
    head.extend([
        "bound x (m)",
        "bound y (m)",
        "bound z (m)",
        "bound pitch (°)",
        "bound yaw (°)",
    ]);
    if roll {
        head.push("bound roll (°)");
    }
    if track.is_some() {
        head.extend([
            "track x (m)",
            "track y (m)",
            "track z (m)",
            "track pitch (°)",
            "track yaw (°)",
            "track surge (m/s)",
        ]);
    }
    let _ = writeln!(out, "| {} |", head.join(" | "));
    let _ = writeln!(out, "|{}", "---|".repeat(head.len()));
    let last = steps.len().saturating_sub(1);
    for (i, s) in steps.iter().enumerate() {
        if i % every != 0 && i != last {
            continue;
        }
        let b = &s.bound;
        let p = &s.pose;
        let mut cells = vec![
            format!("{:.2}", s.t),
            format!("{:.2}", p.x),
            format!("{:.2}", p.y),
            format!("{:.2}", p.z),
            format!("{:.1}", p.pitch.deg()),
            format!("{:.1}", p.yaw.deg()),
        ];
        if roll {
            cells.push(format!("{:.1}", p.roll.deg()));
        }
        for v in [b.x, b.y, b.z, b.pitch_deg, b.yaw_deg] {
            cells.push(num(Some(k * v)));
        }
        if roll {
            cells.push(num(Some(k * b.roll_deg)));
        }
        if let Some(tb) = track.as_ref().and_then(|v| v.get(i)) {
            for v in [tb.x, tb.y, tb.z, tb.pitch_deg, tb.yaw_deg, tb.surge] {
                cells.push(num(Some(k * v)));
            }
        }
        let _ = writeln!(out, "| {} |", cells.join(" | "));
    }
    out!("{out}");
    Ok(())
}

/// The lines above the table: what the bound is of, and how it reads the
/// scene's light and station.
fn heading(a: &CrbArgs, scene: &Scene, what: &str, track: bool) -> String {
    let sensor = own_sensors(scene);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Cramér–Rao bound, {what}, one frame: {}; K_D spread {} 1/m, temperature spread {} °C; {sensor}",
        a.scene.display(),
        scene.montecarlo.sigma_k_d,
        scene.montecarlo.sigma_temp_c,
    );
    if let Some(light) = describe_light(&bound_light(scene)) {
        let _ = writeln!(out, "{light}");
    }
    if let Some(station) = describe_station(scene) {
        let _ = writeln!(out, "{station}");
    }
    if track {
        let _ = writeln!(
            out,
            "Tracker bound ({what}): the whole trajectory, the tracker's default motion model as the prior between frames"
        );
    }
    out
}
