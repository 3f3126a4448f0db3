//! From pose to frame: the light equation, then MODEL.md's "from light to
//! counts" (per-channel gain, temperature factor, dark offset, noise, ADC),
//! the reported temperature and the vehicle's sensors (attitude, depth,
//! DVL). Deterministic for a seed: the random draws of a frame come in a
//! fixed order, and a sensor's draws come after those of the sensors before
//! it, so adding a depth sensor or a DVL to a scene leaves its counts as
//! they were.
//!
//! Spec v3 ("The open sea"): [`Simulator::burst`] makes the N samples of
//! every channel of a frame, each at its own instant (t0 + j / rate +
//! i / sample_hz + k · skew) with the pose there, the light of every
//! beacon through its square wave, and the daylight with its flicker; a
//! v2 scene's frames never go this way and stay v2's bit for bit.

use crate::scene::DEFAULT_SIGMA_ROLL_DEG;
use crate::Kinematics;
use crate::Scene;
use lightpose_core::frame::volts_to_counts;
use lightpose_core::light::{temperature_gain, DetectorView};
use lightpose_core::{
    Angle, AttitudeReading, AttitudeStd, BeamVec, BodyVec, Burst, DepthReading, Frame, LightParams,
    Pose, Truth, VelocityReading, NDET,
};
use rand::{Rng, SeedableRng};
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
    /// Whether the attitude sensor reports roll though the scene gives no
    /// `sigma_roll_deg` (the trajectory has a roll column; spec v3).
    report_roll: bool,
    /// The daylight flicker's random part, drawn once per run (spec v3).
    flicker: RandomFlicker,
}

/// Sinusoids of the flicker's random part: `common` for every detector,
/// `own[k]` for detector k; each (amplitude, 2π·f, phase in rad).
#[derive(Debug, Clone, Default)]
struct RandomFlicker {
    common: Vec<(f64, f64, f64)>,
    own: Vec<Vec<(f64, f64, f64)>>,
}

impl RandomFlicker {
    /// MODEL.md: M common sinusoids of amplitude σ_f·√((1 − spatial)·2/M)
    /// and M per detector of σ_f·√(spatial·2/M), frequencies log-uniform in
    /// the band, phases uniform. Drawn from a generator of their own, so
    /// that a scene with daylight keeps the frames' draws where they were.
    fn draw(scene: &Scene, seed: u64) -> Self {
        let Some(d) = scene.daylight.as_ref().filter(|d| d.random_std > 0.0) else {
            return RandomFlicker::default();
        };
        let m = d.random_components;
        if m == 0 {
            return RandomFlicker::default();
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0F11_C4E2_D4A1_16E7);
        let (lo, hi) = (d.random_min_hz.ln(), d.random_max_hz.ln());
        let mut one = |amp: f64| -> (f64, f64, f64) {
            let f = (lo + (hi - lo) * rng.gen::<f64>()).exp();
            let ph = std::f64::consts::TAU * rng.gen::<f64>();
            (amp, std::f64::consts::TAU * f, ph)
        };
        let m_f = m as f64;
        let a_common = d.random_std * ((1.0 - d.spatial) * 2.0 / m_f).sqrt();
        let a_own = d.random_std * (d.spatial * 2.0 / m_f).sqrt();
        let common = (0..m).map(|_| one(a_common)).collect();
        let own = (0..NDET)
            .map(|_| (0..m).map(|_| one(a_own)).collect())
            .collect();
        RandomFlicker { common, own }
    }

    /// Its part of Φ_k(t).
    fn at(&self, k: usize, t: f64) -> f64 {
        let sum =
            |v: &[(f64, f64, f64)]| v.iter().map(|(a, w, p)| a * (w * t + p).sin()).sum::<f64>();
        sum(&self.common) + self.own.get(k).map_or(0.0, |v| sum(v))
    }
}

impl Simulator {
    pub fn new(scene: Scene, seed: u64) -> Self {
        let flicker = RandomFlicker::draw(&scene, seed);
        Simulator {
            scene,
            rng: ChaCha8Rng::seed_from_u64(seed),
            reported_temp: None,
            beacon_on: true,
            report_roll: false,
            flicker,
        }
    }

    /// The attitude sensor reports roll (MODEL.md: when the trajectory
    /// has a roll column, even without the scene's `sigma_roll_deg`).
    pub fn set_report_roll(&mut self, on: bool) {
        self.report_roll = on;
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
        let fwd = pose.attitude().forward().0;
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
        let mut counts = [0u16; NDET];
        {
            // Borrow the scene and the generator apart.
            let Simulator { scene: s, rng, .. } = &mut *self;
            let gt = temperature_gain(s.temp_c);
            for k in 0..NDET {
                let mut v = volts[k];
                if let Some(n) = s.noise {
                    // Shot noise scales with the light that arrives (E_k).
                    let e = ((v - s.offset_v[k]) / (s.gain[k] * gt)).max(0.0);
                    let var = n.sigma_e_v * n.sigma_e_v + n.kappa_v * e;
                    let z: f64 = StandardNormal.sample(rng);
                    v += var.sqrt() * z;
                }
                counts[k] = volts_to_counts(v, s.adc.v_ref, s.adc.bits);
            }
        }
        let r = self.readings(pose, velocity);
        Frame {
            seq,
            t,
            adc_bits: self.scene.adc.bits,
            counts,
            temp_c: Some(r.temp_c),
            truth: Some(Truth { pose: *pose, surge }),
            attitude: r.attitude,
            depth: r.depth,
            velocity: r.velocity,
            amplitudes: None,
        }
    }

    /// The reported temperature and the vehicle's readings at `pose`,
    /// drawn in their fixed order after the frame's light.
    fn readings(&mut self, pose: &Pose, velocity: &BeamVec) -> Readings {
        let Simulator {
            scene: s,
            rng,
            reported_temp,
            report_roll,
            ..
        } = self;
        let mut normal = || -> f64 { StandardNormal.sample(rng) };
        let temp_c = match (*reported_temp, s.noise) {
            (Some(t), _) => t,
            (None, Some(n)) => s.temp_c + n.sigma_temp_c * normal(),
            (None, None) => s.temp_c,
        };
        let attitude = s.attitude.map(|a| {
            let dp = a.sigma_pitch.rad() * normal();
            let dy = a.sigma_yaw.rad() * normal();
            // Spec v3: roll is read (drawn after pitch and yaw) only when
            // the scene or the trajectory asks, so v2 draws stay v2's.
            let sigma_roll = a
                .sigma_roll
                .or(report_roll.then(|| Angle::from_deg(DEFAULT_SIGMA_ROLL_DEG)));
            let roll =
                sigma_roll.map(|sr| (pose.roll + Angle::from_rad(sr.rad() * normal())).wrapped());
            AttitudeReading {
                roll,
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
            let v = pose.attitude().to_body(velocity).0;
            let mut noisy = [0.0; 3];
            for (n, c) in noisy.iter_mut().zip(v) {
                *n = c + d.sigma_mps * normal();
            }
            VelocityReading {
                v: BodyVec(noisy),
                std: told(d.sigma_mps).then_some(BodyVec([d.sigma_mps; 3])),
            }
        });
        Readings {
            temp_c,
            attitude,
            depth,
            velocity,
        }
    }

    /// Spec v3: the N samples of every channel of the frame whose first
    /// sample is at `t_first`, into `out` (its buffer reused), the vehicle
    /// at `at(t)` for each sample's instant; the truth and the readings at
    /// the frame's middle. Noise is drawn sample by sample, channel within
    /// sample, then the readings as for a frame.
    pub fn burst(
        &mut self,
        seq: u64,
        t_first: f64,
        at: impl Fn(f64) -> Kinematics,
        out: &mut Burst,
    ) {
        let n = self.scene.adc.samples_per_frame();
        if out.n() != n {
            out.resize(n);
        }
        let sample_hz = self.scene.adc.sample_hz;
        let skew = self.scene.adc.channel_skew_s;
        for i in 0..n {
            for k in 0..NDET {
                let t = t_first + i as f64 / sample_hz + k as f64 * skew;
                let v = self.sample_volts(k, t, &at(t).pose);
                let c = volts_to_counts(v, self.scene.adc.v_ref, self.scene.adc.bits);
                out.channel_mut(k)[i] = c;
            }
        }
        let mid = t_first + (n - 1) as f64 / (2.0 * sample_hz);
        let kin = at(mid);
        let r = self.readings(&kin.pose, &kin.velocity);
        out.seq = seq;
        out.t = t_first;
        out.adc_bits = self.scene.adc.bits;
        out.temp_c = Some(r.temp_c);
        out.truth = Some(Truth {
            pose: kin.pose,
            surge: Some(kin.surge()),
        });
        out.attitude = r.attitude;
        out.depth = r.depth;
        out.velocity = r.velocity;
    }

    /// V_kji of MODEL.md for channel `k` at instant `t` and `pose`, with
    /// its noise (drawn here when the scene has noise).
    fn sample_volts(&mut self, k: usize, t: f64, pose: &Pose) -> f64 {
        let (e, a) = self.light_at(k, t, pose);
        let s = &self.scene;
        let gt = temperature_gain(s.temp_c);
        let mut v = s.gain[k] * gt * (e + a) + s.offset_v[k];
        if let Some(n) = s.noise {
            let var = n.sigma_e_v * n.sigma_e_v + n.kappa_v * (e + a).max(0.0);
            let z: f64 = StandardNormal.sample(&mut self.rng);
            v += var.sqrt() * z;
        }
        v
    }

    /// Σ_b E_kb · s_b(t) and A_k(t) at detector `k` (volts of an ideal
    /// channel, before gain): spec v3's light of one instant, noise-free.
    pub fn light_at(&self, k: usize, t: f64, pose: &Pose) -> (f64, f64) {
        let s = &self.scene;
        let att = pose.attitude();
        let n_b = att.to_beam(&s.geometry.normal(k));
        let r = s.geometry.radius_m;
        let p = pose.position();
        let pk = [
            p.0[0] + r * n_b.0[0],
            p.0[1] + r * n_b.0[1],
            p.0[2] + r * n_b.0[2],
        ];
        let mut e = 0.0;
        if self.beacon_on {
            if s.beacons.is_empty() {
                if s.blink.on(t) {
                    e += s
                        .light
                        .irradiance_at(&view(&n_b.0, &pk, &[0.0; 3], &[1.0, 0.0, 0.0]));
                }
            } else {
                for b in &s.beacons {
                    if !b.blink.on(t) {
                        continue;
                    }
                    let light = LightParams {
                        v1: b.v1,
                        sigma_b: b.sigma_b,
                        ..s.light
                    };
                    e += light.irradiance_at(&view(&n_b.0, &pk, &b.position_m, &b.axis()));
                }
            }
        }
        let a = match &s.daylight {
            None => 0.0,
            Some(d) => {
                let h = d.origin_depth_m - pk[2];
                let u = n_b.0[2];
                let shape = (1.0 - d.upwelling) * (1.0 + u) * (1.0 + u) / 4.0 + d.upwelling;
                let mut phi = self.flicker.at(k, t);
                for f in &d.flicker {
                    phi += f.amplitude
                        * (std::f64::consts::TAU * f.hz * t + f.phase_deg.to_radians()).sin();
                }
                let flick = (1.0 + (-h / d.flicker_depth_m).exp() * phi).max(0.0);
                d.surface_v * (-s.light.k_d * h).exp() * shape * flick
            }
        };
        (e, a)
    }
}

impl Simulator {
    /// One frame of counts whose first sample is at `t`, the vehicle at
    /// `at(t)`: a v2 scene's frame as [`Simulator::frame_moving`] makes it
    /// (bit for bit), a spec v3 scene of one sample per frame (daylight, a
    /// beacon's `off_s`) through the samples' path, `scratch` its buffer.
    pub fn frame_at(
        &mut self,
        seq: u64,
        t: f64,
        at: impl Fn(f64) -> Kinematics,
        scratch: &mut Burst,
    ) -> Frame {
        if self.scene.is_v2() {
            return self.frame_moving(seq, t, &at(t));
        }
        self.burst(seq, t, at, scratch);
        one_sample_frame(scratch)
    }
}

/// A burst of one sample per channel as the frame of counts it is.
pub fn one_sample_frame(b: &Burst) -> Frame {
    let mut counts = [0u16; NDET];
    for (k, c) in counts.iter_mut().enumerate() {
        *c = b.channel(k).first().copied().unwrap_or(0);
    }
    Frame {
        seq: b.seq,
        t: b.t,
        adc_bits: b.adc_bits,
        counts,
        temp_c: b.temp_c,
        truth: b.truth,
        attitude: b.attitude,
        depth: b.depth,
        velocity: b.velocity,
        amplitudes: None,
    }
}

/// What the vehicle's sensors give with a frame.
struct Readings {
    temp_c: f64,
    attitude: Option<AttitudeReading>,
    depth: Option<DepthReading>,
    velocity: Option<VelocityReading>,
}

/// d, α, β of a detector at `pk` with normal `n` (both in D) from a beacon
/// at `c` with optical axis `axis` (a unit vector): d = |p_k − c|, α the
/// angle between the axis and p_k − c, cos β = n · (c − p_k) / d.
fn view(n: &[f64; 3], pk: &[f64; 3], c: &[f64; 3], axis: &[f64; 3]) -> DetectorView {
    let rv = [pk[0] - c[0], pk[1] - c[1], pk[2] - c[2]];
    let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross_norm = |a: &[f64; 3], b: &[f64; 3]| {
        let x = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        dot(&x, &x).sqrt()
    };
    let d = dot(&rv, &rv).sqrt();
    // Through atan2, as core's views: full precision near 0 and 180°.
    let alpha = cross_norm(axis, &rv).atan2(dot(axis, &rv));
    let beta = (cross_norm(n, &rv) / d).atan2(-dot(n, &rv) / d);
    DetectorView { d, alpha, beta }
}

/// Whether a sensor's noise goes into its readings as their `std`
/// (FORMATS.md): the simulated sensor knows its σ as a real DVL reports its
/// covariance, so that a replay sees what the live estimator saw. A scene's
/// noise-free sensor (σ 0) says nothing; a std of 0 is no std a filter can
/// use, and the estimator's configured noise applies.
fn told(sigma: f64) -> bool {
    sigma > 0.0
}
