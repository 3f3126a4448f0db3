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
use lightpose_pipeline::model::light::{BeaconLight, Placement};
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
        // Spec v3: a scene whose sensor reads roll; a station sees roll
        // itself (free without it); one beacon takes roll as known.
        roll_sigma: s.attitude.and_then(|n| n.sigma_roll).or_else(|| {
            (s.beacons.len() > 1).then_some(lightpose_core::Angle::from_rad(f64::INFINITY))
        }),
        light: bound_light(s),
        station: station_of(s),
    }
}

/// A station's beacons as the light equation sees them (empty for one
/// `[beacon]`: the sensor model's own at D's origin).
pub fn station_of(s: &Scene) -> Vec<BeaconLight> {
    s.beacons
        .iter()
        .map(|b| BeaconLight {
            v1: b.v1,
            sigma_b: b.sigma_b,
            place: Placement::new(b.position_m, b.axis_yaw, b.axis_pitch),
            model_rel: lightpose_pipeline::model::measurement::AMPLITUDE_MODEL_REL,
        })
        .collect()
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

/// A station's beacons in words (`None` for one `[beacon]`).
pub fn describe_station(s: &Scene) -> Option<String> {
    if s.beacons.is_empty() {
        return None;
    }
    let list: Vec<String> = s
        .beacons
        .iter()
        .map(|b| {
            let c = b.position_m;
            format!(
                "{} {} Hz at ({}, {}, {}) m",
                b.id,
                b.mod_hz(),
                c[0],
                c[1],
                c[2]
            )
        })
        .collect();
    Some(format!(
        "station: {} beacon(s), one image of amplitudes each, the pose in the station's frame D; roll {}: {}",
        s.beacons.len(),
        if s.beacons.len() > 1 && s.attitude.and_then(|a| a.sigma_roll).is_none() {
            "from the light alone"
        } else {
            "as the scene's sensor or prior gives it"
        },
        list.join(", ")
    ))
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
    let mut tracker = Tracker::new(sensor_of(s), cfg)?;
    // Spec v3: a station's tracker, roll a state and every beacon's image.
    if s.beacons.len() > 1 {
        tracker = tracker.with_station(station_of(s));
    }
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
        roll: s.attitude.and_then(|a| a.sigma_roll).map(|r| r.rad()),
        depth: s.depth.map(|d| d.sigma_m),
        dvl: s.dvl.map(|d| d.sigma_mps),
        light: bound_light(s),
    };
    Ok(tracker.track_bound(&track, &sc))
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::Angle;
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

    fn dock(known_water: bool) -> Scene {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/spec");
        let mut s = Scene::load(&root.join("dock-example.toml")).expect("dock-example");
        // Light alone.
        s.attitude = None;
        s.depth = None;
        if known_water {
            s.montecarlo.sigma_k_d = 0.0;
            s.montecarlo.sigma_temp_c = 0.0;
        }
        s
    }

    fn on_axis(s: &Scene, x: f64) -> CrbBound {
        crb_along(
            &crb_scene(s),
            &[Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO)],
        )[0]
    }

    /// Issue 41's scale, one frame by light alone on dock-example.toml
    /// (1.96σ, K_D and the temperature known): at 5 m x .05, y .14, z .17
    /// m, pitch 2.2°, yaw 1.8°, roll 6.9°; at 3 m x .01, y .02, z .02 m.
    /// Four beacons see roll, and one beacon's ridges are gone.
    #[test]
    fn a_station_s_bound_sees_the_whole_pose() {
        let s = dock(true);
        let z = crate::trade::Z95;
        let b5 = on_axis(&s, 5.0);
        let got = [b5.x, b5.y, b5.z, b5.pitch_deg, b5.yaw_deg, b5.roll_deg].map(|v| z * v);
        let want = [0.05, 0.14, 0.17, 2.2, 1.8, 6.9];
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g / w - 1.0).abs() < 0.15,
                "at 5 m: {got:?} against {want:?}"
            );
        }
        let b3 = on_axis(&s, 3.0);
        for (g, w) in [b3.x, b3.y, b3.z].iter().zip([0.01, 0.02, 0.02]) {
            assert!(z * g <= w * 1.1 && z * g >= w * 0.3, "at 3 m: {b3:?}");
        }
        // The same station with one beacon: roll unseen, the ridges back.
        let mut one = s.clone();
        one.beacons.truncate(1);
        let b1 = on_axis(&one, 5.0);
        assert!(
            b1.y > 10.0 * b5.y && b1.yaw_deg > 10.0 * b5.yaw_deg,
            "{b1:?}"
        );
        // Two beacons not in line with the vehicle: roll observable.
        let mut two = s.clone();
        two.beacons.truncate(2);
        let b2 = on_axis(&two, 3.0);
        assert!(b2.roll_deg.is_finite() && b2.roll_deg < 10.0, "{b2:?}");
        // Not knowing K_D costs range, nothing else much.
        let wet = on_axis(&dock(false), 5.0);
        assert!(wet.x > b5.x && wet.yaw_deg < b5.yaw_deg * 1.01, "{wet:?}");
    }

    /// One `[[beacons]]` entry at D's origin along +x is the v2 beacon: the
    /// station's path gives the bound of the sensor model's own beacon.
    #[test]
    fn a_station_of_one_beacon_at_the_origin_is_the_one_beacon_bound() {
        let mut s = dock(true);
        s.beacons.truncate(1);
        s.beacons[0].position_m = [0.0; 3];
        s.light.v1 = s.beacons[0].v1;
        s.light.sigma_b = s.beacons[0].sigma_b;
        let mut plain = s.clone();
        plain.beacons.clear();
        let pose = Pose::new(4.0, 0.2, -0.1, Angle::from_deg(3.0), Angle::from_deg(-2.0));
        let mut cs = crb_scene(&s);
        let mut cp = crb_scene(&plain);
        cs.light = bound_light(&s);
        cp.light = cs.light;
        assert_eq!(crb_along(&cs, &[pose]), crb_along(&cp, &[pose]));
    }
}
