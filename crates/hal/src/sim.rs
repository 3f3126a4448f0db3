//! The simulator as a source (kinds `sim` and `mock`): frames from the
//! simulator, flown along a trajectory, through the same [`FrameSource`]
//! trait as the boards, so that the daemon runs unchanged without hardware;
//! plus injected faults (bus errors, dropped frames, stuck channels) for
//! robustness tests of the daemon.
//!
//! Time: frame k has `t` = k / rate (k counting dropped and failed frames,
//! since a board's clock runs on through them too), the time a paced board
//! would stamp, and it samples the trajectory at t0 + t (modulo its length
//! when looping). Free-running (`rate_hz = 0`) uses the scene's ADC rate
//! for `t`, so that the trajectory is flown at its speed in simulated time.

use std::time::Duration;

use lightpose_core::frame::full_scale;
use lightpose_core::{Frame, NDET};
use lightpose_sim::{Scene, SceneError, Simulator, Trajectory};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::config::{Faults, Pace, SimPlan};
use crate::pace::{Pacer, Stop};
use crate::text::Text;
use crate::{FrameSource, HalError, Sampling, SourceError, SourceHealth, Take};
use lightpose_core::samples::Burst;

/// The simulator as a frame source.
pub struct SimSource {
    sim: Simulator,
    traj: Trajectory,
    looping: bool,
    /// Seconds of simulated time per frame, and its inverse as configured.
    dt: f64,
    clock_hz: f64,
    /// Frames in one pass of the trajectory; a loop starts again at the
    /// same frame times, so every pass samples exactly the same poses.
    per_pass: u64,
    pacer: Pacer,
    faults: Faults,
    rng: ChaCha8Rng,
    seq: u64,
    injected: u64,
    describe: String,
    /// The scene is v3 (its frames are made as bursts, of one sample
    /// when it samples no faster than its frames).
    v3: bool,
    /// `Some` when the scene takes N > 1 samples a frame: the source
    /// gives bursts.
    sampling: Option<Sampling>,
    /// A burst of one sample for a v3 scene's frames, reused.
    one: Burst,
}

impl SimSource {
    /// `rate_hz = None`: as fast as possible.
    pub fn new(
        sim: Simulator,
        traj: Trajectory,
        rate_hz: Option<f64>,
        looping: bool,
        faults: Faults,
    ) -> Self {
        let nominal = rate_hz.unwrap_or(sim.scene().adc.rate_hz);
        let clock_hz = if nominal.is_finite() && nominal > 0.0 {
            nominal
        } else {
            5.0
        };
        let dt = 1.0 / clock_hz;
        let describe = format!(
            "simulator ({}-bit, {}, {} s trajectory{}){}",
            sim.scene().adc.bits,
            match rate_hz {
                Some(r) => format!("{r:.2} Hz"),
                None => "free-running".into(),
            },
            traj.t_end() - traj.t0(),
            if looping { ", looping" } else { "" },
            if faults == Faults::default() {
                ""
            } else {
                " with injected faults"
            },
        );
        let scene = sim.scene();
        let n = scene.adc.samples_per_frame();
        // A frame while its middle is within the trajectory (MODEL.md): with
        // one sample, its instant.
        let per_pass = if n > 1 {
            traj.burst_count(1.0 / dt, n, scene.adc.sample_hz)
        } else {
            traj.frame_count(1.0 / dt)
        }
        .max(1);
        let sampling = (n > 1).then(|| Sampling {
            sample_hz: scene.adc.sample_hz,
            samples_per_frame: n,
            channel_skew_s: scene.adc.channel_skew_s,
            beacons: scene.beacon_infos(),
        });
        let v3 = !scene.is_v2();
        let mut sim = sim;
        // As `lightpose simulate`: an AHRS reports roll when the
        // trajectory has a roll column.
        sim.set_report_roll(traj.has_roll());
        SimSource {
            v3,
            sampling,
            one: Burst::new(1),
            per_pass,
            rng: ChaCha8Rng::seed_from_u64(faults.seed),
            sim,
            traj,
            looping,
            dt,
            clock_hz,
            pacer: Pacer::from_rate(rate_hz),
            faults,
            seq: 0,
            injected: 0,
            describe,
        }
    }

    /// Open what `plan` describes: read and parse its scene (or take the
    /// default tank) and trajectory; waits end early on `stop`.
    pub fn open(plan: &SimPlan, stop: &Stop) -> Result<Self, HalError> {
        let scene = match &plan.scene {
            Some(src) => {
                let text = src.read().map_err(SceneError::from)?;
                Scene::parse(&text, &src.describe())?
            }
            None => Scene::default(),
        };
        let traj = Trajectory::from_source(&plan.trajectory)?;
        let bits = scene.adc.bits;
        let n = scene.adc.samples_per_frame();
        if let Some(r) = plan
            .rate_hz
            .filter(|&r| n > 1 && (r - scene.adc.rate_hz).abs() > 1e-9 * r)
        {
            return Err(HalError::Config {
                key: "rate_hz".into(),
                msg: format!(
                    "{r} Hz, but the scene's frames are {} Hz ({n} samples at sample_hz = {} Hz): a burst's samples are the scene's",
                    scene.adc.rate_hz, scene.adc.sample_hz
                ),
            });
        }
        if let Some(&(_, v)) = plan.faults.stuck.iter().find(|s| s.1 > full_scale(bits)) {
            return Err(HalError::Config {
                key: "faults.stuck".into(),
                msg: format!("value {v} exceeds the scene's {bits}-bit full scale"),
            });
        }
        let mut src = Self::new(
            Simulator::new(scene, plan.seed),
            traj,
            plan.rate_hz,
            plan.looping,
            plan.faults.clone(),
        );
        src.pacer = src.pacer.clone().stoppable(stop.clone());
        Ok(match plan.pace {
            Pace::Realtime => src,
            Pace::Fast => src.free_running(),
        })
    }

    /// Keep the frame times of the configured rate but hand frames out as
    /// fast as they are asked for (benchmarks, soak tests).
    pub fn free_running(mut self) -> Self {
        self.pacer = Pacer::new(None);
        self.describe.push_str(", as fast as possible");
        self
    }

    fn hit(&mut self, every: Option<u64>, prob: f64, seq: u64) -> bool {
        let periodic = every.is_some_and(|n| (seq + 1).checked_rem(n) == Some(0));
        // draw every frame so that the fault sequence depends only on seq
        let random = prob > 0.0 && self.rng.gen::<f64>() < prob;
        periodic || random
    }
}

/// A frame's place in simulated time: its seq, its `t` (a burst's: its
/// first sample's) and the trajectory's time it samples.
struct Slot {
    seq: u64,
    t: f64,
    tt: f64,
}

impl SimSource {
    /// The next frame's slot after its pacing, or the fault that took it
    /// (a dropped frame is passed over here, as a board's would be).
    fn next_slot(&mut self) -> Result<Slot, SourceError> {
        loop {
            let seq = self.seq;
            let t = seq as f64 * self.dt;
            let in_pass = if seq < self.per_pass {
                seq
            } else if self.looping {
                seq % self.per_pass
            } else {
                return Err(SourceError::Ended);
            };
            let tt = self.traj.t0() + in_pass as f64 * self.dt;
            self.pacer.wait();
            self.seq += 1;
            let (fe, fp) = (self.faults.drop_every, self.faults.drop_prob);
            if self.hit(fe, fp, seq) {
                // a lost frame: its seq is skipped, as a board's would be
                self.injected += 1;
                continue;
            }
            let (be, bp) = (self.faults.bus_error_every, self.faults.bus_error_prob);
            if self.hit(be, bp, seq) {
                self.injected += 1;
                let k = (seq % NDET as u64) as usize;
                // Kept inline (no allocation) up to frame 10^15.
                return Err(SourceError::Bus {
                    place: Text::format(format_args!(
                        "sim board channel {k} (injected, frame {seq})"
                    )),
                    msg: Text::from_static("injected fault"),
                });
            }
            return Ok(Slot { seq, t, tt });
        }
    }

    /// The readings' injected faults: a DVL turned, a depth and a pitch
    /// off by a constant.
    fn fault_readings(
        &self,
        velocity: &mut Option<lightpose_core::VelocityReading>,
        depth: &mut Option<lightpose_core::DepthReading>,
        attitude: &mut Option<lightpose_core::AttitudeReading>,
    ) {
        if let Some(r) = velocity.as_mut().filter(|_| self.faults.dvl_turned != 0.0) {
            // Its axes turned to starboard: a forward motion reads
            // partly to the right, each component's std with its axis.
            let (s, c) = self.faults.dvl_turned.sin_cos();
            let [fwd, right, down] = r.v.0;
            r.v.0 = [c * fwd - s * right, s * fwd + c * right, down];
            if let Some(sd) = r.std.as_mut() {
                let [f, ri, d] = sd.0;
                let turn = |a: f64, b: f64| (c * c * a * a + s * s * b * b).sqrt();
                sd.0 = [turn(f, ri), turn(ri, f), d];
            }
        }
        if let Some(d) = depth.as_mut() {
            d.z += self.faults.depth_bias;
        }
        if let Some(a) = attitude.as_mut() {
            a.pitch = lightpose_core::Angle::from_rad(a.pitch.rad() + self.faults.pitch_bias);
        }
    }

    /// The burst of `slot` into `out`: the vehicle flown through the
    /// frame's samples, trajectory time `tt` at its first.
    fn burst_of(&mut self, slot: &Slot, out: &mut Burst) {
        let (traj, off) = (&self.traj, slot.tt - slot.t);
        // As `lightpose simulate`: the trajectory at each sample's instant
        // (a frame's last samples may run past its end, where it holds).
        self.sim
            .burst(slot.seq, slot.t, |s| traj.kinematics(s + off), out);
    }
}

impl FrameSource for SimSource {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        if self.sampling.is_some() {
            return Err(crate::bursts_only("sim"));
        }
        let slot = self.next_slot()?;
        let mut f = if self.v3 {
            // A v3 scene of one sample a frame (daylight, beacons, roll):
            // the simulator's burst of one, as `lightpose simulate` does.
            let mut one = std::mem::take(&mut self.one);
            self.burst_of(&slot, &mut one);
            let f = lightpose_sim::simulator::one_sample_frame(&one);
            self.one = one;
            f
        } else {
            self.sim
                .frame_moving(slot.seq, slot.t, &self.traj.kinematics(slot.tt))
        };
        for &(k, v) in &self.faults.stuck {
            f.counts[k] = v;
        }
        let (mut vel, mut dep, mut att) = (f.velocity, f.depth, f.attitude);
        self.fault_readings(&mut vel, &mut dep, &mut att);
        (f.velocity, f.depth, f.attitude) = (vel, dep, att);
        Ok(f)
    }
    fn sampling(&self) -> Option<Sampling> {
        self.sampling.clone()
    }
    fn next_take(&mut self, burst: &mut Burst) -> Result<Take, SourceError> {
        if self.sampling.is_none() {
            return self.next_frame().map(Take::Frame);
        }
        let slot = self.next_slot()?;
        self.burst_of(&slot, burst);
        for &(k, v) in &self.faults.stuck {
            burst.channel_mut(k).fill(v);
        }
        let (mut vel, mut dep, mut att) = (burst.velocity, burst.depth, burst.attitude);
        self.fault_readings(&mut vel, &mut dep, &mut att);
        (burst.velocity, burst.depth, burst.attitude) = (vel, dep, att);
        Ok(Take::Burst)
    }
    fn adc_bits(&self) -> u8 {
        self.sim.scene().adc.bits
    }
    fn describe(&self) -> String {
        self.describe.clone()
    }
    fn period(&self) -> Option<Duration> {
        self.pacer.period()
    }
    fn rate_hz(&self) -> Option<f64> {
        Some(self.clock_hz)
    }
    fn health(&self) -> SourceHealth {
        SourceHealth {
            injected_faults: self.injected,
            ..SourceHealth::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::Angle;
    use lightpose_sim::trajectory::Knot;

    fn traj() -> Trajectory {
        let k = |t: f64, x: f64| Knot {
            t,
            pose: lightpose_core::Pose::new(x, 0.0, 0.1, Angle::ZERO, Angle::ZERO),
        };
        Trajectory::from_knots(vec![k(0.0, 8.0), k(1.0, 7.0), k(2.0, 6.0)])
    }

    fn src(looping: bool, faults: Faults) -> SimSource {
        src_in(Scene::default(), looping, faults)
    }

    /// The source over `traj()` in `scene`, seed 7.
    fn src_in(scene: Scene, looping: bool, faults: Faults) -> SimSource {
        SimSource::new(Simulator::new(scene, 7), traj(), None, looping, faults)
    }

    #[test]
    fn gives_simulator_frames_with_truth_and_ends_or_loops() {
        let mut s = src(false, Faults::default());
        let bits = s.adc_bits();
        let dt = s.dt;
        let mut n = 0;
        let mut last = None;
        loop {
            match s.next_frame() {
                Ok(f) => {
                    assert_eq!(f.seq, n);
                    assert!((f.t - n as f64 * dt).abs() < 1e-12);
                    assert_eq!(f.adc_bits, bits);
                    let truth = f.truth.expect("sim frames carry truth");
                    assert!(truth.pose.x <= 8.0 + 1e-9 && truth.pose.x >= 6.0 - 1e-9);
                    assert!(
                        f.counts.iter().any(|&c| c > 0),
                        "beacon at 6-8 m must be seen"
                    );
                    last = Some(f);
                    n += 1;
                }
                Err(SourceError::Ended) => break,
                Err(e) => panic!("{e}"),
            }
            assert!(n < 10_000);
        }
        assert_eq!(n, (2.0 / dt).floor() as u64 + 1);
        assert!((last.unwrap().truth.unwrap().pose.x - 6.0).abs() < 0.1);

        let mut l = src(true, Faults::default());
        for _ in 0..(3 * n) {
            let f = l.next_frame().unwrap();
            let x = f.truth.unwrap().pose.x;
            assert!((6.0 - 1e-9..=8.0 + 1e-9).contains(&x));
        }
    }

    #[test]
    fn injects_bus_errors_drops_and_stuck_channels() {
        let faults = Faults {
            bus_error_every: Some(5),
            drop_every: Some(7),
            stuck: vec![(12, 999)],
            ..Faults::default()
        };
        let mut s = src(true, faults);
        let mut seqs = Vec::new();
        let mut errors = 0;
        for _ in 0..30 {
            match s.next_frame() {
                Ok(f) => {
                    assert_eq!(f.counts[12], 999);
                    seqs.push(f.seq);
                }
                Err(SourceError::Bus { place, .. }) => {
                    assert!(place.contains("injected"), "{place}");
                    errors += 1;
                }
                Err(e) => panic!("{e}"),
            }
        }
        // seq 6, 13, 20, ... dropped; 4, 9, 14, ... bus errors
        assert!(!seqs.contains(&6) && !seqs.contains(&13));
        assert!(!seqs.contains(&4) && !seqs.contains(&9));
        assert!(seqs.contains(&5) && seqs.contains(&7));
        assert!(errors >= 5);
        let drops = (0..s.seq).filter(|q| (q + 1) % 7 == 0).count() as u64;
        assert!(drops >= 4);
        assert_eq!(s.health().injected_faults, errors + drops);
    }

    /// A DVL mounted backwards (turned 180°) reads the velocity negated,
    /// down unchanged; turned 90° (to starboard), forward motion reads to
    /// the right.
    #[test]
    fn a_turned_dvl_reads_the_velocity_turned() {
        let scene = Scene {
            dvl: Some(lightpose_sim::DvlNoise { sigma_mps: 0.0 }),
            ..Scene::default()
        };
        let frame = |deg: f64| {
            let faults = Faults {
                dvl_turned: deg.to_radians(),
                ..Faults::default()
            };
            let mut s = src_in(scene.clone(), false, faults);
            s.next_frame().unwrap().velocity.expect("a DVL reading").v.0
        };
        let (v, back, across) = (frame(0.0), frame(180.0), frame(90.0));
        assert!(v[0] > 0.5, "{v:?}");
        for k in 0..2 {
            assert!((back[k] + v[k]).abs() < 1e-9, "{back:?} {v:?}");
        }
        assert!((back[2] - v[2]).abs() < 1e-12);
        assert!((across[1] - v[0]).abs() < 1e-9 && (across[0] + v[1]).abs() < 1e-9);
    }

    /// A depth sensor and an AHRS off by a constant read their truth plus
    /// the bias, the rest of the frame untouched.
    #[test]
    fn biased_depth_and_pitch_read_biased() {
        let scene = Scene {
            attitude: Some(lightpose_sim::AttitudeNoise {
                sigma_pitch: lightpose_core::Angle::from_deg(0.0),
                sigma_yaw: lightpose_core::Angle::from_deg(0.0),
                sigma_roll: None,
            }),
            depth: Some(lightpose_sim::DepthNoise { sigma_m: 0.0 }),
            ..Scene::default()
        };
        let frame = |depth_bias: f64, pitch_bias_deg: f64| {
            let faults = Faults {
                depth_bias,
                pitch_bias: pitch_bias_deg.to_radians(),
                ..Faults::default()
            };
            src_in(scene.clone(), false, faults).next_frame().unwrap()
        };
        let (clean, biased) = (frame(0.0, 0.0), frame(0.1, 2.0));
        let d = |f: &lightpose_core::Frame| f.depth.expect("a depth reading").z;
        let a = |f: &lightpose_core::Frame| f.attitude.expect("an attitude reading");
        assert!((d(&biased) - d(&clean) - 0.1).abs() < 1e-12);
        assert!((a(&biased).pitch.deg() - a(&clean).pitch.deg() - 2.0).abs() < 1e-9);
        assert_eq!(a(&biased).yaw, a(&clean).yaw);
        assert_eq!(biased.counts, clean.counts);
    }

    #[test]
    fn random_faults_follow_their_probability_and_seed() {
        let f = Faults {
            bus_error_prob: 0.2,
            seed: 3,
            ..Faults::default()
        };
        let run = |f: Faults| -> Vec<bool> {
            let mut s = src(true, f);
            (0..500).map(|_| s.next_frame().is_err()).collect()
        };
        let a = run(f.clone());
        assert_eq!(a, run(f));
        let rate = a.iter().filter(|&&e| e).count() as f64 / 500.0;
        assert!((rate - 0.2).abs() < 0.06, "{rate}");
    }

    /// Issue 16: a trajectory of absurd length (two knots 1e9 s apart,
    /// 5e9 frames a pass) opens at once: frames are made as they are
    /// asked for, never counted or held.
    #[test]
    fn a_trajectory_of_absurd_length_opens_at_once() {
        let k = |t: f64, x: f64| Knot {
            t,
            pose: lightpose_core::Pose::new(x, 0.0, 0.1, Angle::ZERO, Angle::ZERO),
        };
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let far = Trajectory::from_knots(vec![k(0.0, 8.0), k(1e9, 7.0)]);
            let mut s = SimSource::new(
                Simulator::new(Scene::default(), 7),
                far,
                Some(5.0),
                true,
                Faults::default(),
            );
            let _ = tx.send((s.per_pass, s.next_frame().is_ok()));
        });
        let got = rx.recv_timeout(std::time::Duration::from_secs(5));
        assert_eq!(got.ok(), Some((5_000_000_001, true)));
    }

    /// The harbour by day, blinking at 250 Hz and sampled at 2 kHz.
    fn day() -> Scene {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/scenes/harbour-day.toml");
        Scene::load(&p).expect("config/scenes/harbour-day.toml")
    }

    /// Spec v3: a scene that samples faster than its frames gives bursts,
    /// each the simulator's own for that frame (the same seed, the same
    /// samples), its readings faulted as a frame's; `next_frame` refuses.
    #[test]
    fn a_sampling_scene_gives_the_simulators_bursts() {
        let faults = Faults {
            stuck: vec![(3, 77)],
            bus_error_every: Some(4),
            ..Faults::default()
        };
        let mut s = src_in(day(), false, faults);
        let sampling = s.sampling().expect("bursts");
        assert_eq!(sampling.samples_per_frame, 400);
        assert_eq!(sampling.sample_hz, 2000.0);
        assert_eq!(sampling.channel_skew_s, 2e-5);
        assert_eq!(sampling.beacons.len(), 1);
        assert_eq!(sampling.beacons[0].mod_hz, 250.0);
        assert!(matches!(s.next_frame(), Err(SourceError::BadData { .. })));

        let mut s = src_in(day(), false, Faults::default());
        let mut direct = Simulator::new(day(), 7);
        let (mut got, mut want) = (Burst::new(1), Burst::new(400));
        for seq in 0..3u64 {
            assert_eq!(s.next_take(&mut got).expect("a burst"), Take::Burst);
            let t = seq as f64 / 5.0;
            direct.burst(seq, t, |u| traj().kinematics(u), &mut want);
            assert_eq!(got, want, "frame {seq}");
        }
        // traj() is 2 s: frames while their middle is within it.
        let mut n = 3;
        while s.next_take(&mut got).is_ok() {
            n += 1;
        }
        assert_eq!(n, 10);

        let faults = Faults {
            stuck: vec![(3, 77)],
            bus_error_every: Some(4),
            ..Faults::default()
        };
        let mut s = src_in(day(), true, faults);
        let mut errors = 0;
        for _ in 0..12 {
            match s.next_take(&mut got) {
                Ok(Take::Burst) => assert!(got.channel(3).iter().all(|&c| c == 77)),
                Ok(Take::Frame(_)) => panic!("a frame from a source of bursts"),
                Err(SourceError::Bus { .. }) => errors += 1,
                Err(e) => panic!("{e}"),
            }
        }
        assert_eq!(errors, 3);
        assert_eq!(s.health().injected_faults, 3);
    }
}
