//! From pose to frame: the light equation, then MODEL.md's "from light to
//! counts" (per-channel gain, temperature factor, dark offset, noise, ADC),
//! the reported temperature and the vehicle's sensors (attitude, depth,
//! DVL). Deterministic for a seed: the random draws of a frame come in a
//! fixed order, and a sensor's draws come after those of the sensors before
//! it, so adding a depth sensor or a DVL to a scene leaves its counts as
//! they were.

use crate::Kinematics;
use crate::Scene;
use lightpose_core::frame::volts_to_counts;
use lightpose_core::light::temperature_gain;
use lightpose_core::{
    Angle, Attitude, AttitudeReading, AttitudeStd, BeamVec, BodyVec, DepthReading, Frame, Pose,
    Truth, VelocityReading, NDET,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Makes frames of a scene.
#[derive(Debug, Clone)]
pub struct Simulator {
    scene: Scene,
    rng: ChaCha8Rng,
    /// The temperature the frames report, if it is not the sensor's reading
    /// of the true temperature (the Monte Carlo reports T0 exactly).
    reported_temp: Option<f64>,
    /// Light on (false: dark frames, V1 = 0).
    beacon_on: bool,
}

impl Simulator {
    pub fn new(scene: Scene, seed: u64) -> Self {
        Simulator {
            scene,
            rng: ChaCha8Rng::seed_from_u64(seed),
            reported_temp: None,
            beacon_on: true,
        }
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }
    pub fn scene_mut(&mut self) -> &mut Scene {
        &mut self.scene
    }

    /// Report exactly this temperature with every frame (no sensor noise),
    /// whatever the water's true temperature: the Monte Carlo's setting.
    pub fn set_reported_temp(&mut self, t_c: Option<f64>) {
        self.reported_temp = t_c;
    }

    /// Switch the beacon off for dark frames.
    pub fn set_beacon(&mut self, on: bool) {
        self.beacon_on = on;
    }

    /// Noise-free volts at each channel (before the ADC).
    pub fn volts(&self, pose: &Pose, out: &mut [f64; NDET]) {
        let s = &self.scene;
        let mut e = [0.0; NDET];
        if self.beacon_on {
            s.light.irradiance(&s.geometry, pose, &mut e);
        }
        let gt = temperature_gain(s.temp_c);
        for k in 0..NDET {
            out[k] = s.gain[k] * gt * e[k] + s.offset_v[k];
        }
    }

    /// One frame at `pose`, with its truth; a vehicle that moves, moves
    /// along its bow at `surge` (the DVL, if any, reads that).
    pub fn frame(&mut self, seq: u64, t: f64, pose: &Pose, surge: Option<f64>) -> Frame {
        let fwd = Attitude::new(pose.pitch, pose.yaw).forward().0;
        let u = surge.unwrap_or(0.0);
        let velocity = BeamVec([u * fwd[0], u * fwd[1], u * fwd[2]]);
        self.frame_of(seq, t, pose, surge, &velocity)
    }

    /// One frame of a vehicle at `k` (pose and velocity over the ground):
    /// the DVL, if any, reads the whole velocity, sideslip and heave too.
    pub fn frame_moving(&mut self, seq: u64, t: f64, k: &Kinematics) -> Frame {
        self.frame_of(seq, t, &k.pose, Some(k.surge()), &k.velocity)
    }

    fn frame_of(
        &mut self,
        seq: u64,
        t: f64,
        pose: &Pose,
        surge: Option<f64>,
        velocity: &BeamVec,
    ) -> Frame {
        let mut volts = [0.0; NDET];
        self.volts(pose, &mut volts);
        // Borrow the scene and the generator apart.
        let Simulator {
            scene: s,
            rng,
            reported_temp,
            ..
        } = self;
        let mut normal = || -> f64 { StandardNormal.sample(rng) };
        let gt = temperature_gain(s.temp_c);
        let mut counts = [0u16; NDET];
        for k in 0..NDET {
            let mut v = volts[k];
            if let Some(n) = s.noise {
                // Shot noise scales with the light that arrives (E_k).
                let e = ((v - s.offset_v[k]) / (s.gain[k] * gt)).max(0.0);
                let var = n.sigma_e_v * n.sigma_e_v + n.kappa_v * e;
                v += var.sqrt() * normal();
            }
            counts[k] = volts_to_counts(v, s.adc.v_ref, s.adc.bits);
        }
        let temp_c = match (*reported_temp, s.noise) {
            (Some(t), _) => t,
            (None, Some(n)) => s.temp_c + n.sigma_temp_c * normal(),
            (None, None) => s.temp_c,
        };
        let attitude = s.attitude.map(|a| {
            let dp = a.sigma_pitch.rad() * normal();
            let dy = a.sigma_yaw.rad() * normal();
            AttitudeReading {
                roll: None,
                std: told(a.sigma_pitch.rad().min(a.sigma_yaw.rad())).then_some(AttitudeStd {
                    pitch: a.sigma_pitch,
                    yaw: a.sigma_yaw,
                }),
                ..AttitudeReading::new(
                    pose.pitch + Angle::from_rad(dp),
                    // A heading as a sensor reports it: a wide noise
                    // had written readings of −219°, refused by replay.
                    (pose.yaw + Angle::from_rad(dy)).wrapped(),
                )
            }
        });
        let depth = s.depth.map(|d| DepthReading {
            z: pose.z + d.sigma_m * normal(),
            std: told(d.sigma_m).then_some(d.sigma_m),
        });
        let velocity = s.dvl.map(|d| {
            let v = Attitude::new(pose.pitch, pose.yaw).to_body(velocity).0;
            let mut noisy = [0.0; 3];
            for (n, c) in noisy.iter_mut().zip(v) {
                *n = c + d.sigma_mps * normal();
            }
            VelocityReading {
                v: BodyVec(noisy),
                std: told(d.sigma_mps).then_some(BodyVec([d.sigma_mps; 3])),
            }
        });
        Frame {
            seq,
            t,
            adc_bits: s.adc.bits,
            counts,
            temp_c: Some(temp_c),
            truth: Some(Truth { pose: *pose, surge }),
            attitude,
            depth,
            velocity,
        }
    }
}

/// Whether a sensor's noise goes into its readings as their `std`
/// (FORMATS.md): the simulated sensor knows its σ as a real DVL reports its
/// covariance, so that a replay sees what the live estimator saw. A scene's
/// noise-free sensor (σ 0) says nothing; a std of 0 is no std a filter can
/// use, and the estimator's configured noise applies.
fn told(sigma: f64) -> bool {
    sigma > 0.0
}
