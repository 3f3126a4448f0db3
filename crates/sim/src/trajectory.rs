//! Trajectories: knots `t,x,y,z,pitch,yaw` from CSV, a natural cubic spline
//! per column, sampled at t = t0 + k / rate while t ≤ t_end. True surge is
//! the spline's velocity along the vehicle's forward axis.

use crate::spline::Spline;
use lightpose_core::textfile::{read_text, TextError};
use lightpose_core::{Angle, Attitude, BeamVec, Pose};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// Unreadable or too large.
    #[error(transparent)]
    Text(#[from] TextError),
    #[error("{file}:{line}: {msg}")]
    Invalid {
        file: String,
        line: usize,
        msg: String,
    },
}

/// One knot: time (s), position (m) and attitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knot {
    pub t: f64,
    pub pose: Pose,
}

/// Where the vehicle is and how it moves at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub pose: Pose,
    /// Velocity over the ground in B, m/s.
    pub velocity: BeamVec,
}

impl Kinematics {
    /// Speed along the forward axis (MODEL.md's surge).
    pub fn surge(&self) -> f64 {
        let f = Attitude::new(self.pose.pitch, self.pose.yaw).forward();
        f.dot(&self.velocity)
    }
}

#[derive(Debug, Clone)]
pub struct Trajectory {
    knots: Vec<Knot>,
    /// x, y, z, pitch (rad), yaw (rad)
    cols: [Spline; 5],
}

const HEADER: [&str; 6] = ["t", "x", "y", "z", "pitch", "yaw"];

impl Trajectory {
    pub fn load(path: &Path) -> Result<Self, TrajectoryError> {
        let text = read_text(path)?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parse CSV text with the header `t,x,y,z,pitch,yaw` (angles in degrees).
    pub fn parse(text: &str, file: &str) -> Result<Self, TrajectoryError> {
        let err = |line: usize, msg: String| TrajectoryError::Invalid {
            file: file.to_string(),
            line,
            msg,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (hl, header) = lines
            .next()
            .ok_or_else(|| err(1, "empty trajectory: no header".into()))?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        if names != HEADER {
            return Err(err(
                hl,
                format!("header must be `{}`, found `{header}`", HEADER.join(",")),
            ));
        }
        let mut knots = Vec::new();
        let mut last_line = hl;
        for (ln, l) in lines {
            let fields: Vec<&str> = l.split(',').map(str::trim).collect();
            if fields.len() != 6 {
                return Err(err(
                    ln,
                    format!("expected 6 values, found {}", fields.len()),
                ));
            }
            let mut v = [0.0; 6];
            for (i, (f, slot)) in fields.iter().zip(v.iter_mut()).enumerate() {
                *slot = f
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        err(ln, format!("{} = `{f}` is not a finite number", HEADER[i]))
                    })?;
            }
            if let Some(prev) = knots.last().map(|k: &Knot| k.t) {
                if v[0] <= prev {
                    return Err(err(
                        ln,
                        format!("t = {} does not increase (previous {prev})", v[0]),
                    ));
                }
            }
            if v[4].abs() >= 90.0 || v[5].abs() >= 180.0 {
                return Err(err(
                    ln,
                    "pitch must be within ±90° and yaw within ±180°".into(),
                ));
            }
            knots.push(Knot {
                t: v[0],
                pose: Pose::new(
                    v[1],
                    v[2],
                    v[3],
                    Angle::from_deg(v[4]),
                    Angle::from_deg(v[5]),
                ),
            });
            last_line = ln;
        }
        if knots.len() < 2 {
            return Err(err(
                last_line,
                format!("a trajectory needs at least 2 knots, found {}", knots.len()),
            ));
        }
        Ok(Self::from_knots(knots))
    }

    /// Build from knots already checked: at least two, `t` increasing.
    pub fn from_knots(knots: Vec<Knot>) -> Self {
        let t: Vec<f64> = knots.iter().map(|k| k.t).collect();
        let col = |f: fn(&Pose) -> f64| {
            let y: Vec<f64> = knots.iter().map(|k| f(&k.pose)).collect();
            Spline::new(&t, &y)
        };
        let cols = [
            col(|p| p.x),
            col(|p| p.y),
            col(|p| p.z),
            col(|p| p.pitch.rad()),
            col(|p| p.yaw.rad()),
        ];
        Trajectory { knots, cols }
    }

    pub fn knots(&self) -> &[Knot] {
        &self.knots
    }
    pub fn t0(&self) -> f64 {
        self.knots[0].t
    }
    pub fn t_end(&self) -> f64 {
        self.knots[self.knots.len() - 1].t
    }

    /// Pose and true surge (m/s along the forward axis) at time `t`.
    pub fn sample(&self, t: f64) -> (Pose, f64) {
        let k = self.kinematics(t);
        (k.pose, k.surge())
    }

    /// Pose and velocity in B at time `t` (the splines and their slopes).
    pub fn kinematics(&self, t: f64) -> Kinematics {
        let (x, vx) = self.cols[0].eval(t);
        let (y, vy) = self.cols[1].eval(t);
        let (z, vz) = self.cols[2].eval(t);
        let (pitch, _) = self.cols[3].eval(t);
        let (yaw, _) = self.cols[4].eval(t);
        Kinematics {
            pose: Pose::new(x, y, z, Angle::from_rad(pitch), Angle::from_rad(yaw)),
            velocity: BeamVec([vx, vy, vz]),
        }
    }

    /// The frame times t0 + k / rate, k = 0, 1, … while t ≤ t_end.
    pub fn frame_times(&self, rate_hz: f64) -> impl Iterator<Item = f64> + '_ {
        let (t0, t_end) = (self.t0(), self.t_end());
        // Tolerance so that t_end itself is sampled despite rounding.
        let n = ((t_end - t0) * rate_hz + 1e-9).floor() as u64;
        (0..=n).map(move |k| t0 + k as f64 / rate_hz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIVE: &str = "t,x,y,z,pitch,yaw\n0,8.5,0,0,10,0\n2.6,7.22,0,0.22,8.7,0\n5.2,5.93,0,0.38,5.2,0\n8,4.53,0,0.45,0,0\n";

    #[test]
    fn dive_has_41_frames_at_5_hz_and_positive_surge() {
        let tr = Trajectory::parse(DIVE, "dive.csv").unwrap();
        let times: Vec<f64> = tr.frame_times(5.0).collect();
        assert_eq!(times.len(), 41);
        assert!((times[40] - 8.0).abs() < 1e-12);
        let (p, surge) = tr.sample(2.6);
        assert!((p.x - 7.22).abs() < 1e-12 && (p.pitch.deg() - 8.7).abs() < 1e-9);
        // approaching at about 0.5 m/s, bow towards the beacon
        assert!(surge > 0.4 && surge < 0.6, "{surge}");
    }

    #[test]
    fn bad_csv_is_named() {
        for (text, want) in [
            ("", "dive.csv:1: empty"),
            ("t,x,y\n", "dive.csv:1: header"),
            ("t,x,y,z,pitch,yaw\n0,1,2,3,4\n", "dive.csv:2: expected 6"),
            (
                "t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n1,1,0,0,zz,0\n",
                "dive.csv:3: pitch = `zz`",
            ),
            (
                "t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n0,1,0,0,0,0\n",
                "dive.csv:3: t = 0 does not increase",
            ),
            ("t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n", "at least 2 knots"),
        ] {
            let e = Trajectory::parse(text, "dive.csv").unwrap_err().to_string();
            assert!(e.contains(want), "{e} lacks {want}");
        }
    }
}
