//! The DVL judged by the light's own range: does the range change the
//! DVL's velocity says agree with the one the light sees?
//!
//! A DVL set up wrong (mounted backwards or across the bow with its
//! mounting rotation unset, its axes swapped, its units mistaken) gives a
//! velocity as steady and as confident as a good one. The gate cannot see
//! it, since the filter's velocity follows the DVL, and the reading check
//! blames the attitude sensor instead: on a minute of coming and going in
//! the tank with the DVL turned 180°, every reading was fused, the AHRS's
//! yaw was called biased and refused, the water check learned a K_D of
//! 0.048 for the tank's 0.09, and x was 2.9 m off at p95 on poses marked
//! `ok` (docs/estimators.md, "A DVL set up wrong").
//!
//! The light sees the range independently of the DVL and of the filter:
//! the paper's law reads it off the brightest channel. Over the last
//! [`WINDOW_S`], the DVL's velocity along the line of sight (at the
//! state's bearing of the beacon, which the light pins) integrates to the
//! change of range it claims; the law's ranges at the window's ends (each
//! a mean over a second) give the light's. Water unlike the calibration's
//! scales the light's change: more turbid water up without bound (2.2× at
//! 3 m in water of K_D 1.0 for a tank calibrated at 0.09), clearer water
//! down to its geometric part at most (2/x of K_D + 2/x: 0.53 at 20 m in
//! the tank); the law's bias follows the geometry (ratios of 0.39–1.6 on
//! good runs). No water turns its sign or takes it under a third, and
//! none the beacon is seen through makes it five times. So when the
//! light's change along the DVL's is under [`REFUSE_BELOW`] of it or over
//! [`REFUSE_ABOVE`] times it, beyond the law's wander and its counts'
//! noise, the DVL is refused (`refused_light`) until a window with a metre
//! of travel has its ratio inside [`TAKE`]. The window is judged whether
//! the DVL is fused or not, so a DVL put right is taken again.
//!
//! What it does not see: a DVL turned by up to ~80° (the track's direction
//! does, with an attitude sensor: `dvl_heading`); a scale of ¼–4× (a wrong
//! sound speed is a few per cent), which water mimics; nor a turned DVL
//! while the range does not change (a vehicle on station, or circling the
//! beacon).
//!
//! About the sensor, not the state: kept across restarts, and handed to a
//! water bank's members.

use lightpose_core::{Agreement, ReadingUse, Refusal};

use super::dvl_heading::HeadingCheck;
use super::readings::{FrameReadings, PaperReading, Pending};
use super::state::{body_axes, State};
use super::Tracker;

/// The window, s: the reading check's default, long enough for a metre
/// of travel at cruising speed.
pub(super) const WINDOW_S: f64 = 5.0;

/// A window shorter than this is not judged, s; each end's range is the
/// mean over its first and last [`END_S`], so that one noisy frame of the
/// law (its brightest channel, at 10 m) is not a disagreement.
const MIN_SPAN_S: f64 = 2.0;
const END_S: f64 = 1.0;

/// What the law's range may wander by over a window with a good DVL, m,
/// beyond its counts' noise: its bias follows the geometry (0.34 m over
/// 5 s on a minute in the tank).
const WANDER_M: f64 = 0.35;

/// The counts' noise of the two ends' means counts this many σ.
const NOISE_K: f64 = 3.0;

/// Faster than this the light's range does not change, m/s: the DVL's
/// own limit (`velocity_limit_mps`'s default).
const JUMP_MPS: f64 = 5.0;

/// The least change of range, m, the DVL's or the light's, for a window
/// to be judged (and the DVL's, for the under-a-third test).
const MIN_JUDGED_M: f64 = 0.5;

/// The least change of range, m: the DVL's, for a refused DVL to be taken
/// again; the light's, for a DVL that claims too little to be refused.
pub(super) const MIN_TRAVEL_M: f64 = 1.0;

/// Light's range change over the DVL's: when the light's is less than
/// this share of the DVL's (along it) beyond the law's wander and noise,
/// the DVL is refused. On good runs in their own water (tank, harbour and
/// the held-out tank; dive, zigzag, dock, approach and a minute of
/// to-and-fro) the ratio of the ends was 0.39–1.6; clearer water than the
/// calibration's takes it down to 2/x of K_D + 2/x at most. None of 24 000
/// Monte Carlo runs (`lightpose bench`, 2000 per case and set of sensors
/// with a DVL, water drawn) refused a good DVL.
pub(super) const REFUSE_BELOW: f64 = 1.0 / 3.0;

/// Light's range change over the DVL's: past this (beyond the wander and
/// noise) the DVL is refused too; more turbid water than the calibration's
/// grows the ratio, but not this far where the beacon is still seen.
pub(super) const REFUSE_ABOVE: f64 = 5.0;

/// Light's range change over the DVL's: inside this, with a metre of
/// travel, a refused DVL is taken again.
pub(super) const TAKE: [f64; 2] = [0.5, 2.0];

/// Samples the window holds: one per 0.2 s slot, `READING_CHECK_MAX_S`.
const RING: usize = crate::settings::WATER_CHECK_MAX_FRAMES;

/// One slot's sample: its time, the light's range and its counts' noise
/// (1σ), and the DVL's range change integrated since the chain began.
#[derive(Debug, Clone, Copy, Default)]
struct Sample {
    t: f64,
    light: f64,
    noise: f64,
    dvl: f64,
}

/// The window and the verdict.
#[derive(Debug, Clone, Copy)]
pub(super) struct RangeCheck {
    ring: [Sample; RING],
    head: usize,
    len: usize,
    /// The last frame's time and DVL range rate (m/s), for the integral;
    /// `None` breaks the chain (no DVL or no light on a frame, a gap).
    last: Option<(f64, f64)>,
    /// The integral of the DVL's range rate since the chain began, m.
    dvl: f64,
    refused: bool,
    /// The last judged window's changes of range, m: the light's and the
    /// DVL's.
    changes: Option<[f64; 2]>,
    /// The last frame's time and light's range, for `jumped`.
    last_light: Option<(f64, f64)>,
}

impl Default for RangeCheck {
    fn default() -> Self {
        RangeCheck {
            ring: [Sample::default(); RING],
            head: 0,
            len: 0,
            last: None,
            dvl: 0.0,
            refused: false,
            changes: None,
            last_light: None,
        }
    }
}

impl RangeCheck {
    /// Its verdict and last judged changes, with an empty window.
    fn verdict(&self) -> RangeCheck {
        RangeCheck {
            refused: self.refused,
            changes: self.changes,
            ..Default::default()
        }
    }

    /// Whether the DVL stands refused.
    pub fn refused(&self) -> bool {
        self.refused
    }

    /// The changes of range over the last judged window, m: the light's
    /// and the DVL's (`None` before one was judged).
    pub fn changes(&self) -> Option<[f64; 2]> {
        self.changes
    }

    /// Whether the light's range `light` at `t` jumped from the last
    /// frame's further than any vehicle moves (a metre, or
    /// [`JUMP_MPS`] × the time between): a looped simulation or spliced
    /// logs put the vehicle elsewhere, which is no DVL's fault, so the
    /// windows start again there.
    pub fn jumped(&mut self, t: f64, light: f64) -> bool {
        let jump = self
            .last_light
            .is_some_and(|(t0, l0)| (light - l0).abs() > (JUMP_MPS * (t - t0).abs()).max(1.0));
        self.last_light = Some((t, light));
        jump
    }

    /// A frame on which the DVL or the light's range is missing: the
    /// integral cannot go on, so the window starts again.
    pub fn break_chain(&mut self) {
        self.last = None;
        self.len = 0;
    }

    /// Take one frame at time `t`: the light's range `light` (m) with its
    /// counts' noise `noise` (1σ, m) and the DVL's range rate `rate` (m/s,
    /// positive receding); judge the window of `span_s` (`max_gap_s` the
    /// longest step of the integral). Returns whether the DVL is refused
    /// from this frame on.
    pub fn push(
        &mut self,
        t: f64,
        light: [f64; 2],
        rate: f64,
        span_s: f64,
        max_gap_s: f64,
    ) -> bool {
        let [light, noise] = light;
        if !([t, light, noise, rate].iter().all(|v| v.is_finite()) && noise >= 0.0) {
            self.break_chain();
            return self.refused;
        }
        match self.last {
            Some((t0, r0)) if t >= t0 && t - t0 <= max_gap_s => {
                self.dvl += 0.5 * (r0 + rate) * (t - t0);
            }
            _ => {
                self.len = 0;
                self.dvl = 0.0;
            }
        }
        self.last = Some((t, rate));
        // One sample per slot: at 50 Hz the window is still a time.
        let newest = self.newest();
        if newest.is_some_and(|n| t - n.t < crate::settings::READING_CHECK_SLOT_S - 0.01) {
            return self.refused;
        }
        self.ring[self.head] = Sample {
            t,
            light,
            noise,
            dvl: self.dvl,
        };
        self.head = (self.head + 1) % RING;
        self.len = (self.len + 1).min(RING);
        if let Some(ends) = self.ends(t, span_s) {
            self.judge(ends);
        }
        self.refused
    }

    /// The window's two ends (the means over its first and last `END_S`):
    /// the light's change of range, the DVL's, and the 1σ of the light's
    /// from the counts' noise. `None` while the window is under
    /// `MIN_SPAN_S`.
    fn ends(&self, now: f64, span_s: f64) -> Option<[f64; 3]> {
        let window = (0..self.len)
            .map(|k| self.ring[(self.head + RING - 1 - k) % RING])
            .take_while(|o| now - o.t <= span_s + 1e-9);
        let oldest = window.clone().last()?.t;
        if now - oldest < MIN_SPAN_S {
            return None;
        }
        // (Σ light, Σ dvl, Σ noise², n) over each end.
        let mut sums = [[0.0; 4]; 2];
        for o in window {
            for (end, near) in [(0, o.t - oldest <= END_S), (1, now - o.t <= END_S)] {
                if near {
                    let e = &mut sums[end];
                    e[0] += o.light;
                    e[1] += o.dvl;
                    e[2] += o.noise * o.noise;
                    e[3] += 1.0;
                }
            }
        }
        let [old, new] = sums;
        let d_light = new[0] / new[3] - old[0] / old[3];
        let d_dvl = new[1] / new[3] - old[1] / old[3];
        let sigma = (new[2] / (new[3] * new[3]) + old[2] / (old[3] * old[3])).sqrt();
        Some([d_light, d_dvl, sigma])
    }

    /// The verdict on a window's ends. Judged once either change is half a
    /// metre: a good DVL on station (a change of 0) leaves no band for the
    /// law's wander, which is then the whole of the light's change.
    fn judge(&mut self, [d_light, d_dvl, sigma]: [f64; 3]) {
        if d_dvl.abs().max(d_light.abs()) < MIN_JUDGED_M {
            return;
        }
        self.changes = Some([d_light, d_dvl]);
        let slack = WANDER_M + NOISE_K * sigma;
        // The light's change along the DVL's, against the least any water
        // gives: in clearer water than the calibration's the light's change
        // shrinks only to its geometric part, 2/x of K_D + 2/x (0.53 at
        // 20 m in the tank); in more turbid water it grows without bound
        // (2.2× at 3 m in water of K_D 1.0 for the tank's 0.09), so a
        // light that moves more than the DVL says is not judged here.
        // A DVL claiming a fifth of the light's change or less (turned near
        // 90°, or reading 10× too slow) is beyond the turbid water the
        // beacon is seen through (K_D 1.0 for the tank's 0.09 makes it 2.2×
        // at 3 m).
        let along = if d_dvl == 0.0 {
            -d_light.abs()
        } else {
            d_light * d_dvl.signum()
        };
        let least = REFUSE_BELOW * d_dvl.abs() - slack;
        // And only once the light has moved a metre: on station the law's
        // range drifts as the vehicle turns (which channel is brightest).
        let most = (REFUSE_ABOVE * d_dvl.abs() + slack).max(MIN_TRAVEL_M);
        if along < least || d_light.abs() > most {
            self.refused = true;
        } else {
            let ratio = d_light / d_dvl;
            if (TAKE[0]..=TAKE[1]).contains(&ratio) && d_dvl.abs() >= MIN_TRAVEL_M {
                self.refused = false;
            }
        }
    }

    fn newest(&self) -> Option<Sample> {
        (self.len > 0).then(|| self.ring[(self.head + RING - 1) % RING])
    }
}

/// Both checks and what the tracker did about them: about the sensor, so
/// kept across the filter's restarts and handed to a water bank's members.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct DvlChecks {
    range: RangeCheck,
    heading: HeadingCheck,
    /// The DVL stood refused at the last frame that asked (a first refusal
    /// starts the filter again once).
    restarted: bool,
}

impl DvlChecks {
    /// Whether either check refuses the DVL now.
    pub fn refused(&self) -> bool {
        self.range.refused() || self.heading.refused()
    }

    /// The verdicts alone, for a tracker of another calibration (a
    /// reload): the DVL's setup has not changed, but the windows hold this
    /// calibration's light. A refused DVL stays refused, and is taken
    /// again as a fresh window or track agrees; no second restart.
    pub fn verdicts(&self) -> DvlChecks {
        DvlChecks {
            range: self.range.verdict(),
            heading: self.heading.verdict(),
            restarted: self.refused(),
        }
    }

    /// What they last judged, into `a`.
    pub fn report(&self, a: &mut Agreement) {
        a.dvl_range_change_m = self.range.changes();
        a.dvl_turned_deg = self.heading.turned_deg();
        a.dvl_refused = self.refused();
    }
}

impl Tracker {
    /// The checks' standing verdict on the frame's DVL reading: refused
    /// while either check says so. Returns whether it was first refused
    /// since the last frame that asked: the state then followed the DVL,
    /// and the caller starts again without it.
    pub(super) fn apply_dvl_verdict(&mut self, r: &mut FrameReadings) -> bool {
        let refused = self.cfg.dvl_check && self.dvl.refused();
        if refused && r.velocity.ready().is_some() {
            r.velocity = Pending::Done(ReadingUse::Refused(Refusal::Light));
        }
        let first = refused && !self.dvl.restarted;
        self.dvl.restarted = refused;
        first
    }

    /// What the DVL checks read of this frame, before the update: the
    /// DVL's reading (forward, right, down, m/s; refused or not), the
    /// attitude reading (pitch, yaw, rad) and the law's reading of x
    /// (`law`, the frame's). A jump of the law's x no vehicle makes (a
    /// looped simulation, spliced logs) starts the checks' windows again
    /// here, whatever the filter does with the frame.
    pub(super) fn dvl_sample(
        &mut self,
        t: f64,
        r: &FrameReadings,
        law: Option<PaperReading>,
    ) -> Option<DvlSample> {
        let v = r.velocity.ready().filter(|_| self.cfg.dvl_check)?;
        let law = law?;
        let x = law.range.z[0];
        if self.dvl.range.jumped(t, x) {
            self.dvl.range.break_chain();
            self.dvl.heading.break_chain();
        }
        Some(DvlSample {
            v: [v.z[0], v.z[1], v.z[2]],
            att: r.attitude.ready().map(|a| [a.z[0], a.z[1]]),
            x,
            noise: law.noise,
        })
    }

    /// Give the checks the frame's sample, at state `s` after the frame's
    /// update (the bearing is the light's of this frame, as the attitude
    /// reading is). The law reads x, the beacon's axis: the state's
    /// geometry makes it a range (|p|/x, 1.004 at 5° off the axis). A frame
    /// without a sample is skipped: the windows go on across it while the
    /// gap is under `max_gap_s`.
    pub(super) fn observe_dvl(&mut self, t: f64, s: &State, sample: Option<DvlSample>) {
        let Some(d) = sample else {
            return;
        };
        let p = [s.x[0], s.x[1], s.x[2]];
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        if !(p[0] > 0.1 && r.is_finite()) {
            return;
        }
        let to_range = r / p[0];
        let (range, noise, gap) = (d.x * to_range, d.noise * to_range, self.cfg.max_gap_s);
        if let Some(rate) = range_rate(p, s.x[3], s.x[4], d.v) {
            self.dvl.range.push(t, [range, noise], rate, WINDOW_S, gap);
        }
        if let Some((light, vel)) = d.att.and_then(|att| horizontal(s, att, range, d.v)) {
            self.dvl.heading.push(t, light, vel, gap);
        }
    }
}

/// What the DVL checks read of one frame (`Tracker::dvl_sample`).
#[derive(Debug, Clone, Copy)]
pub(super) struct DvlSample {
    v: [f64; 3],
    att: Option<[f64; 2]>,
    /// The law's x (m) and its counts' noise (1σ, m).
    x: f64,
    noise: f64,
}

/// The vehicle's horizontal position in B by the light, and the DVL's
/// horizontal velocity in B, both at the attitude reading's pitch and yaw
/// `att` (rad): the law's `range` along the beacon's bearing in the body,
/// which the light pins (read off state `s`: a DVL that turned the
/// state's heading turned its position about the beacon with it, not the
/// bearing), and the DVL's velocity `v` (forward, right, down).
fn horizontal(s: &State, att: [f64; 2], range: f64, v: [f64; 3]) -> Option<([f64; 2], [f64; 2])> {
    let p = [s.x[0], s.x[1], s.x[2]];
    let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    if !(r > 1e-6) {
        return None;
    }
    let bearing = body_axes(s.x[3], s.x[4]).map(|a| -(a[0] * p[0] + a[1] * p[1] + a[2] * p[2]) / r);
    let axes = body_axes(att[0], att[1]);
    let (mut light, mut vel) = ([0.0; 2], [0.0; 2]);
    for i in 0..2 {
        for k in 0..3 {
            light[i] -= range * bearing[k] * axes[k][i];
            vel[i] += v[k] * axes[k][i];
        }
    }
    Some((light, vel))
}

/// The DVL's range rate, m/s (+ receding from the beacon): its velocity
/// (forward, right, down) in B through the body axes at pitch `theta` and
/// yaw `psi`, along the line of sight from the beacon to the vehicle at
/// `pos`.
pub(super) fn range_rate(pos: [f64; 3], theta: f64, psi: f64, v: [f64; 3]) -> Option<f64> {
    let r = (pos[0] * pos[0] + pos[1] * pos[1] + pos[2] * pos[2]).sqrt();
    if !(r > 1e-6) {
        return None;
    }
    let axes = body_axes(theta, psi);
    let mut rate = 0.0;
    for (a, vk) in axes.iter().zip(v) {
        for i in 0..3 {
            rate += vk * a[i] * pos[i] / r;
        }
    }
    rate.is_finite().then_some(rate)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames at 5 Hz from `t0` for `secs` of a vehicle coming and going
    /// between 4 and 8 m (a 20 s period), the DVL reading `scale` times
    /// the truth's range rate.
    fn run(check: &mut RangeCheck, t0: f64, secs: f64, scale: f64) -> bool {
        let w = std::f64::consts::PI / 10.0;
        let mut refused = check.refused();
        for k in 0..(secs * 5.0).round() as usize {
            let t = t0 + k as f64 * 0.2;
            let (range, rate) = (6.0 - 2.0 * (w * t).sin(), -2.0 * w * (w * t).cos());
            refused = check.push(t, [range, 0.02], rate * scale, 5.0, 2.0);
        }
        refused
    }

    #[test]
    fn a_good_dvl_and_water_that_scales_the_light_are_taken() {
        for scale in [1.0, 0.7, 1.5] {
            let mut c = RangeCheck::default();
            assert!(!run(&mut c, 0.0, 10.0, scale), "scale {scale}");
            let [l, d] = c.changes().expect("judged");
            assert!((l * scale - d).abs() < 0.01 * l.abs(), "{l} {d}");
        }
    }

    #[test]
    fn a_backwards_across_or_mistaken_dvl_is_refused() {
        // Backwards, across the bow (no range change), 10× (cm/s as dm/s).
        for scale in [-1.0, 0.0, 10.0, 0.1] {
            let mut c = RangeCheck::default();
            assert!(run(&mut c, 0.0, 5.0, scale), "scale {scale}");
        }
    }

    #[test]
    fn a_dvl_put_right_is_taken_again_and_a_doubtful_one_keeps_its_verdict() {
        let mut c = RangeCheck::default();
        assert!(run(&mut c, 0.0, 5.0, -1.0));
        // Between the bands (light 3× the DVL): the verdict stands.
        assert!(run(&mut c, 5.0, 10.0, 1.0 / 3.0));
        assert!(!run(&mut c, 15.0, 10.0, 1.0));
        // Never refused, a DVL 3× off stays taken: water cannot be told
        // from it by the range alone.
        let mut c = RangeCheck::default();
        assert!(!run(&mut c, 0.0, 20.0, 1.0 / 3.0));
        assert!(c
            .changes()
            .is_some_and(|[l, d]| (l - 3.0 * d).abs() < 0.05 * l.abs()));
    }

    #[test]
    fn too_little_travel_and_broken_chains_judge_nothing() {
        let mut c = RangeCheck::default();
        // On station: the DVL says 0.5 m/s backwards but nothing moves
        // far enough within a window broken every second.
        for k in 0..100 {
            let t = k as f64 * 0.2;
            if k % 5 == 0 {
                c.break_chain();
            }
            assert!(!c.push(t, [6.0, 0.02], 0.5, 5.0, 2.0));
        }
        assert_eq!(c.changes(), None);
        // Not finite: no panic, nothing judged.
        assert!(!c.push(30.0, [f64::NAN, 0.02], 0.5, 5.0, 2.0));
        assert!(!c.push(30.2, [6.0, -1.0], 0.5, 5.0, 2.0));
    }

    /// The law read at 10 m has counts' noise of its own (here 0.3 m per
    /// frame, told): a good DVL is not refused for it, and a backwards one
    /// still is.
    #[test]
    fn the_laws_noise_is_not_a_disagreement() {
        let mut seed = 7u64;
        let mut normal = || {
            let mut u = || {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        for (scale, want) in [(1.0, false), (-1.0, true)] {
            let mut c = RangeCheck::default();
            let mut refused = false;
            for k in 0..150 {
                let t = k as f64 * 0.2;
                let w = std::f64::consts::TAU / 20.0;
                let range = 10.0 - 1.5 * (w * t).sin() + 0.3 * normal();
                let rate = -1.5 * w * (w * t).cos();
                refused |= c.push(t, [range, 0.3], rate * scale, 5.0, 2.0);
            }
            assert_eq!(refused, want, "scale {scale}: {:?}", c.changes());
        }
    }

    /// The law's range jumping further than a vehicle moves (a looped
    /// simulation) is told; its wander and a fast vehicle's travel are not.
    #[test]
    fn a_jump_of_the_light_is_told() {
        let mut c = RangeCheck::default();
        assert!(!c.jumped(0.0, 8.0));
        assert!(!c.jumped(0.2, 7.6));
        assert!(!c.jumped(1.2, 3.0));
        assert!(c.jumped(1.4, 8.5));
        assert!(!c.jumped(1.6, 8.4));
    }

    /// A DVL that says the vehicle moves while the light's range stays put
    /// (stuck reporting an old velocity) is refused too.
    #[test]
    fn a_dvl_moving_a_vehicle_on_station_is_refused() {
        let mut c = RangeCheck::default();
        let refused = (0..25).any(|k| c.push(k as f64 * 0.2, [6.0, 0.02], 0.5, 5.0, 2.0));
        assert!(refused);
    }

    proptest::proptest! {
        /// The range rate is the derivative of the range as the vehicle
        /// moves by its body velocity through its axes.
        #[test]
        fn the_range_rate_is_the_ranges_derivative(
            x in 1.0f64..15.0, y in -3.0f64..3.0, z in -3.0f64..3.0,
            theta in -1.2f64..1.2, psi in -3.0f64..3.0,
            u in -1.0f64..1.0, v in -1.0f64..1.0, w in -1.0f64..1.0,
        ) {
            let rate = range_rate([x, y, z], theta, psi, [u, v, w]).unwrap();
            let axes = crate::model::tracker::state::body_axes(theta, psi);
            let h = 1e-6;
            let moved: Vec<f64> = (0..3)
                .map(|i| [x, y, z][i] + h * (u * axes[0][i] + v * axes[1][i] + w * axes[2][i]))
                .collect();
            let r = |p: &[f64]| p.iter().map(|c| c * c).sum::<f64>().sqrt();
            let numeric = (r(&moved) - r(&[x, y, z])) / h;
            proptest::prop_assert!((numeric - rate).abs() < 1e-5, "{numeric} vs {rate}");
        }
    }

    #[test]
    fn the_range_rate_is_the_velocity_along_the_line_of_sight() {
        // Level, facing the beacon (yaw 0): forward is −x in B.
        let r = range_rate([6.0, 0.0, 0.0], 0.0, 0.0, [0.5, 0.0, 0.0]).unwrap();
        assert!((r + 0.5).abs() < 1e-12);
        // Sideways to the line of sight: no range change.
        let r = range_rate([6.0, 0.0, 0.0], 0.0, 0.0, [0.0, 0.3, 0.0]).unwrap();
        assert!(r.abs() < 1e-12);
        // Down (−z in B) from below the beacon: receding.
        let r = range_rate([0.0, 0.0, -5.0], 0.0, 0.0, [0.0, 0.0, 0.2]).unwrap();
        assert!((r - 0.2).abs() < 1e-12);
        assert_eq!(range_rate([0.0; 3], 0.0, 0.0, [1.0; 3]), None);
    }
}
