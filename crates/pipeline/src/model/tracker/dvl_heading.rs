//! The DVL's mounting judged by the light: does the vehicle move the way
//! the DVL says it does?
//!
//! A DVL turned by α about its down axis with its mounting rotation unset
//! reads the vehicle's motion turned by α. The range check
//! (`dvl_check`) sees that only past ~80°, where the change of range
//! contradicts; at 15–70° the filter took the DVL whole, blamed the AHRS's
//! yaw and put y and yaw off (on a minute in the tank, turned 45°: y p95
//! 0.83 m, yaw 9.7°, 285 of 291 `ok` poses beyond 3σ).
//!
//! With an attitude reading the light gives the vehicle's horizontal
//! position relative to the beacon without the DVL: the law's range along
//! the beacon's bearing in the body (which the light pins, read off the
//! state) turned into B by the AHRS's attitude. The DVL's velocity turned
//! by the same attitude integrates to its own track. Over the last
//! [`SPAN_S`], in blocks of a second (their means), the rotation that
//! best lays the DVL's track onto the light's about their centroids, with a
//! scale, is the DVL's turn (Procrustes): a water or a law that scales the
//! light's track does not turn it, and an AHRS whose heading is off turns
//! both alike.
//! Once it is known to [`MAX_SE_DEG`], a turn past [`REFUSE_DEG`] refuses
//! the DVL until it is back within [`TAKE_DEG`]; the turn is reported
//! (STATUS `readings.check.dvl.turned_deg`), so the operator can set the
//! DVL's mounting rotation. The samples are taken after the frame's update
//! (`Tracker::observe_dvl`): the bearing of that frame, as the attitude
//! reading is (with the last frame's bearing, the zigzags' yaw swings of
//! 6°/s put 7° of bias on a good DVL's turn).

use std::f64::consts::PI;

/// The span judged, s: enough track for the angle's noise (the light's
/// lateral position is the AHRS's heading noise times the range) to
/// average down.
pub(super) const SPAN_S: f64 = 10.0;

/// One block, s.
const BLOCK_S: f64 = 1.0;

/// Blocks held: the span's and one more.
const BLOCKS: usize = 12;

/// The angle is judged over at least this many blocks, on a track that
/// spreads at least [`MIN_SPREAD_M2`] about its centroid (Σ of the blocks'
/// squared distances), once its standard error is under [`MAX_SE_DEG`]:
/// the light's lateral noise and the law's wander (what the turn leaves
/// unexplained) over the root of that spread. Judged over 3 blocks with
/// half a m² of spread, the harbour's Monte Carlo reached 31° on a good
/// DVL; as set, 12° at most over 12 000 runs.
const MIN_BLOCKS: usize = 6;
pub(super) const MIN_SPREAD_M2: f64 = 1.0;
pub(super) const MAX_SE_DEG: f64 = 3.0;

/// A turn past this refuses the DVL, °: on good DVLs the angle judged
/// stayed within ±13.1° (the Monte Carlo's 12 000 runs with an attitude
/// sensor and a DVL, water drawn) and −5.1…+0.4° on the minute in the
/// tank.
pub(super) const REFUSE_DEG: f64 = 20.0;

/// A refused DVL is taken again within this, °.
pub(super) const TAKE_DEG: f64 = 10.0;

/// A block's sums: the light's position, the DVL's track, and how many.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    t0: f64,
    light: [f64; 2],
    dvl: [f64; 2],
    n: f64,
}

/// The blocks, the DVL's track, and the verdict.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct HeadingCheck {
    open: Option<Sums>,
    /// Closed blocks' means (light, DVL), oldest first from `head - len`.
    blocks: [([f64; 2], [f64; 2], f64); BLOCKS],
    head: usize,
    len: usize,
    /// The last sample's time and the DVL's horizontal velocity in B.
    last: Option<(f64, [f64; 2])>,
    track: [f64; 2],
    refused: bool,
    /// The last judged angle, rad: the DVL reads the motion turned by this
    /// to starboard.
    turned: Option<f64>,
}

impl HeadingCheck {
    pub fn refused(&self) -> bool {
        self.refused
    }

    /// Its verdict and last judged turn, with no track.
    pub fn verdict(&self) -> HeadingCheck {
        HeadingCheck {
            refused: self.refused,
            turned: self.turned,
            ..Default::default()
        }
    }

    /// The last judged turn of the DVL's readings, ° to starboard.
    pub fn turned_deg(&self) -> Option<f64> {
        self.turned.map(f64::to_degrees)
    }

    /// No sample this frame (no DVL, attitude or light): the track cannot
    /// go on.
    pub fn break_chain(&mut self) {
        self.last = None;
        self.open = None;
        self.len = 0;
    }

    /// Take one frame at `t`: the vehicle's horizontal position in B by
    /// the light (`light`, m) and the DVL's horizontal velocity in B
    /// (`v`, m/s); `max_gap_s` the longest step of the track. Returns
    /// whether the DVL is refused.
    pub fn push(&mut self, t: f64, light: [f64; 2], v: [f64; 2], max_gap_s: f64) -> bool {
        if ![t, light[0], light[1], v[0], v[1]]
            .iter()
            .all(|x| x.is_finite())
        {
            self.break_chain();
            return self.refused;
        }
        match self.last {
            Some((t0, v0)) if t >= t0 && t - t0 <= max_gap_s => {
                for i in 0..2 {
                    self.track[i] += 0.5 * (v0[i] + v[i]) * (t - t0);
                }
            }
            _ => {
                self.break_chain();
                self.track = [0.0; 2];
            }
        }
        self.last = Some((t, v));
        let fresh = Sums {
            t0: t,
            ..Sums::default()
        };
        match self.open {
            Some(b) if t - b.t0 >= BLOCK_S - 0.01 => {
                self.blocks[self.head] = (b.light.map(|x| x / b.n), b.dvl.map(|x| x / b.n), b.t0);
                self.head = (self.head + 1) % BLOCKS;
                self.len = (self.len + 1).min(BLOCKS);
                self.open = Some(fresh);
                self.judge(t);
            }
            Some(_) => {}
            None => self.open = Some(fresh),
        }
        let open = self.open.get_or_insert(fresh);
        for i in 0..2 {
            open.light[i] += light[i];
            open.dvl[i] += self.track[i];
        }
        open.n += 1.0;
        self.refused
    }

    /// The angle over the closed blocks within the span: the rotation that
    /// best lays the DVL's track onto the light's about their centroids
    /// (Procrustes: the argument of Σ conj(D − D̄)·(L − L̄)), so that the
    /// whole spread of the track, not its steps, sets the angle's noise.
    fn judge(&mut self, now: f64) {
        let block = |k: usize| self.blocks[(self.head + BLOCKS - 1 - k) % BLOCKS];
        let n = (0..self.len)
            .take_while(|&k| now - block(k).2 <= SPAN_S + BLOCK_S)
            .count();
        if n < MIN_BLOCKS {
            return;
        }
        let (mut lm, mut dm) = ([0.0; 2], [0.0; 2]);
        for k in 0..n {
            let (l, d, _) = block(k);
            for i in 0..2 {
                lm[i] += l[i] / n as f64;
                dm[i] += d[i] / n as f64;
            }
        }
        let (mut re, mut im, mut spread) = (0.0, 0.0, 0.0);
        for k in 0..n {
            let (l, d, _) = block(k);
            let l = [l[0] - lm[0], l[1] - lm[1]];
            let d = [d[0] - dm[0], d[1] - dm[1]];
            re += d[0] * l[0] + d[1] * l[1];
            im += d[0] * l[1] - d[1] * l[0];
            spread += d[0] * d[0] + d[1] * d[1];
        }
        if !(spread >= MIN_SPREAD_M2 && re.is_finite() && im.is_finite()) {
            return;
        }
        // The angle from the DVL's track to the light's, in B (z up):
        // positive is counter-clockwise seen from above, the DVL's track
        // turned clockwise, to starboard, of the truth.
        let a = im.atan2(re);
        // Its standard error from what the turn and a scale leave
        // unexplained (the light's lateral noise, the law's wander) over the
        // track's spread: a short or noisy track is not judged. The scale
        // is fitted too (a water or a law that scales the light's track by
        // k left |k − 1| in the residual, and at 1.3 nothing was judged).
        let scale = re.hypot(im) / spread;
        let (sa, ca) = a.sin_cos();
        let mut left = 0.0;
        for k in 0..n {
            let (l, d, _) = block(k);
            let l = [l[0] - lm[0], l[1] - lm[1]];
            let d = [d[0] - dm[0], d[1] - dm[1]];
            let fit = [
                scale * (ca * d[0] - sa * d[1]),
                scale * (sa * d[0] + ca * d[1]),
            ];
            left += (l[0] - fit[0]).powi(2) + (l[1] - fit[1]).powi(2);
        }
        let se = (left / (2 * n - 4) as f64 / (scale * scale * spread)).sqrt();
        if !(se <= MAX_SE_DEG.to_radians()) {
            return;
        }
        self.turned = Some(a);
        if a.abs() > REFUSE_DEG.to_radians() {
            self.refused = true;
        } else if a.abs() < TAKE_DEG.to_radians() {
            self.refused = false;
        }
        debug_assert!(a.abs() <= PI);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle in B coming and going along x with a slow drift in y
    /// (5 Hz, 0.5 m/s), the light's position with `noise` (m, a fixed
    /// pattern), the DVL's velocity turned by `deg` (starboard: clockwise
    /// seen from above in B).
    fn run(c: &mut HeadingCheck, secs: f64, deg: f64, noise: f64) -> bool {
        run_scaled(c, secs, deg, noise, 1.0)
    }

    /// The same, the light's track `k` times the truth's about the beacon
    /// (water unlike the calibration's, the law).
    fn run_scaled(c: &mut HeadingCheck, secs: f64, deg: f64, noise: f64, scale: f64) -> bool {
        let (s, co) = (-deg.to_radians()).sin_cos();
        let mut refused = false;
        for k in 0..(secs * 5.0) as usize {
            let t = k as f64 * 0.2;
            let w = std::f64::consts::TAU / 20.0;
            let p = [6.0 + 1.6 * (w * t).sin(), 0.3 + 0.02 * t];
            let v = [1.6 * w * (w * t).cos(), 0.02];
            let jitter = noise * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
            let turned = [co * v[0] - s * v[1], s * v[0] + co * v[1]];
            let light = [scale * p[0] + jitter, scale * p[1] - jitter];
            refused = c.push(t, light, turned, 2.0);
        }
        refused
    }

    #[test]
    fn a_dvl_turned_past_twenty_degrees_is_refused_and_its_turn_told() {
        for (deg, refused) in [
            (0.0, false),
            (8.0, false),
            (30.0, true),
            (-45.0, true),
            (180.0, true),
        ] {
            let mut c = HeadingCheck::default();
            assert_eq!(run(&mut c, 30.0, deg, 0.1), refused, "{deg}°");
            let told = c.turned_deg().expect("judged");
            let err = (told - deg + 180.0).rem_euclid(360.0) - 180.0;
            assert!(err.abs() < 2.0, "{deg}°: told {told}");
        }
    }

    /// A light track scaled by the water (0.6–1.6×) turns nothing: the
    /// turn is still judged and told.
    #[test]
    fn a_scaled_light_track_is_still_judged() {
        for k in [0.6, 1.3, 1.6] {
            for (deg, refused) in [(0.0, false), (45.0, true)] {
                let mut c = HeadingCheck::default();
                assert_eq!(
                    run_scaled(&mut c, 30.0, deg, 0.05, k),
                    refused,
                    "{k}× {deg}°"
                );
                let told = c.turned_deg().expect("judged");
                assert!((told - deg).abs() < 2.0, "{k}× {deg}°: told {told}");
            }
        }
    }

    #[test]
    fn a_dvl_put_right_is_taken_again() {
        let mut c = HeadingCheck::default();
        assert!(run(&mut c, 30.0, 45.0, 0.0));
        assert!(!run(&mut c, 30.0, 2.0, 0.0));
    }

    #[test]
    fn too_little_track_or_garbage_judges_nothing() {
        let mut c = HeadingCheck::default();
        for k in 0..100 {
            let t = k as f64 * 0.2;
            assert!(!c.push(t, [6.0, 0.0], [0.01, 0.0], 2.0));
        }
        assert_eq!(c.turned_deg(), None);
        assert!(!c.push(30.0, [f64::NAN, 0.0], [0.5, 0.0], 2.0));
    }
}
