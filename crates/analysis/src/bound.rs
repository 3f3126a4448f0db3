//! The Cramér–Rao bound of a simulated scene, as the Monte Carlo draws it:
//! the scene's true sensor, its K_D and temperature spreads as the priors
//! an estimator does not know, and its attitude sensor when it has one.
//!
//! Also the bound for a tracker along the whole trajectory
//! ([`track_bound_along`]), which is where a DVL's worth shows.
//!
//! Why here: `lightpose bench` sets the bound beside every estimator and
//! `lightpose crb` prints it along a trajectory; both must mean the same
//! scene, and only this crate knows both the simulator's `Scene` and the
//! pipeline's `CrbScene`.

use lightpose_core::{Attitude, Pose};
use lightpose_pipeline::model::bound_light::{BoundDaylight, BoundLight};
use lightpose_pipeline::model::crb::{crb_along, CrbBound, CrbScene};
use lightpose_pipeline::model::tracker::{TrackBound, TrackBoundScene, TrackPoint};
use lightpose_pipeline::model::{SensorModel, Tracker};
use lightpose_pipeline::settings::TrackerConfig;
use lightpose_sim::{Scene, Trajectory};

/// The true sensor of a scene (what the simulator draws frames from).
pub fn sensor_of(s: &Scene) -> SensorModel {
    SensorModel {
        light: s.light,
        geometry: s.geometry,
        gain: s.gain,
        offset_v: s.offset_v,
        v_ref: s.adc.v_ref,
        adc_bits: s.adc.bits,
        sigma_e_v: s.noise.map_or(0.0, |n| n.sigma_e_v),
        kappa_v: s.noise.map_or(0.0, |n| n.kappa_v),
        k_d_sigma: 0.0,
    }
}

/// The bound's view of `s`: spreads of `[montecarlo]` (a zero spread means
/// known exactly) and the `[attitude]` and `[depth]` sensors when present
/// (a `[dvl]` adds nothing to one frame's bound).
pub fn crb_scene(s: &Scene) -> CrbScene {
    CrbScene {
        model: sensor_of(s),
        temp_c: s.temp_c,
        sigma_k_d: Some(s.montecarlo.sigma_k_d).filter(|v| *v > 0.0),
        sigma_temp_c: Some(s.montecarlo.sigma_temp_c).filter(|v| *v > 0.0),
        attitude_sigma: s.attitude.map(|n| (n.sigma_pitch, n.sigma_yaw)),
        depth_sigma: s.depth.map(|d| d.sigma_m),
        // Spec v3: a scene whose sensor reads roll; else roll as known.
        roll_sigma: s.attitude.and_then(|n| n.sigma_roll),
        light: bound_light(s),
    }
}

/// How `s`'s frames carry the light to an estimator (spec v3): a blinking
/// beacon's amplitudes over the frame's samples, or counts; and the sun's
/// mean, whose flicker common to every detector is in its unknown level
/// and whose own part per detector is a noise.
pub fn bound_light(s: &Scene) -> BoundLight {
    let mod_hz = s.beacons.first().map_or(s.blink.mod_hz, |b| b.mod_hz());
    let n = s.adc.samples_per_frame();
    BoundLight {
        blink_samples: (mod_hz > 0.0 && n > 1).then(|| u32::try_from(n).unwrap_or(u32::MAX)),
        daylight: s.daylight.as_ref().map(|d| BoundDaylight {
            surface_v: d.surface_v,
            origin_depth_m: d.origin_depth_m,
            upwelling: d.upwelling,
            own_flicker: d.random_std * d.spatial.sqrt(),
            flicker_depth_m: d.flicker_depth_m,
        }),
    }
}

/// What the bound reads a v3 scene's frames as, in words (`None` for
/// v1/v2's counts of a steady beacon without daylight).
pub fn describe_light(l: &BoundLight) -> Option<String> {
    let sun = |d: &BoundDaylight| {
        format!(
            "daylight {} V at the surface ({} m above B's origin)",
            d.surface_v, d.origin_depth_m
        )
    };
    match (l.blink_samples, &l.daylight) {
        (None, None) => None,
        (Some(n), d) => Some(format!(
            "light: a blinking beacon's amplitudes, {n} samples a channel a frame, at the white-noise limit (no demodulator's search, no model error){}",
            d.map_or(String::new(), |d| format!("; {}: its shot noise only", sun(&d)))
        )),
        (None, Some(d)) => Some(format!(
            "light: a steady beacon's counts; {}: its level unknown each frame, each detector's own flicker a noise",
            sun(d)
        )),
    }
}

/// One frame time of a trajectory with its true pose and the bound there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundStep {
    pub t: f64,
    pub pose: Pose,
    pub bound: CrbBound,
}

/// The single-frame bound at every frame time of `traj` (the scene's ADC
/// rate), in time order.
pub fn along_trajectory(s: &Scene, traj: &Trajectory) -> Vec<BoundStep> {
    let times: Vec<f64> = traj.frame_times(s.adc.rate_hz).collect();
    let poses: Vec<Pose> = times.iter().map(|&t| traj.sample(t).0).collect();
    let bounds = crb_along(&crb_scene(s), &poses);
    times
        .into_iter()
        .zip(poses)
        .zip(bounds)
        .map(|((t, pose), bound)| BoundStep { t, pose, bound })
        .collect()
}

/// The bound for a tracker with `cfg`'s motion model along `traj` in
/// `s` (its spreads and own sensors, DVL included), at every frame time:
/// see `lightpose_pipeline::model::tracker::bound`.
pub fn track_bound_along(
    s: &Scene,
    traj: &Trajectory,
    cfg: &TrackerConfig,
) -> Result<Vec<TrackBound>, lightpose_pipeline::settings::ModelError> {
    // The scene's truth is the model here; the water's doubt is the
    // Monte Carlo's, as for the estimators the bench runs.
    let cfg = cfg
        .clone()
        .in_water_known_to(s.montecarlo.sigma_k_d, s.montecarlo.sigma_temp_c);
    let tracker = Tracker::new(sensor_of(s), cfg)?;
    let track: Vec<TrackPoint> = traj
        .frame_times(s.adc.rate_hz)
        .map(|t| {
            let k = traj.kinematics(t);
            let att = Attitude::new(k.pose.pitch, k.pose.yaw);
            TrackPoint {
                t,
                pose: k.pose,
                velocity: att.to_body(&k.velocity),
            }
        })
        .collect();
    let sc = TrackBoundScene {
        temp_c: s.temp_c,
        sigma_k_d: Some(s.montecarlo.sigma_k_d).filter(|v| *v > 0.0),
        sigma_temp_c: Some(s.montecarlo.sigma_temp_c).filter(|v| *v > 0.0),
        attitude: s.attitude.map(|a| (a.sigma_pitch.rad(), a.sigma_yaw.rad())),
        depth: s.depth.map(|d| d.sigma_m),
        dvl: s.dvl.map(|d| d.sigma_mps),
        light: bound_light(s),
    };
    Ok(tracker.track_bound(&track, &sc))
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_sim::AttitudeNoise;
    use std::path::Path;

    fn load() -> (Scene, Trajectory) {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let s = Scene::load(&root.join("config/scenes/tank.toml")).expect("tank scene");
        let t = Trajectory::load(&root.join("config/trajectories/dive.csv")).expect("dive");
        (s, t)
    }

    /// MODEL.md, Frames: one frame cannot separate y from yaw or z from
    /// pitch; the attitude sensor pins them, and (information only adds)
    /// never loosens any axis.
    #[test]
    fn the_bound_shows_the_ridge_and_the_sensor_closes_it() {
        let (mut s, traj) = load();
        let free = along_trajectory(&s, &traj);
        assert_eq!(free.len(), 41);
        assert!(free
            .iter()
            .all(|b| b.bound.y > 1.0 && b.bound.yaw_deg > 10.0));
        s.attitude = Some(AttitudeNoise::default());
        let pinned = along_trajectory(&s, &traj);
        for (f, p) in free.iter().zip(&pinned) {
            assert!(p.bound.y < 0.3 && p.bound.z < 0.3, "{p:?}");
            assert!(p.bound.pitch_deg <= 0.3 + 1e-9 && p.bound.yaw_deg <= 1.5 + 1e-9);
            assert!(p.bound.x <= f.bound.x * (1.0 + 1e-9), "{f:?} {p:?}");
        }
        // Closer is better: the end of the dive (4.5 m) beats its start.
        assert!(pinned[40].bound.y < pinned[0].bound.y);
    }
}
