//! The vehicle's latest readings (attitude, depth, water temperature, DVL
//! velocity), each with the moment it was taken, as the receivers left
//! them; the frame thread attaches to each frame those that are fresh.
//!
//! Readings are already in the frames of MODEL.md when stored (pitch and
//! yaw in B, z in B, velocity in V), so attaching is a copy. Neither
//! storing nor attaching allocates or takes a lock (see `latest`).

use crate::latest::{opt, word, Latest};
use lightpose_core::{Angle, AttitudeReading, AttitudeStd, BodyVec, DepthReading, Frame};
use lightpose_core::{AttitudeReading as Att, VelocityReading};
use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// How old each reading may be and still go with a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaxAge {
    pub attitude: Duration,
    pub depth: Duration,
    pub temperature: Duration,
    pub velocity: Duration,
}

impl Default for MaxAge {
    /// Attitude 0.25 s (a turning ROV moves its heading tens of degrees per
    /// second), depth 0.5 s, temperature 10 s (it changes slowly and is
    /// streamed slowly), velocity 1 s (the DVL reports at 2–15 Hz).
    fn default() -> Self {
        MaxAge {
            attitude: Duration::from_millis(250),
            depth: Duration::from_millis(500),
            temperature: Duration::from_secs(10),
            velocity: Duration::from_secs(1),
        }
    }
}

/// Which readings [`Readings::attach`] gave a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Attached {
    pub attitude: bool,
    pub depth: bool,
    pub temperature: bool,
    pub velocity: bool,
}

/// Per reading: frames that got it, and frames that found only a stale one.
#[derive(Default)]
struct Use {
    attached: AtomicU64,
    stale: AtomicU64,
}

/// The latest reading of each kind. Word 0 of every cell is the moment
/// taken, in nanoseconds since `epoch`.
pub struct Readings {
    epoch: Instant,
    attitude: Latest<5>,
    depth: Latest<3>,
    temperature: Latest<2>,
    velocity: Latest<7>,
    uses: [Use; 4],
}

const ATT: usize = 0;
const DEPTH: usize = 1;
const TEMP: usize = 2;
const VEL: usize = 3;

impl Default for Readings {
    fn default() -> Self {
        Readings {
            epoch: Instant::now(),
            attitude: Latest::default(),
            depth: Latest::default(),
            temperature: Latest::default(),
            velocity: Latest::default(),
            uses: Default::default(),
        }
    }
}

/// STATUS figures of one reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReadingStatus {
    /// Seconds since the latest was taken; `null` if none ever came.
    pub age_s: Option<f64>,
    /// Readings stored.
    pub stored: u64,
    /// Frames that carried one.
    pub attached: u64,
    /// Frames that found only one older than the limit.
    pub stale: u64,
}

/// STATUS figures of all readings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReadingsStatus {
    pub attitude: ReadingStatus,
    pub depth: ReadingStatus,
    pub temperature: ReadingStatus,
    pub velocity: ReadingStatus,
}

impl Readings {
    fn stamp(&self, at: Instant) -> u64 {
        at.saturating_duration_since(self.epoch).as_nanos() as u64
    }

    /// `Some(words)` if the cell holds a reading taken no longer than
    /// `max_age` before `now`; counts a stale one.
    #[inline]
    fn fresh<const N: usize>(
        &self,
        cell: &Latest<N>,
        k: usize,
        now: Instant,
        max_age: Duration,
    ) -> Option<[u64; N]> {
        let (_, w) = cell.load()?;
        let taken = self.epoch + Duration::from_nanos(w[0]);
        if now.saturating_duration_since(taken) <= max_age {
            Some(w)
        } else {
            self.uses[k].stale.fetch_add(1, Relaxed);
            None
        }
    }

    pub fn store_attitude(&self, at: Instant, r: &AttitudeReading) {
        let s = r.std.map(|s| (s.pitch.rad(), s.yaw.rad()));
        self.attitude.store([
            self.stamp(at),
            r.pitch.rad().to_bits(),
            r.yaw.rad().to_bits(),
            word(s.map(|s| s.0)),
            word(s.map(|s| s.1)),
        ]);
    }

    pub fn store_depth(&self, at: Instant, r: &DepthReading) {
        self.depth
            .store([self.stamp(at), r.z.to_bits(), word(r.std)]);
    }

    pub fn store_temperature(&self, at: Instant, temp_c: f64) {
        self.temperature.store([self.stamp(at), temp_c.to_bits()]);
    }

    pub fn store_velocity(&self, at: Instant, r: &VelocityReading) {
        let [f, ri, d] = r.v.0;
        let s = r.std.map(|s| s.0);
        self.velocity.store([
            self.stamp(at),
            f.to_bits(),
            ri.to_bits(),
            d.to_bits(),
            word(s.map(|s| s[0])),
            word(s.map(|s| s[1])),
            word(s.map(|s| s[2])),
        ]);
    }

    /// The latest attitude if fresh at `now`.
    pub fn attitude(&self, now: Instant, max_age: Duration) -> Option<AttitudeReading> {
        let w = self.fresh(&self.attitude, ATT, now, max_age)?;
        let std = match (opt(w[3]), opt(w[4])) {
            (Some(p), Some(y)) => Some(AttitudeStd {
                pitch: Angle::from_rad(p),
                yaw: Angle::from_rad(y),
            }),
            _ => None,
        };
        Some(Att {
            pitch: Angle::from_rad(f64::from_bits(w[1])),
            yaw: Angle::from_rad(f64::from_bits(w[2])),
            std,
        })
    }

    /// The latest depth reading (z in B) if fresh at `now`.
    pub fn depth(&self, now: Instant, max_age: Duration) -> Option<DepthReading> {
        let w = self.fresh(&self.depth, DEPTH, now, max_age)?;
        Some(DepthReading {
            z: f64::from_bits(w[1]),
            std: opt(w[2]),
        })
    }

    /// The latest water temperature (°C) if fresh at `now`.
    pub fn temperature(&self, now: Instant, max_age: Duration) -> Option<f64> {
        let w = self.fresh(&self.temperature, TEMP, now, max_age)?;
        Some(f64::from_bits(w[1]))
    }

    /// The latest DVL velocity (V, FRD) if fresh at `now`.
    pub fn velocity(&self, now: Instant, max_age: Duration) -> Option<VelocityReading> {
        let w = self.fresh(&self.velocity, VEL, now, max_age)?;
        let std = match (opt(w[4]), opt(w[5]), opt(w[6])) {
            (Some(a), Some(b), Some(c)) => Some(BodyVec([a, b, c])),
            _ => None,
        };
        Some(VelocityReading {
            v: BodyVec([
                f64::from_bits(w[1]),
                f64::from_bits(w[2]),
                f64::from_bits(w[3]),
            ]),
            std,
        })
    }

    /// Give `frame` every reading that is fresh at `now` and that the frame
    /// does not carry already (a recording's or the simulator's own
    /// readings win). For the frame thread: no allocation, no lock.
    pub fn attach(&self, frame: &mut Frame, now: Instant, max_age: &MaxAge) -> Attached {
        let mut a = Attached::default();
        if frame.attitude.is_none() {
            frame.attitude = self.attitude(now, max_age.attitude);
            a.attitude = frame.attitude.is_some();
        }
        if frame.depth.is_none() {
            frame.depth = self.depth(now, max_age.depth);
            a.depth = frame.depth.is_some();
        }
        if frame.temp_c.is_none() {
            frame.temp_c = self.temperature(now, max_age.temperature);
            a.temperature = frame.temp_c.is_some();
        }
        if frame.velocity.is_none() {
            frame.velocity = self.velocity(now, max_age.velocity);
            a.velocity = frame.velocity.is_some();
        }
        for (k, got) in [a.attitude, a.depth, a.temperature, a.velocity]
            .into_iter()
            .enumerate()
        {
            if got {
                self.uses[k].attached.fetch_add(1, Relaxed);
            }
        }
        a
    }

    fn one_status<const N: usize>(
        &self,
        cell: &Latest<N>,
        k: usize,
        now: Instant,
    ) -> ReadingStatus {
        let age_s = cell.load().map(|(_, w)| {
            now.saturating_duration_since(self.epoch + Duration::from_nanos(w[0]))
                .as_secs_f64()
        });
        ReadingStatus {
            age_s,
            stored: cell.version(),
            attached: self.uses[k].attached.load(Relaxed),
            stale: self.uses[k].stale.load(Relaxed),
        }
    }

    /// Ages and counts for STATUS.
    pub fn status(&self, now: Instant) -> ReadingsStatus {
        ReadingsStatus {
            attitude: self.one_status(&self.attitude, ATT, now),
            depth: self.one_status(&self.depth, DEPTH, now),
            temperature: self.one_status(&self.temperature, TEMP, now),
            velocity: self.one_status(&self.velocity, VEL, now),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::NDET;

    #[test]
    fn fresh_readings_are_attached_and_stale_ones_counted() {
        let r = Readings::default();
        let t0 = Instant::now();
        r.store_attitude(
            t0,
            &AttitudeReading::new(Angle::from_deg(5.0), Angle::from_deg(-3.0)),
        );
        r.store_depth(
            t0,
            &DepthReading {
                z: 0.4,
                std: Some(0.02),
            },
        );
        r.store_temperature(t0, 12.5);
        r.store_velocity(t0, &VelocityReading::new(0.3, 0.01, -0.02));
        let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
        let a = r.attach(&mut f, t0 + Duration::from_millis(100), &MaxAge::default());
        assert_eq!(
            a,
            Attached {
                attitude: true,
                depth: true,
                temperature: true,
                velocity: true
            }
        );
        assert!((f.attitude.unwrap().pitch.deg() - 5.0).abs() < 1e-12);
        assert_eq!(f.depth.unwrap().std, Some(0.02));
        assert_eq!(f.temp_c, Some(12.5));
        assert_eq!(f.velocity.unwrap().v.0, [0.3, 0.01, -0.02]);
        assert_eq!(f.velocity.unwrap().std, None);
        // 0.6 s later attitude and depth are stale, temperature and DVL not.
        let mut g = Frame::new(1, 0.2, 10, [0; NDET]);
        let a = r.attach(&mut g, t0 + Duration::from_millis(600), &MaxAge::default());
        assert!(!a.attitude && !a.depth && a.temperature && a.velocity);
        let st = r.status(t0 + Duration::from_millis(600));
        assert_eq!((st.attitude.attached, st.attitude.stale), (1, 1));
        assert_eq!(st.attitude.stored, 1);
        assert!((st.depth.age_s.unwrap() - 0.6).abs() < 1e-9);
    }

    #[test]
    fn a_frame_keeps_its_own_readings() {
        let r = Readings::default();
        let t0 = Instant::now();
        r.store_temperature(t0, 12.5);
        let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
        f.temp_c = Some(20.0);
        let a = r.attach(&mut f, t0, &MaxAge::default());
        assert_eq!(f.temp_c, Some(20.0));
        assert!(!a.temperature);
        assert_eq!(r.status(t0).velocity.age_s, None);
    }
}
