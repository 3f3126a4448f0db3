//! Cramér–Rao lower bounds on single-frame pose accuracy for a scene.
//!
//! Why: to know how far any estimator is from the best the photodiodes can
//! do, and where the geometry (not the algorithm) is the limit — on the beam
//! axis one frame hardly tells y from yaw or z from pitch (MODEL.md). The
//! Fisher information comes from the light equation's analytic Jacobian and
//! the noise model σ² = σ_e² + κE plus LSB²/12; K_D is a nuisance parameter
//! with the Monte Carlo's spread as prior, so is the unknown temperature
//! (a common gain), and the vehicle's own sensors add priors: the attitude
//! sensor on pitch and yaw, the depth sensor 1/σ_d² on z (spec v2).
//! Spec v3: the pose's roll is where the light is evaluated, and roll is a
//! nuisance parameter too when the scene says how well it is known (the
//! attitude sensor's roll σ, or a prior), as the estimators consider it.
//! A blinking beacon's frame is its amplitudes with their white-noise
//! variance, and a steady beacon by day pays for the sun's unknown level
//! (`bound_light`).
//!
//! A DVL adds nothing here: it measures velocity, and one frame's bound
//! has no velocity in it. What the DVL buys is the tie between frames,
//! which only a bound over the whole track (a tracker's bound) can show;
//! docs/estimators.md says how the trade table treats it.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::light::temperature_gain;
use lightpose_core::{Angle, Pose};
use nalgebra::{SMatrix, SVector};

use super::bound_light::{channels, station_channels, BoundLight, NG};
use super::light::from_pose;
use super::light::BeaconLight;
use super::SensorModel;

/// Parameters: x, y, z, θ, ψ, K_D, common gain, roll.
const NP: usize = NG;

/// A scene as the bound needs it.
#[derive(Debug, Clone, PartialEq)]
pub struct CrbScene {
    pub model: SensorModel,
    /// True water temperature (the frames' gain g_T).
    pub temp_c: f64,
    /// 1σ spread of K_D not known to the estimator (MODEL.md Monte Carlo:
    /// 0.015 m⁻¹); `None`: K_D known exactly.
    pub sigma_k_d: Option<f64>,
    /// 1σ error of the temperature the estimator corrects with (Monte Carlo:
    /// 3 °C); `None`: known exactly.
    pub sigma_temp_c: Option<f64>,
    /// The attitude sensor's 1σ (pitch, yaw), when the vehicle has one.
    pub attitude_sigma: Option<(Angle, Angle)>,
    /// The depth sensor's 1σ (m), when the vehicle has one. Its reading is
    /// the sensor's z; a lever arm only shifts it by a known function of
    /// pitch, so the bound takes it at the dome centre.
    pub depth_sigma: Option<f64>,
    /// Spec v3: 1σ of the roll the estimator is given (the attitude
    /// sensor's roll, or a prior without one); `None`: roll known exactly
    /// (spec v1/v2, and the bound is v2's bit for bit).
    pub roll_sigma: Option<Angle>,
    /// Spec v3: counts or a blinking beacon's amplitudes, and the sun
    /// (`bound_light`); the default is v1/v2's.
    pub light: BoundLight,
    /// Spec v3: a docking station's beacons, each an image of amplitudes;
    /// empty: the model's one beacon at the origin (D = B).
    pub station: Vec<BeaconLight>,
}

impl CrbScene {
    /// The scene of MODEL.md's Monte Carlo for `model`: K_D spread
    /// 0.015 m⁻¹, temperature spread 3 °C, no attitude sensor.
    pub fn montecarlo(model: SensorModel) -> Self {
        CrbScene {
            model,
            temp_c: 20.0,
            sigma_k_d: Some(0.015),
            sigma_temp_c: Some(3.0),
            attitude_sigma: None,
            depth_sigma: None,
            roll_sigma: None,
            light: BoundLight::default(),
            station: Vec::new(),
        }
    }
}

/// Lower bounds on the 1σ error of an unbiased single-frame estimate.
/// `f64::INFINITY` where the frame carries no information on a coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrbBound {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    /// Spec v3: roll's, degrees, with its prior (`CrbScene::roll_sigma`);
    /// 0 when roll is known exactly.
    pub roll_deg: f64,
}

/// Fisher information of one frame at `pose` over (x, y, z, θ, ψ, K_D, gain,
/// roll), priors included. Channels the model puts at or beyond full scale, or at
/// zero, are censored and carry (almost) nothing; they are left out.
pub fn fisher(scene: &CrbScene, pose: &Pose) -> SMatrix<f64, NP, NP> {
    let m = &scene.model;
    let gt = temperature_gain(scene.temp_c);
    let q = from_pose(pose);
    let (roll, k_d) = (pose.roll.rad(), m.light.k_d);
    let images = if scene.station.is_empty() {
        vec![channels(m, &scene.light, &q, roll, k_d, gt)]
    } else {
        station_channels(m, &scene.light, &scene.station, &q, roll, k_d, gt)
    };
    let mut f = SMatrix::<f64, NP, NP>::zeros();
    for c in images.iter().flatten().filter(|c| c.used) {
        let row = SVector::<f64, NP>::from_column_slice(&c.grad);
        f += row * row.transpose() / c.var;
    }
    let mut fix = |i: usize, sigma: Option<f64>| match sigma {
        Some(s) if s > 0.0 && s.is_finite() => f[(i, i)] += 1.0 / (s * s),
        // Unknown and without a prior: the light alone tells it (roll of
        // a station without an attitude sensor).
        Some(s) if s == f64::INFINITY => {}
        // Known exactly: remove the parameter from the problem.
        _ => {
            for j in 0..NP {
                f[(i, j)] = 0.0;
                f[(j, i)] = 0.0;
            }
            f[(i, i)] = 1.0;
        }
    };
    fix(5, scene.sigma_k_d);
    let slope = lightpose_core::light::temperature_gain_slope(scene.temp_c);
    fix(6, scene.sigma_temp_c.map(|s| s * slope));
    fix(7, scene.roll_sigma.map(|s| s.rad()));
    if let Some((sp, sy)) = scene.attitude_sigma {
        f[(3, 3)] += 1.0 / (sp.rad() * sp.rad());
        f[(4, 4)] += 1.0 / (sy.rad() * sy.rad());
    }
    if let Some(sd) = scene.depth_sigma.filter(|s| *s > 0.0 && s.is_finite()) {
        f[(2, 2)] += 1.0 / (sd * sd);
    }
    f
}

/// Per-pose Cramér–Rao bounds on x, y, z, pitch, yaw for single frames of
/// `scene` at each of `poses`.
pub fn crb_along(scene: &CrbScene, poses: &[Pose]) -> Vec<CrbBound> {
    poses
        .iter()
        .map(|p| {
            let f = fisher(scene, p);
            let sd = |c: &SMatrix<f64, NP, NP>, i: usize| {
                let v = c[(i, i)];
                if v.is_finite() && v >= 0.0 {
                    v.sqrt()
                } else {
                    f64::INFINITY
                }
            };
            // Scale to unit diagonal before inverting: the columns differ by
            // many orders of magnitude (metres, radians, m⁻¹, gain).
            let d = SVector::<f64, NP>::from_fn(|i, _| {
                let v = f[(i, i)];
                if v > 0.0 {
                    1.0 / v.sqrt()
                } else {
                    1.0
                }
            });
            let scaled = SMatrix::<f64, NP, NP>::from_fn(|i, j| f[(i, j)] * d[i] * d[j]);
            match scaled.cholesky() {
                Some(ch) => {
                    let inv = ch.inverse();
                    let c = SMatrix::<f64, NP, NP>::from_fn(|i, j| inv[(i, j)] * d[i] * d[j]);
                    CrbBound {
                        x: sd(&c, 0),
                        y: sd(&c, 1),
                        z: sd(&c, 2),
                        pitch_deg: sd(&c, 3).to_degrees(),
                        yaw_deg: sd(&c, 4).to_degrees(),
                        roll_deg: if scene.roll_sigma.is_some() {
                            sd(&c, 7).to_degrees()
                        } else {
                            0.0
                        },
                    }
                }
                None => CrbBound {
                    x: f64::INFINITY,
                    y: f64::INFINITY,
                    z: f64::INFINITY,
                    pitch_deg: f64::INFINITY,
                    yaw_deg: f64::INFINITY,
                    roll_deg: f64::INFINITY,
                },
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis(x: f64) -> Pose {
        Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO)
    }

    #[test]
    fn on_axis_y_and_yaw_need_the_attitude_sensor() {
        let mut scene = CrbScene::montecarlo(SensorModel::default());
        let poses = [axis(4.5), axis(6.5), axis(8.5)];
        let bare = crb_along(&scene, &poses);
        scene.attitude_sigma = Some((Angle::from_deg(0.3), Angle::from_deg(1.5)));
        let with = crb_along(&scene, &poses);
        for (b, w) in bare.iter().zip(&with) {
            eprintln!("CRB on axis: without sensor {b:?}\n             with sensor    {w:?}");
            // Without the sensor, y and yaw trade off along a ridge: their
            // bounds are several times what the sensor's 1.5° allows.
            assert!(b.y > 3.0 * w.y, "y: {b:?} vs {w:?}");
            assert!(b.yaw_deg > 3.0 * w.yaw_deg, "yaw: {b:?} vs {w:?}");
            assert!(b.z > 3.0 * w.z && b.pitch_deg > 3.0 * w.pitch_deg);
            // Range does not hinge on the attitude.
            assert!(b.x < 1.5 * w.x);
            assert!(w.yaw_deg <= 1.5 + 1e-9 && w.pitch_deg <= 0.3 + 1e-9);
        }
        // Farther is dimmer: worse range bound.
        assert!(bare[2].x > bare[0].x);
    }

    /// Depth pins z, and through the z–pitch ridge pitch too; it does not
    /// touch the y–yaw ridge.
    #[test]
    fn depth_pins_z_and_pitch_not_yaw() {
        let mut scene = CrbScene::montecarlo(SensorModel::default());
        let p = [Pose::new(6.5, 0.1, 0.2, Angle::from_deg(3.0), Angle::ZERO)];
        let bare = crb_along(&scene, &p)[0];
        scene.depth_sigma = Some(0.02);
        let d = crb_along(&scene, &p)[0];
        assert!(d.z <= 0.02 + 1e-12 && d.z < bare.z / 10.0, "{bare:?} {d:?}");
        assert!(d.pitch_deg < bare.pitch_deg / 5.0, "{bare:?} {d:?}");
        // The y/yaw ridge narrows (the beam couples it to z) but stays open.
        assert!(d.yaw_deg > 10.0 && d.y > 1.0, "{bare:?} {d:?}");
    }

    /// A roll known to its sensor's 0.3° costs the bound little; one known
    /// only to a few degrees costs y and z more (the beam's gradient
    /// across the dome turns with roll), and a rolled pose is bounded.
    #[test]
    fn roll_s_doubt_widens_the_bound_and_known_roll_is_v2() {
        let mut scene = CrbScene::montecarlo(SensorModel::default());
        scene.attitude_sigma = Some((Angle::from_deg(0.3), Angle::from_deg(1.5)));
        let p = Pose::new(6.5, 0.3, -0.2, Angle::from_deg(3.0), Angle::from_deg(-4.0));
        let v2 = crb_along(&scene, &[p])[0];
        scene.roll_sigma = Some(Angle::from_deg(0.3));
        let sensed = crb_along(&scene, &[p])[0];
        scene.roll_sigma = Some(Angle::from_deg(5.0));
        let prior = crb_along(&scene, &[p])[0];
        eprintln!("roll known {v2:?}\nroll ±0.3° {sensed:?}\nroll ±5° {prior:?}");
        for (a, b) in [
            (v2.y, sensed.y),
            (v2.z, sensed.z),
            (sensed.y, prior.y),
            (sensed.z, prior.z),
        ] {
            assert!(b >= a * (1.0 - 1e-9), "{a} {b}");
        }
        assert!(sensed.y < 1.1 * v2.y && sensed.z < 1.1 * v2.z);
        assert!(prior.y.max(prior.z) > v2.y.max(v2.z) * 1.001);
        let rolled = crb_along(&scene, &[p.with_roll(Angle::from_deg(8.0))])[0];
        assert!(rolled.x.is_finite() && rolled.y.is_finite() && rolled.z.is_finite());
        // One Gaussian beacon barely sees roll (MODEL.md): a frame leaves
        // a 5° prior nearly as it was, which is why the estimators take
        // roll as a consider parameter rather than fit it.
        for q in [
            p,
            p.with_roll(Angle::from_deg(8.0)),
            Pose::new(4.0, 0.5, 0.4, Angle::ZERO, Angle::ZERO),
        ] {
            let b = crb_along(&scene, &[q])[0];
            eprintln!(
                "roll's bound at {q:?}: {:.5}° of the prior's 5°",
                b.roll_deg
            );
            assert!(b.roll_deg > 4.9 && b.roll_deg <= 5.0 + 1e-9, "{b:?}");
        }
        assert_eq!(v2.roll_deg, 0.0);
    }

    /// Spec v3 in the bound: a blinking beacon's amplitudes over N samples
    /// bound far below one count per frame, and the sun only adds its
    /// shot noise to them; a steady beacon by day pays for the sun's
    /// unknown level with a wider bound, most on the axes its shape over
    /// the dome resembles, never a narrower one.
    #[test]
    fn amplitudes_and_daylight_in_the_bound() {
        use super::super::bound_light::BoundDaylight;
        // Shot noise on (κ), so that the sun costs the amplitudes; the
        // water known, so that the light's own information shows rather
        // than the K_D and temperature priors'.
        let model = SensorModel {
            adc_bits: 12,
            kappa_v: 1e-3,
            ..SensorModel::default()
        };
        let mut scene = CrbScene::montecarlo(model);
        scene.sigma_k_d = None;
        scene.sigma_temp_c = None;
        scene.attitude_sigma = Some((Angle::from_deg(0.3), Angle::from_deg(1.5)));
        let day = BoundDaylight {
            surface_v: 5.0,
            origin_depth_m: 4.0,
            upwelling: 0.02,
            own_flicker: 0.3 * 0.3f64.sqrt(),
            flicker_depth_m: 3.0,
        };
        let p = [Pose::new(
            6.5,
            0.3,
            -0.2,
            Angle::from_deg(3.0),
            Angle::from_deg(-4.0),
        )];
        let mut at = |blink_samples, daylight| {
            scene.light = BoundLight {
                blink_samples,
                daylight,
            };
            crb_along(&scene, &p)[0]
        };
        let steady_night = at(None, None);
        let steady_day = at(None, Some(day));
        let blink_night = at(Some(200), None);
        let blink_day = at(Some(200), Some(day));
        eprintln!(
            "steady night {steady_night:?}\nsteady day   {steady_day:?}\nblink night  {blink_night:?}\nblink day    {blink_day:?}"
        );
        let xyz = |b: &CrbBound| [b.x, b.y, b.z];
        // y and z lean on the attitude's prior and x on them (the beam
        // factor off axis): the amplitudes narrow every axis, none 7×.
        assert!(blink_night.x < 0.8 * steady_night.x && blink_night.z < 0.7 * steady_night.z);
        for i in 0..3 {
            assert!(xyz(&blink_night)[i] < xyz(&steady_night)[i], "{i}");
            assert!(
                xyz(&blink_day)[i] >= xyz(&blink_night)[i] * (1.0 - 1e-9),
                "{i}"
            );
            assert!(
                xyz(&steady_day)[i] >= xyz(&steady_night)[i] * (1.0 - 1e-9),
                "{i}"
            );
        }
        // The sun's level costs a steady beacon real precision somewhere.
        assert!(steady_day.x > 1.2 * steady_night.x || steady_day.z > 1.2 * steady_night.z);
        // Without shot noise, 100 on and 100 off samples carry N/4 = 50×
        // one count's information on every channel: x's, which no prior
        // touches, exactly so.
        let mut quiet = scene.clone();
        quiet.model.kappa_v = 0.0;
        quiet.light = BoundLight::default();
        let f1 = fisher(&quiet, &p[0]);
        quiet.light.blink_samples = Some(200);
        let f200 = fisher(&quiet, &p[0]);
        assert!(
            (f200[(0, 0)] / f1[(0, 0)] - 50.0).abs() < 1e-9,
            "{}",
            f200[(0, 0)] / f1[(0, 0)]
        );
        // Only its shot noise touches the amplitudes.
        assert!(blink_day.x > blink_night.x, "{blink_day:?} {blink_night:?}");
        assert!(
            blink_day.x < 2.0 * blink_night.x,
            "{blink_day:?} {blink_night:?}"
        );
    }

    #[test]
    fn k_d_spread_limits_range() {
        let m = SensorModel::default();
        let mut scene = CrbScene::montecarlo(m);
        scene.attitude_sigma = Some((Angle::from_deg(0.3), Angle::from_deg(1.5)));
        let with_spread = crb_along(&scene, &[axis(8.5)])[0];
        scene.sigma_k_d = None;
        scene.sigma_temp_c = None;
        let known = crb_along(&scene, &[axis(8.5)])[0];
        assert!(with_spread.x > known.x);
        // Unknown K_D by 0.015 at 8.5 m is ≈ 0.015·8.3/(0.09 + 2/8.3) ≈ 0.4 m
        // of range if intensity alone gave range; the image's spread helps
        // little, so the bound stays of that order.
        assert!(
            with_spread.x > 0.1 && with_spread.x < 1.0,
            "{with_spread:?}"
        );
    }
}
