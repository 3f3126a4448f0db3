//! The water check: a tracker that holds the calibration's K_D watches
//! how well its counts fit while a DVL's readings are fused, and when they
//! stop fitting it goes on as a bank of waters that learns the water.
//!
//! Why: told nothing, a tracker takes the water to be the sweep's, and in
//! murkier water a dimmer beacon reads as a farther one (K_D 0.19 about a
//! tank's 0.09: x 1.1 m off on every frame, reported `ok`). Without a DVL
//! nothing in the frames says so: a wrong K_D is a wrong range, which the
//! state absorbs. With one, the change of range is fixed independently of
//! the light, so the brightness along the track no longer fits the
//! calibration's Beer's law, and the counts' normalized innovation squared
//! per channel, about 1 in the calibration's water, stands at 1.7–2.0 in
//! that water. The limit, its median over 25 frames above 1.7, was passed
//! on 3 of 12,000 eight-second Monte Carlo runs told the water's spread
//! (and 3 of the bench's 6,000) and on none of 400 minute-long ones
//! (docs/estimators.md, "The water check").

use std::any::Any;

use lightpose_core::{Estimator, Findings, Frame, PoseEstimate};

use super::{Tracker, WaterBank};
use crate::settings::ModelError;

/// One tracker with the water check (name `"tracker"`): itself until the
/// check fires, then a bank of waters told `water_check_doubt`, until
/// `reset`.
#[derive(Debug, Clone)]
pub struct WaterWatch {
    tracker: Tracker,
    /// The bank the check turns the tracker into, built with it (its
    /// settings checked then, nothing allocated when it fires).
    bank: WaterBank,
    /// When the check fired (s) and the window's median then; the bank
    /// runs from then on.
    fired: Option<(f64, f64)>,
}

impl WaterWatch {
    /// Whether `tracker` should be watched: the check on, and the tracker
    /// holding the calibration's K_D (a bank or a tracker estimating K_D
    /// learns the water already; `water_bank = false` keeps one tracker).
    pub fn wanted(tracker: &Tracker) -> bool {
        let c = tracker.config();
        c.water_check_frames > 0
            && c.water_bank
            && !c.estimate_k_d
            && !c.estimate_k_d_with_velocity
            && !WaterBank::wanted(tracker)
    }

    /// `tracker` watched, with the bank it turns into: its waters spread
    /// over `water_check_doubt` about the calibration's.
    pub fn new(tracker: Tracker) -> Result<Self, ModelError> {
        let doubt = tracker.config().water_check_doubt;
        let bank = WaterBank::new(&tracker.doubting(doubt)?)?;
        Ok(WaterWatch {
            tracker,
            bank,
            fired: None,
        })
    }

    /// When the check fired (s, the frame's time) and its window's median.
    pub fn fired(&self) -> Option<(f64, f64)> {
        self.fired
    }
}

/// Whether `e` has a depth or attitude reading whose check has not yet a
/// full window to judge it by: the water check waits for that verdict
/// too. Both windows span 5 s, and when a biased depth came from the start
/// the water check could fire a frame before the reading check called it:
/// the bank then took the bias for water, and x stayed 0.1 m off at 3σ
/// for 20 s after the depth's offset was learned.
fn unjudged(e: &PoseEstimate) -> bool {
    use lightpose_core::ReadingUse;
    let had = |u: ReadingUse| u != ReadingUse::Absent;
    (had(e.readings.attitude) && (e.agreement.mean[0].is_none() || e.agreement.mean[1].is_none()))
        || (had(e.readings.depth) && e.agreement.mean[2].is_none())
}

impl Estimator for WaterWatch {
    fn name(&self) -> &'static str {
        Tracker::NAME
    }
    fn std_with_every_ok_pose(&self) -> bool {
        true
    }

    fn estimate(&mut self, frame: &Frame) -> PoseEstimate {
        if self.fired.is_some() {
            return self.bank.estimate(frame);
        }
        let e = self.tracker.estimate(frame);
        let Some(median) = self.tracker.water_misfit() else {
            return e;
        };
        // A reading the light disagrees with (the reading check's suspect:
        // a depth sensor biased from mid-run) explains the misfit as well
        // as another water does, and a bank that learns the water then
        // takes the bias into range for good: a depth 0.3 m off, switched
        // on mid-run, left the harbour's track 2.3 m short with K_D learned
        // at 0.9 (true 0.2), `out_of_range` to the end.
        if e.agreement.suspect != 0 || unjudged(&e) {
            return e;
        }
        // The bank starts from this frame: its members, each in its own
        // water, fit the start afresh (`initialising` for a second), since
        // the tracker's state is the wrong water's.
        self.fired = Some((frame.t, median));
        self.bank.reset();
        self.bank.inherit_checks(&self.tracker);
        self.bank.estimate(frame)
    }

    fn reset(&mut self) {
        self.tracker.reset();
        self.bank.reset();
        self.fired = None;
    }

    fn findings(&self) -> Option<Findings> {
        match self.fired {
            Some(_) => self.bank.findings(),
            None => self.tracker.findings(),
        }
    }

    /// The tracker's, which the bank takes over when the check fires.
    fn take_findings(&mut self, found: &(dyn Any + Send)) {
        self.tracker.take_findings(found);
    }

    fn water_k_d(&self) -> Option<f64> {
        match self.fired {
            Some(_) => self.bank.water_k_d(),
            None => self.tracker.water_k_d(),
        }
    }

    fn depth_offset(&self) -> Option<(f64, f64)> {
        match self.fired {
            Some(_) => self.bank.depth_offset(),
            None => self.tracker.depth_offset(),
        }
    }

    fn pitch_offset_deg(&self) -> Option<(f64, f64)> {
        match self.fired {
            Some(_) => self.bank.pitch_offset_deg(),
            None => self.tracker.pitch_offset_deg(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::testutil::{synth_frame, Rng};
    use crate::model::SensorModel;
    use crate::settings::TrackerConfig;
    use lightpose_core::{Angle, Attitude, BeamVec, DepthReading, Pose, Status, VelocityReading};

    /// The tank's calibration and the tracker `auto` builds from it, told
    /// nothing about the water.
    fn tank() -> (SensorModel, Tracker) {
        super::super::tests::tank_tracker(TrackerConfig::default())
    }

    /// A minute of coming and going between 4 and 6 m, smoothly (a DVL
    /// would not believe a reversal at once), in `water` (300
    /// frames at 5 Hz), with the attitude sensor, and depth and the DVL
    /// when `dvl`, MODEL.md's noise: per `ok` frame its time, x's error
    /// and σ.
    fn a_minute(
        est: &mut dyn Estimator,
        water: &SensorModel,
        dvl: bool,
        seed: u64,
    ) -> Vec<(f64, f64, f64)> {
        let w = std::f64::consts::PI / 10.0;
        let (pitch, yaw) = (Angle::from_deg(2.0), Angle::from_deg(-3.0));
        let mut rng = Rng::new(seed);
        let mut out = Vec::new();
        est.reset();
        for i in 0..300u64 {
            let t = i as f64 * 0.2;
            let pose = Pose::new(5.0 + (w * t).cos(), 0.1, 0.1, pitch, yaw);
            let vx = -w * (w * t).sin();
            let att = Some((0.3f64.to_radians(), 1.5f64.to_radians()));
            let mut f = synth_frame(water, &pose, i, t, att, &mut rng);
            if dvl {
                let v = Attitude::new(pitch, yaw)
                    .to_body(&BeamVec([vx, 0.0, 0.0]))
                    .0;
                let n = |r: &mut Rng| 0.02 * r.normal();
                f.velocity = Some(VelocityReading::new(
                    v[0] + n(&mut rng),
                    v[1] + n(&mut rng),
                    v[2] + n(&mut rng),
                ));
                f.depth = Some(DepthReading::new(pose.z + n(&mut rng)));
            }
            let e = est.estimate(&f);
            if let (Status::Ok, Some(x), Some(sx)) = (e.status, e.x, e.std.x) {
                out.push((t, x - pose.x, sx));
            }
        }
        out
    }

    /// Untold, water of K_D 0.19 about the tank's 0.09 put x 1.1 m off,
    /// reported `ok`, over the whole minute (one tracker, all three
    /// sensors: 295 of 295 `ok` frames beyond 3σ). With the check the
    /// tracker turns into a bank once its window is full and learns the
    /// water. Measured: fired at 6.0–7.2 s (median 1.76–1.97), then x
    /// beyond 3σ on none of 254–260 frames, x RMS 0.030–0.054 m, K_D
    /// 0.190–0.192 learned.
    #[test]
    fn with_a_dvl_the_check_finds_water_it_was_not_told() {
        let (calibrated, tracker) = tank();
        assert!(WaterWatch::wanted(&tracker));
        let mut water = calibrated.clone();
        water.light.k_d += 0.1;
        let mut one = tracker.clone();
        let mut watch = WaterWatch::new(tracker).unwrap();
        for seed in 40..43 {
            let untold = a_minute(&mut one, &water, true, seed);
            let off = untold.iter().filter(|(_, e, s)| e.abs() > 3.0 * s).count();
            let got = a_minute(&mut watch, &water, true, seed);
            let (t, median) = watch.fired().expect("the check fired");
            // The frames from two seconds after it fired (the bank's start).
            let after: Vec<_> = got.iter().filter(|(ti, _, _)| *ti >= t + 2.0).collect();
            let beyond = after.iter().filter(|(_, e, s)| e.abs() > 3.0 * s).count();
            // The bank starts afresh: `initialising`, not `ok`, for its
            // first second, so the autopilot's `reset_counter` steps
            // (the pose jumps by a metre) instead of the jump being fused.
            let restart = got.iter().filter(|(ti, _, _)| (t..t + 0.7).contains(ti));
            assert_eq!(restart.count(), 0, "an ok pose right after the switch");
            let rms =
                (after.iter().map(|(_, e, _)| e * e).sum::<f64>() / after.len() as f64).sqrt();
            let k = watch.water_k_d().expect("the bank's water");
            eprintln!(
                "seed {seed}: untold {off} of {} beyond 3σ; fired at {t:.1} s (median {median:.2}), \
                 then {beyond} of {} beyond 3σ, x RMS {rms:.3} m, K_D {k:.3}",
                untold.len(),
                after.len()
            );
            assert!(off * 2 > untold.len(), "untold: the check's reason is gone");
            assert!(t <= 10.0, "fired only at {t} s");
            assert!(after.len() >= 200 && beyond * 100 <= after.len());
            assert!(rms < 0.15, "x RMS {rms}");
            assert!((k / water.light.k_d - 1.0).abs() < 0.1, "K_D {k}");
        }
    }

    /// In the calibration's own water the check stays quiet (the counts fit:
    /// its window's median is about 1), and without a DVL it never fires: a
    /// wrong K_D is then a wrong range, which nothing in the frames
    /// contradicts (docs/extremes.md).
    #[test]
    fn the_check_is_quiet_in_the_calibrated_water_and_without_a_dvl() {
        let (calibrated, tracker) = tank();
        let mut watch = WaterWatch::new(tracker).unwrap();
        let mut murky = calibrated.clone();
        murky.light.k_d += 0.1;
        for seed in 50..53 {
            let n = a_minute(&mut watch, &calibrated, true, seed).len();
            assert!(
                n > 250 && watch.fired().is_none(),
                "seed {seed}: {:?}",
                watch.fired()
            );
            assert_eq!(watch.water_k_d(), None);
            a_minute(&mut watch, &murky, false, seed);
            assert!(
                watch.fired().is_none(),
                "no DVL, seed {seed}: {:?}",
                watch.fired()
            );
        }
        // Off, or with K_D learned some other way, there is nothing to watch.
        let (_, t) = tank();
        for cfg in [
            TrackerConfig {
                water_check_frames: 0,
                ..t.config().clone()
            },
            TrackerConfig {
                estimate_k_d_with_velocity: true,
                ..t.config().clone()
            },
            TrackerConfig {
                water_bank: false,
                ..t.config().clone()
            },
            TrackerConfig {
                k_d_sigma: Some(0.3),
                ..t.config().clone()
            },
        ] {
            let tr = Tracker::new(calibrated.clone(), cfg).unwrap();
            assert!(!WaterWatch::wanted(&tr), "{:?}", tr.config());
        }
    }

    /// The water check waits while a reading the frame has has no full
    /// window in the reading check yet, and not for one it does not have.
    #[test]
    fn the_water_check_waits_for_the_reading_check() {
        use lightpose_core::ReadingUse;
        let mut e = PoseEstimate::empty(0, 0.0, Status::Ok, "tracker");
        assert!(!unjudged(&e), "no readings: nothing to wait for");
        e.readings.depth = ReadingUse::Used;
        assert!(unjudged(&e), "depth, its window not full");
        e.agreement.mean[2] = Some(0.1);
        assert!(!unjudged(&e));
        e.readings.attitude = ReadingUse::Used;
        e.agreement.mean[0] = Some(0.0);
        assert!(unjudged(&e), "yaw's window not full");
        e.agreement.mean[1] = Some(0.0);
        assert!(!unjudged(&e));
        e.agreement.mean[2] = None;
        e.readings.depth = ReadingUse::Absent;
        assert!(!unjudged(&e), "no depth this frame");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(32))]
        /// Frames of a vehicle coming in (so that the tracker starts and
        /// the watch, set to fire on any misfit after two frames, turns
        /// into the bank), with garbage spliced in: counts, time steps and
        /// DVL readings of any size. No NaN and no panic, before or after.
        #[test]
        fn any_frames_through_the_watch_give_no_nan(
            seed in 0u64..1000,
            garbage in proptest::collection::vec(
                (proptest::option::of(proptest::array::uniform25(0u16..=1023)),
                 0.0f64..0.5, -10.0f64..10.0), 10..40),
        ) {
            let m = SensorModel::default();
            let cfg = TrackerConfig {
                water_check_frames: 2,
                water_check_nis: 1.0001,
                ..TrackerConfig::default()
            };
            let mut watch = WaterWatch::new(Tracker::new(m.clone(), cfg).unwrap()).unwrap();
            let mut rng = Rng::new(seed);
            let mut t = 0.0;
            for (i, (counts, dt, v)) in garbage.into_iter().enumerate() {
                t += dt;
                let pose = Pose::new(6.0 - 0.3 * t, 0.1, 0.1, Angle::ZERO, Angle::ZERO);
                let mut f = synth_frame(&m, &pose, i as u64, t, Some((0.005, 0.03)), &mut rng);
                if let Some(c) = counts.filter(|_| i % 4 == 3) {
                    f.counts = c;
                }
                let u = if i % 5 == 4 { v } else { 0.3 };
                f.velocity = Some(VelocityReading::new(u, 0.0, 0.0));
                f.depth = Some(DepthReading::new(0.1));
                let e = watch.estimate(&f);
                for x in [e.x, e.y, e.z, e.pitch_deg, e.yaw_deg, e.surge,
                          e.std.x, e.std.y, e.std.z, e.std.pitch, e.std.yaw, e.std.surge] {
                    proptest::prop_assert!(x.is_none_or(|x| x.is_finite()));
                }
                if let Some(k) = watch.water_k_d() {
                    proptest::prop_assert!(k.is_finite() && k > 0.0);
                }
            }
        }
    }
}
