//! The calibration sweeps of MODEL.md (paper section 2.2.1): the
//! translation grid, the orientation fans at three ranges, and dark frames
//! with the beacon off. Every lit frame carries its true pose.

use crate::simulator::one_sample_frame;
use crate::{Kinematics, Scene, Simulator};
use lightpose_core::{Angle, BeamVec, Burst, Frame, LogWriter, Pose};
use std::io::Write;

/// Which sweep to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SweepKind {
    Translation,
    Orientation,
    /// Beacon off (V1 = 0), for each channel's dark offset.
    Dark,
    /// Translation then orientation: the 125 + 183 lit poses.
    All,
}

impl SweepKind {
    pub fn parse(s: &str) -> Option<SweepKind> {
        match s {
            "translation" => Some(SweepKind::Translation),
            "orientation" => Some(SweepKind::Orientation),
            "dark" => Some(SweepKind::Dark),
            "all" => Some(SweepKind::All),
            _ => None,
        }
    }
    pub fn as_str(self) -> &'static str {
        match self {
            SweepKind::Translation => "translation",
            SweepKind::Orientation => "orientation",
            SweepKind::Dark => "dark",
            SweepKind::All => "all",
        }
    }
}

/// x = 4.5..8.5 step 1, y = −0.6..0.6 step 0.3, z = 0..0.8 step 0.2: 125.
pub fn translation_poses() -> Vec<Pose> {
    let mut v = Vec::with_capacity(125);
    for i in 0..5 {
        for j in 0..5i32 {
            for k in 0..5i32 {
                // Tenths as integers, so that a truth label reads 0.3,
                // not 0.29999999999999993 (n / 10.0 rounds as the literal).
                let x = 4.5 + f64::from(i);
                let y = f64::from(3 * j - 6) / 10.0;
                let z = f64::from(2 * k) / 10.0;
                v.push(Pose::new(x, y, z, Angle::ZERO, Angle::ZERO));
            }
        }
    }
    v
}

/// Pitch and yaw each −15..15° step 1° with the other 0, (0, 0) once, at
/// x = 4.5, 6.5 and 8.5 m: 61 poses per range, 183 in all.
pub fn orientation_poses() -> Vec<Pose> {
    let mut v = Vec::with_capacity(183);
    for x in [4.5, 6.5, 8.5] {
        v.push(Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO));
        for d in -15..=15 {
            if d != 0 {
                v.push(Pose::new(
                    x,
                    0.0,
                    0.0,
                    Angle::from_deg(d as f64),
                    Angle::ZERO,
                ));
            }
        }
        for d in -15..=15 {
            if d != 0 {
                v.push(Pose::new(
                    x,
                    0.0,
                    0.0,
                    Angle::ZERO,
                    Angle::from_deg(d as f64),
                ));
            }
        }
    }
    v
}

/// Spec v3: a docking station's translation grid, x = 1.5, 2.5, 3.5,
/// 5, 6.5, 8 m, y and z = −0.6..0.6 step 0.3 (150 poses). Why its own: the
/// single beacon's grid (4.5–8.5 m, z ≥ 0 by the beam's symmetry) misses
/// the last metres of an approach, where a station is used most, and a
/// station is not symmetric in z.
pub fn station_translation_poses() -> Vec<Pose> {
    let mut v = Vec::with_capacity(150);
    for x in [15, 25, 35, 50, 65, 80] {
        for j in -2..=2i32 {
            for k in -2..=2i32 {
                let (y, z) = (f64::from(3 * j) / 10.0, f64::from(3 * k) / 10.0);
                v.push(Pose::new(
                    f64::from(x) / 10.0,
                    y,
                    z,
                    Angle::ZERO,
                    Angle::ZERO,
                ));
            }
        }
    }
    v
}

/// Spec v3: a station's orientation fans, pitch, yaw and roll each
/// −15..15° step 3° with the others 0, (0, 0, 0) once, at x = 2, 4 and
/// 6 m: 31 poses per range, 93 in all. Roll is in them because a station
/// sees it (the truth of a sweep must span what the calibration serves).
pub fn station_orientation_poses() -> Vec<Pose> {
    let mut v = Vec::with_capacity(93);
    for x in [2.0, 4.0, 6.0] {
        v.push(Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO));
        for axis in 0..3 {
            for d in (-15..=15).step_by(3).filter(|d| *d != 0) {
                let a = Angle::from_deg(f64::from(d));
                let mut p = Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO);
                match axis {
                    0 => p.pitch = a,
                    1 => p.yaw = a,
                    _ => p.roll = a,
                }
                v.push(p);
            }
        }
    }
    v
}

/// What a sweep will write.
#[derive(Debug, Clone)]
pub struct SweepPlan {
    pub kind: SweepKind,
    pub samples: u32,
    /// Lit poses in order (empty for a dark sweep).
    pub poses: Vec<Pose>,
}

impl SweepPlan {
    pub fn new(kind: SweepKind, samples: u32) -> Self {
        let poses = match kind {
            SweepKind::Translation => translation_poses(),
            SweepKind::Orientation => orientation_poses(),
            SweepKind::Dark => Vec::new(),
            SweepKind::All => {
                let mut v = translation_poses();
                v.extend(orientation_poses());
                v
            }
        };
        SweepPlan {
            kind,
            samples,
            poses,
        }
    }

    /// The sweep of `scene`: a docking station's (several `[[beacons]]`)
    /// spans a docking approach ([`station_translation_poses`],
    /// [`station_orientation_poses`]); one beacon's is [`SweepPlan::new`].
    pub fn for_scene(kind: SweepKind, samples: u32, scene: &Scene) -> Self {
        let mut plan = SweepPlan::new(kind, samples);
        if scene.beacons.len() > 1 {
            plan.poses = match kind {
                SweepKind::Translation => station_translation_poses(),
                SweepKind::Orientation => station_orientation_poses(),
                SweepKind::Dark => Vec::new(),
                SweepKind::All => {
                    let mut v = station_translation_poses();
                    v.extend(station_orientation_poses());
                    v
                }
            };
        }
        plan
    }

    /// Number of frames it writes.
    pub fn frames(&self) -> u64 {
        match self.kind {
            SweepKind::Dark => self.samples as u64,
            _ => self.poses.len() as u64 * self.samples as u64,
        }
    }

    /// Call `sink` with every frame of the sweep, in order.
    pub fn run(
        &self,
        scene: &Scene,
        seed: u64,
        mut sink: impl FnMut(&Frame) -> std::io::Result<()>,
    ) -> std::io::Result<u64> {
        let mut sim = Simulator::new(scene.clone(), seed);
        let dt = 1.0 / scene.adc.rate_hz;
        let mut seq = 0u64;
        let mut emit = |sim: &mut Simulator, pose: &Pose, truth: bool| {
            let mut f = sim.frame(seq, seq as f64 * dt, pose, Some(0.0));
            if !truth {
                f.truth = None;
            }
            seq += 1;
            sink(&f)
        };
        sim.set_beacon(self.kind != SweepKind::Dark);
        self.each_pose(|pose, truth| emit(&mut sim, pose, truth))?;
        Ok(seq)
    }

    /// Spec v3: call `sink` with every frame of the sweep as the samples
    /// the ADC takes (a [`Burst`], its buffer reused), the vehicle still at
    /// each pose; a dark sweep has no daylight either (MODEL.md).
    pub fn run_bursts(
        &self,
        scene: &Scene,
        seed: u64,
        mut sink: impl FnMut(&Burst) -> std::io::Result<()>,
    ) -> std::io::Result<u64> {
        let mut scene = scene.clone();
        if self.kind == SweepKind::Dark {
            scene.daylight = None;
        }
        let mut sim = Simulator::new(scene.clone(), seed);
        let dt = 1.0 / scene.adc.rate_hz;
        let mut burst = Burst::new(scene.adc.samples_per_frame());
        let mut seq = 0u64;
        let mut emit = |sim: &mut Simulator, pose: &Pose, truth: bool| {
            let still = Kinematics {
                pose: *pose,
                velocity: BeamVec::default(),
            };
            sim.burst(seq, seq as f64 * dt, |_| still, &mut burst);
            if !truth {
                burst.truth = None;
            }
            seq += 1;
            sink(&burst)
        };
        sim.set_beacon(self.kind != SweepKind::Dark);
        self.each_pose(|pose, truth| emit(&mut sim, pose, truth))?;
        Ok(seq)
    }

    /// The sweep's schedule: `samples` frames at each pose, with truth; a
    /// dark sweep's frames carry none (with the beacon off the pose is
    /// moot).
    fn each_pose(
        &self,
        mut emit: impl FnMut(&Pose, bool) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        if self.kind == SweepKind::Dark {
            let pose = Pose::new(4.5, 0.0, 0.0, Angle::ZERO, Angle::ZERO);
            for _ in 0..self.samples {
                emit(&pose, false)?;
            }
        } else {
            for pose in &self.poses {
                for _ in 0..self.samples {
                    emit(pose, true)?;
                }
            }
        }
        Ok(())
    }

    /// Write the sweep as an intensity log: FRAME lines, or (spec v3, a
    /// scene of several samples per frame) BURST lines.
    pub fn write<W: Write>(&self, scene: &Scene, seed: u64, out: W) -> std::io::Result<u64> {
        let mut header = scene.log_header();
        header
            .extra
            .insert("sweep".into(), self.kind.as_str().into());
        header.extra.insert("samples".into(), self.samples.into());
        header.extra.insert("seed".into(), seed.into());
        let mut w = LogWriter::new(out, &header)?;
        let n = if scene.adc.samples_per_frame() > 1 {
            self.run_bursts(scene, seed, |b| w.write_burst(b))?
        } else if !scene.is_v2() {
            self.run_bursts(scene, seed, |b| w.write_frame(&one_sample_frame(b)))?
        } else {
            self.run(scene, seed, |f| w.write_frame(f))?
        };
        w.flush()?;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_counts_match_model_md() {
        assert_eq!(translation_poses().len(), 125);
        assert_eq!(orientation_poses().len(), 183);
        assert_eq!(SweepPlan::new(SweepKind::All, 200).frames(), 61_600);
        let t = translation_poses();
        assert_eq!((t[0].x, t[0].y, t[0].z), (4.5, -0.6, 0.0));
        // Exactly MODEL.md's decimals, as the sweep's truth labels print.
        let ys: Vec<f64> = t.iter().take(25).step_by(5).map(|p| p.y).collect();
        assert_eq!(ys, [-0.6, -0.3, 0.0, 0.3, 0.6]);
        let zs: Vec<f64> = t.iter().take(5).map(|p| p.z).collect();
        assert_eq!(zs, [0.0, 0.2, 0.4, 0.6, 0.8]);
        assert_eq!((t[124].x, t[124].y, t[124].z), (8.5, 0.6, 0.8));
        assert_eq!(station_translation_poses().len(), 150);
        let so = station_orientation_poses();
        assert_eq!(so.len(), 93);
        assert_eq!(so.iter().filter(|p| p.roll != Angle::ZERO).count(), 30);
        let o = orientation_poses();
        let zeros = o
            .iter()
            .filter(|p| p.pitch == Angle::ZERO && p.yaw == Angle::ZERO)
            .count();
        assert_eq!(zeros, 3);
        assert!(o
            .iter()
            .all(|p| p.pitch.deg().abs() <= 15.0 + 1e-9 && p.yaw.deg().abs() <= 15.0 + 1e-9));
    }
}
