//! The vehicle's latest readings (attitude, depth, water temperature, DVL
//! velocity), each with the moment it was taken, as the receivers left
//! them; the frame thread attaches to each frame those that are fresh at
//! the frame's capture.
//!
//! Readings are already in the frames of MODEL.md when stored (pitch and
//! yaw in B, z in B, velocity in V). An attitude stored with its rates
//! ([`AttitudeRates`], from ATTITUDE's body rates) is carried from the
//! moment it was taken to the frame's capture, and a depth by the DVL's
//! climb rate, each std widened by the carry's error; the others are
//! copied as they are (docs/vehicle.md, "Time"). A carried reading without
//! a std of its own (MAVLink's) gets the σ the estimator assumes for it
//! ([`AssumedStd`], told by the daemon), widened. Neither storing nor
//! attaching allocates or takes a lock (see `latest`).

use crate::latest::{opt, word, Latest};
use crate::ned::wrap_pi;
use lightpose_core::{Angle, AttitudeReading, AttitudeStd, BodyVec, DepthReading, Frame};
use lightpose_core::{AttitudeReading as Att, VelocityReading};
use serde::Serialize;
use std::f64::consts::FRAC_PI_2;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// How fast pitch and yaw in B change (rad/s): the Euler angle rates of
/// the attitude, not the gyro's body rates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeRates {
    pub pitch: f64,
    pub yaw: f64,
}

/// Body rates above a gyro's range (2000 °/s) are no rates.
const MAX_BODY_RATE: f64 = 2000.0 * std::f64::consts::PI / 180.0;
/// Within about 6° of pointing straight up or down yaw is ill-defined and
/// its rate (÷ cos θ) unbounded: no rates there.
const MIN_COS_PITCH: f64 = 0.1;
/// The longest a rate is trusted to hold (either way): an attitude is
/// carried at most this far, so a long `max_age` does not turn a rate into
/// a large made-up turn.
const MAX_CARRY_S: f64 = 0.5;

impl AttitudeRates {
    /// Pitch and yaw rates from the body rates q (pitch) and r (yaw) of an
    /// FRD body at roll φ and pitch θ (radians, rad/s): θ̇ = q cos φ − r sin φ
    /// and ψ̇ = (q sin φ + r cos φ) / cos θ, the Z-Y-X Euler kinematics of
    /// ArduPilot's ATTITUDE. Yaw in B is the heading less a constant
    /// (`Site::yaw_b`) and pitch in B is the pitch, so these are B's rates
    /// too. `None` for rates not finite, beyond a gyro's range, or near
    /// θ = ±90° (see [`MIN_COS_PITCH`]).
    pub fn from_body(roll: f64, pitch: f64, q: f64, r: f64) -> Option<AttitudeRates> {
        let ok = |w: f64| w.is_finite() && w.abs() <= MAX_BODY_RATE;
        if !(ok(q) && ok(r) && roll.is_finite() && pitch.is_finite()) {
            return None;
        }
        let (sr, cr) = roll.sin_cos();
        let cp = pitch.cos();
        if cp.abs() < MIN_COS_PITCH {
            return None;
        }
        Some(AttitudeRates {
            pitch: q * cr - r * sr,
            yaw: (q * sr + r * cr) / cp,
        })
    }
}

/// Seconds from `taken` to `at` (negative for a reading newer than the
/// capture), not bounded: how far the reading is from the capture.
fn span_s(taken: Instant, at: Instant) -> f64 {
    if at >= taken {
        (at - taken).as_secs_f64()
    } else {
        -(taken - at).as_secs_f64()
    }
}

/// `span` within ±[`MAX_CARRY_S`]: how far a reading is carried.
fn carry_s(span: f64) -> f64 {
    span.clamp(-MAX_CARRY_S, MAX_CARRY_S)
}

const DEG: f64 = std::f64::consts::PI / 180.0;

/// White angular-acceleration density (rad/s²)²/Hz behind the carry's
/// error: the tracker's default `ang_accel_psd_deg`, 20 (°/s²)²/Hz
/// (docs/estimators.md), so that a carried reading is as uncertain as the
/// tracker's own prediction over the same time from a known rate. For an
/// ROV it is a change of rate of √20 ≈ 4.5 °/s in a second, 1.4 °/s in
/// 0.1 s: a turn started or stopped within the carry.
const CARRY_ANG_ACCEL_PSD: f64 = 20.0 * DEG * DEG;

/// 1σ of ATTITUDE's Euler rates (rad/s): 0.5 °/s. A MEMS gyro's noise
/// through the autopilot's low-pass is a few hundredths of a °/s and its
/// bias left after the EKF about 0.1 °/s; the rest is for thruster
/// vibration and the Euler conversion's roll (1° of roll in a 30 °/s turn
/// moves θ̇ by 0.5 °/s). Small beside the acceleration's term beyond
/// 0.1 s (0.125° against 0.32° at 0.25 s).
const CARRY_RATE_STD: f64 = 0.5 * DEG;

/// The variance a carry adds to an angle (rad²): the reading is `span`
/// seconds from the capture and was carried `dt` of them at `rate`. With a
/// white angular acceleration of density q the carried angle is off by
/// ∫(ω(s) − ω(taken)) ds, of variance q·|span|³/3; the rate's own error
/// adds (σ_ω·|span|)²; and beyond [`MAX_CARRY_S`] the turn not made,
/// (rate·(|span| − |dt|))², is off in full.
fn carry_var(rate: f64, span: f64, dt: f64) -> f64 {
    let s = span.abs();
    let dropped = rate * (s - dt.abs());
    CARRY_ANG_ACCEL_PSD * s * s * s / 3.0 + (CARRY_RATE_STD * s).powi(2) + dropped * dropped
}

/// `std` grown in quadrature by `var`. A std that is not finite and
/// positive is left as it is (the estimator refuses it: widening must not
/// turn a bad std into a good one).
fn widened(std: f64, var: f64) -> f64 {
    let w = (std * std + var).sqrt();
    if var > 0.0 && std.is_finite() && std > 0.0 && w.is_finite() {
        w
    } else {
        std
    }
}

/// A std the estimator takes (finite and positive).
fn usable(std: f64) -> bool {
    std.is_finite() && std > 0.0
}

/// The σ (1σ) the estimator assumes for a reading that brings no std of
/// its own: its configured `attitude_sigma_pitch_deg`,
/// `attitude_sigma_yaw_deg` and `depth_sigma_m`. A reading without a std
/// that is carried (its carry adds a variance above 0) goes on the frame
/// with this σ widened by the carry's error, so that the estimator does
/// not take it as surely as one taken at the capture; one not carried
/// keeps no std (the estimator's σ applies as it is). Told to
/// [`Readings::assume_std`] by whoever built the estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssumedStd {
    pub pitch: Angle,
    pub yaw: Angle,
    pub depth_m: f64,
}

/// `a` carried from `taken` to `at` at `rates`, over at most
/// [`MAX_CARRY_S`] either way (a reading newer than the capture is carried
/// back). Yaw is wrapped into (−180°, 180°], pitch kept within ±90°. Its
/// std, if it has one, grows by the carry's error ([`carry_var`]), back as
/// well as forward. A reading without a std that is carried (`at` ≠
/// `taken`) gets `assumed`'s pitch and yaw σ, widened the same way, if
/// both are usable; otherwise, or not carried, it keeps none (the
/// estimator's configured σ applies, which does not know the carry).
///
/// A reading without rates is neither carried nor widened, though it is off
/// by about rate × age: the rate is unknown here, an ROV's spread of rates
/// (still on station, 30 °/s in a turn) is no one number, and the error is
/// a lag shared by successive frames, which a wider σ would only lighten,
/// not describe (the tracker, which has the rate, is where it could be
/// taken off).
fn carried(
    a: Att,
    rates: Option<AttitudeRates>,
    assumed: Option<AssumedStd>,
    taken: Instant,
    at: Instant,
) -> Att {
    let Some(w) = rates else { return a };
    let span = span_s(taken, at);
    let dt = carry_s(span);
    let (var_pitch, var_yaw) = (carry_var(w.pitch, span, dt), carry_var(w.yaw, span, dt));
    let std = match a.std {
        Some(s) => Some((s.pitch.rad(), s.yaw.rad())),
        None if var_pitch > 0.0 && var_yaw > 0.0 => assumed
            .map(|s| (s.pitch.rad(), s.yaw.rad()))
            .filter(|&(p, y)| usable(p) && usable(y)),
        None => None,
    };
    Att {
        pitch: Angle::from_rad((a.pitch.rad() + w.pitch * dt).clamp(-FRAC_PI_2, FRAC_PI_2)),
        yaw: wrap_pi(Angle::from_rad(a.yaw.rad() + w.yaw * dt)),
        roll: a.roll,
        std: std.map(|(p, y)| AttitudeStd {
            pitch: Angle::from_rad(widened(p, var_pitch)),
            yaw: Angle::from_rad(widened(y, var_yaw)),
        }),
    }
}

/// `d` carried from `taken` to `at` by the vehicle's climb rate in B, from
/// the DVL's velocity (V, FRD) and the pitch: ż = sin θ·v_fwd − cos θ·v_down
/// (the tracker's depth model: the forward axis climbs at sin θ, the down
/// axis at −cos θ; roll left out, as there), over at most [`MAX_CARRY_S`]
/// either way. Without a velocity or an attitude, as it is. Why: a pressure
/// sensor streamed at 5–10 Hz is 0.1–0.2 s old at a frame's capture, 0.05–0.1
/// m at 0.5 m/s of descent against its σ of 0.02 m.
///
/// Its std, if it has one, grows in quadrature by the climb rate's error
/// over the carry: σ_climb² = (sin θ·σ_fwd)² + (cos θ·σ_down)² from the
/// DVL's std (its components taken as independent, as they are stored),
/// times span²; beyond [`MAX_CARRY_S`] also the climb not carried. The
/// pitch's error is left out (0.3° at 1 m/s is 0.005 m/s against a DVL's
/// 0.02), and so is the heave's change during the carry (the DVL does not
/// report acceleration). A velocity without a std adds nothing.
///
/// A depth without a std whose carry adds a variance (a DVL with a std,
/// or a carry beyond [`MAX_CARRY_S`]) gets `assumed_m` (the estimator's
/// `depth_sigma_m`), if usable, widened the same way; otherwise it keeps
/// none.
fn carried_depth(
    d: DepthReading,
    att: Option<&AttitudeReading>,
    vel: Option<&VelocityReading>,
    assumed_m: Option<f64>,
    taken: Instant,
    at: Instant,
) -> DepthReading {
    let (Some(att), Some(vel)) = (att, vel) else {
        return d;
    };
    let span = span_s(taken, at);
    let dt = carry_s(span);
    let (st, ct) = att.pitch.rad().sin_cos();
    let [fwd, _, down] = vel.v.0;
    let climb = st * fwd - ct * down;
    let z = d.z + climb * dt;
    let climb_var = vel.std.map_or(0.0, |s| {
        let [sf, _, sd] = s.0;
        (st * sf).powi(2) + (ct * sd).powi(2)
    });
    let dropped = climb * (span.abs() - dt.abs());
    let var = climb_var * span * span + dropped * dropped;
    let std = d
        .std
        .or_else(|| assumed_m.filter(|&s| var > 0.0 && usable(s)));
    if z.is_finite() {
        DepthReading {
            z,
            std: std.map(|s| widened(s, var)),
        }
    } else {
        d
    }
}

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
    /// taken, pitch, yaw, their std, their rates (rad/s; NaN: none), and
    /// roll (rad; NaN: the sender gave none, spec v3).
    attitude: Latest<8>,
    depth: Latest<3>,
    temperature: Latest<2>,
    velocity: Latest<7>,
    /// The estimator's σ for a reading without one ([`AssumedStd`]):
    /// pitch, yaw (rad), depth (m). Never written: none.
    assumed: Latest<3>,
    uses: [Use; 4],
}

const ATT: usize = 0;
const DEPTH: usize = 1;
const TEMP: usize = 2;
const VEL: usize = 3;

impl Default for Readings {
    fn default() -> Self {
        // An hour back: a reading taken before the hub was made (a DVL's
        // time of validity at start) keeps its moment rather than being
        // moved up to the epoch, which would carry an attitude wrongly.
        let now = Instant::now();
        Readings {
            epoch: now.checked_sub(Duration::from_secs(3600)).unwrap_or(now),
            attitude: Latest::default(),
            depth: Latest::default(),
            temperature: Latest::default(),
            velocity: Latest::default(),
            assumed: Latest::default(),
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

impl ReadingsStatus {
    /// One attitude's figures (an input of its own), the rest empty.
    pub fn only_attitude(attitude: ReadingStatus) -> Self {
        let none = ReadingStatus {
            age_s: None,
            stored: 0,
            attached: 0,
            stale: 0,
        };
        ReadingsStatus {
            attitude,
            depth: none,
            temperature: none,
            velocity: none,
        }
    }
}

impl Readings {
    fn stamp(&self, at: Instant) -> u64 {
        at.saturating_duration_since(self.epoch).as_nanos() as u64
    }

    /// `Some((taken, words))` if the cell holds a reading taken no longer
    /// than `max_age` before `at` (one taken after `at` is fresh); counts a
    /// stale one.
    #[inline]
    fn fresh<const N: usize>(
        &self,
        cell: &Latest<N>,
        k: usize,
        at: Instant,
        max_age: Duration,
    ) -> Option<(Instant, [u64; N])> {
        let (_, w) = cell.load()?;
        let taken = self.epoch + Duration::from_nanos(w[0]);
        if at.saturating_duration_since(taken) <= max_age {
            Some((taken, w))
        } else {
            self.uses[k].stale.fetch_add(1, Relaxed);
            None
        }
    }

    /// The σ the estimator assumes for a reading without a std of its own
    /// (`None`: none, as before any was told): from the next frame on, a
    /// carried reading without a std goes on the frame with it, widened by
    /// the carry (see [`AssumedStd`]). Told when the estimator is built (at
    /// start and at a calibration reload); neither allocates nor locks. A
    /// σ not finite makes it none as a whole.
    pub fn assume_std(&self, s: Option<AssumedStd>) {
        self.assumed.store([
            word(s.map(|s| s.pitch.rad())),
            word(s.map(|s| s.yaw.rad())),
            word(s.map(|s| s.depth_m)),
        ]);
    }

    /// The σ last told to [`Readings::assume_std`], if any.
    pub fn assumed_std(&self) -> Option<AssumedStd> {
        let (_, w) = self.assumed.load()?;
        Some(AssumedStd {
            pitch: Angle::from_rad(opt(w[0])?),
            yaw: Angle::from_rad(opt(w[1])?),
            depth_m: opt(w[2])?,
        })
    }

    /// An attitude without rates: attached as it is.
    pub fn store_attitude(&self, at: Instant, r: &AttitudeReading) {
        self.store_attitude_with_rates(at, r, None);
    }

    /// An attitude and, if known, how fast it changes: attached carried to
    /// the frame's capture.
    pub fn store_attitude_with_rates(
        &self,
        at: Instant,
        r: &AttitudeReading,
        rates: Option<AttitudeRates>,
    ) {
        let s = r.std.map(|s| (s.pitch.rad(), s.yaw.rad()));
        self.attitude.store([
            self.stamp(at),
            r.pitch.rad().to_bits(),
            r.yaw.rad().to_bits(),
            word(s.map(|s| s.0)),
            word(s.map(|s| s.1)),
            word(rates.map(|w| w.pitch)),
            word(rates.map(|w| w.yaw)),
            word(r.roll.map(|r| r.rad())),
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

    /// The latest attitude if fresh at `at`, carried to `at` by its rates
    /// when it has them (a std-less one given the assumed σ, widened: see
    /// [`AssumedStd`]).
    pub fn attitude(&self, at: Instant, max_age: Duration) -> Option<AttitudeReading> {
        let (taken, w) = self.fresh(&self.attitude, ATT, at, max_age)?;
        let std = match (opt(w[3]), opt(w[4])) {
            (Some(p), Some(y)) => Some(AttitudeStd {
                pitch: Angle::from_rad(p),
                yaw: Angle::from_rad(y),
            }),
            _ => None,
        };
        let rates = match (opt(w[5]), opt(w[6])) {
            (Some(pitch), Some(yaw)) => Some(AttitudeRates { pitch, yaw }),
            _ => None,
        };
        let a = Att {
            pitch: Angle::from_rad(f64::from_bits(w[1])),
            yaw: Angle::from_rad(f64::from_bits(w[2])),
            roll: opt(w[7]).map(Angle::from_rad),
            std,
        };
        let assumed = if a.std.is_none() && rates.is_some() {
            self.assumed_std()
        } else {
            None
        };
        Some(carried(a, rates, assumed, taken, at))
    }

    /// The latest depth reading (z in B) if fresh at `at`.
    pub fn depth(&self, at: Instant, max_age: Duration) -> Option<DepthReading> {
        self.depth_taken(at, max_age).map(|(_, d)| d)
    }

    /// The latest depth reading if fresh at `at`, and when it was taken.
    fn depth_taken(&self, at: Instant, max_age: Duration) -> Option<(Instant, DepthReading)> {
        let (taken, w) = self.fresh(&self.depth, DEPTH, at, max_age)?;
        let d = DepthReading {
            z: f64::from_bits(w[1]),
            std: opt(w[2]),
        };
        Some((taken, d))
    }

    /// The latest water temperature (°C) if fresh at `at`.
    pub fn temperature(&self, at: Instant, max_age: Duration) -> Option<f64> {
        let (_, w) = self.fresh(&self.temperature, TEMP, at, max_age)?;
        Some(f64::from_bits(w[1]))
    }

    /// The latest DVL velocity (V, FRD) if fresh at `at`.
    pub fn velocity(&self, at: Instant, max_age: Duration) -> Option<VelocityReading> {
        let (_, w) = self.fresh(&self.velocity, VEL, at, max_age)?;
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

    /// Give `frame` every reading that is fresh at `capture` (the instant
    /// the frame was sampled) and that the frame does not carry already (a
    /// recording's or the simulator's own readings win); an attitude with
    /// rates is carried to `capture`, and a depth by the DVL's climb rate,
    /// a carried one without a std given the assumed σ widened
    /// ([`AssumedStd`]). For the frame thread: no allocation, no lock.
    pub fn attach(&self, frame: &mut Frame, capture: Instant, max_age: &MaxAge) -> Attached {
        let mut a = Attached::default();
        if frame.attitude.is_none() {
            frame.attitude = self.attitude(capture, max_age.attitude);
            a.attitude = frame.attitude.is_some();
        }
        if frame.velocity.is_none() {
            frame.velocity = self.velocity(capture, max_age.velocity);
            a.velocity = frame.velocity.is_some();
        }
        if frame.depth.is_none() {
            frame.depth = self.depth_taken(capture, max_age.depth).map(|(taken, d)| {
                let assumed = if d.std.is_none() {
                    self.assumed_std().map(|s| s.depth_m)
                } else {
                    None
                };
                carried_depth(
                    d,
                    frame.attitude.as_ref(),
                    frame.velocity.as_ref(),
                    assumed,
                    taken,
                    capture,
                )
            });
            a.depth = frame.depth.is_some();
        }
        if frame.temp_c.is_none() {
            frame.temp_c = self.temperature(capture, max_age.temperature);
            a.temperature = frame.temp_c.is_some();
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

    /// How long before `now` the latest reading of `cell` was taken.
    fn age<const N: usize>(&self, cell: &Latest<N>, now: Instant) -> Option<Duration> {
        cell.load()
            .map(|(_, w)| now.saturating_duration_since(self.epoch + Duration::from_nanos(w[0])))
    }

    /// How long before `now` the latest attitude was taken.
    pub fn attitude_age(&self, now: Instant) -> Option<Duration> {
        self.age(&self.attitude, now)
    }

    fn one_status<const N: usize>(
        &self,
        cell: &Latest<N>,
        k: usize,
        now: Instant,
    ) -> ReadingStatus {
        let age_s = self.age(cell, now).map(|d| d.as_secs_f64());
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

    fn deg(d: f64) -> Angle {
        Angle::from_deg(d)
    }

    fn rates(pitch_dps: f64, yaw_dps: f64) -> Option<AttitudeRates> {
        Some(AttitudeRates {
            pitch: pitch_dps.to_radians(),
            yaw: yaw_dps.to_radians(),
        })
    }

    /// The attitude `r` gives a frame captured at `at` (pitch, yaw in °).
    fn attached(r: &Readings, at: Instant, max_age: &MaxAge) -> Option<(f64, f64)> {
        let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
        r.attach(&mut f, at, max_age);
        f.attitude.map(|a| (a.pitch.deg(), a.yaw.deg()))
    }

    fn near(got: Option<(f64, f64)>, want: (f64, f64)) -> bool {
        got.is_some_and(|g| (g.0 - want.0).abs() < 1e-9 && (g.1 - want.1).abs() < 1e-9)
    }

    /// Audit: an attitude went on a frame as it was when taken, 70–200 ms
    /// before the frame's capture: at 30 °/s, 2–6° of yaw. With ATTITUDE's
    /// rates it is carried to the capture, forward or back.
    #[test]
    fn an_attitude_is_carried_to_the_capture_by_its_rates() {
        let r = Readings::default();
        let t0 = Instant::now();
        let ages = MaxAge::default();
        let a = AttitudeReading::new(deg(2.0), deg(10.0));
        r.store_attitude_with_rates(t0, &a, rates(-4.0, 30.0));
        // Captured 150 ms after the reading was taken (its arrival later
        // still does not matter).
        let capture = t0 + Duration::from_millis(150);
        let got = attached(&r, capture, &ages);
        assert!(near(got, (2.0 - 0.6, 10.0 + 4.5)), "{got:?}");
        // A reading taken 40 ms after the capture is carried back.
        r.store_attitude_with_rates(capture + Duration::from_millis(40), &a, rates(-4.0, 30.0));
        let got = attached(&r, capture, &ages);
        assert!(near(got, (2.0 + 0.16, 10.0 - 1.2)), "{got:?}");
        // Without rates (the UDP input, a message without them): as taken.
        r.store_attitude(t0, &a);
        assert!(near(attached(&r, capture, &ages), (2.0, 10.0)));
    }

    /// Yaw carried across ±180° comes out wrapped into (−180°, 180°].
    #[test]
    fn a_carried_yaw_wraps_across_180() {
        let r = Readings::default();
        let t0 = Instant::now();
        let ages = MaxAge::default();
        let at = t0 + Duration::from_millis(150);
        r.store_attitude_with_rates(
            t0,
            &AttitudeReading::new(deg(0.0), deg(178.0)),
            rates(0.0, 30.0),
        );
        let got = attached(&r, at, &ages);
        assert!(near(got, (0.0, -177.5)), "{got:?}");
        r.store_attitude_with_rates(
            t0,
            &AttitudeReading::new(deg(0.0), deg(-179.0)),
            rates(0.0, -30.0),
        );
        let got = attached(&r, at, &ages);
        assert!(near(got, (0.0, 176.5)), "{got:?}");
        // Carried back from after the capture, the other way across.
        let later = at + Duration::from_millis(100);
        r.store_attitude_with_rates(
            later,
            &AttitudeReading::new(deg(0.0), deg(-179.0)),
            rates(0.0, 30.0),
        );
        let got = attached(&r, at, &ages);
        assert!(near(got, (0.0, 178.0)), "{got:?}");
        // Pitch stops at ±90°.
        r.store_attitude_with_rates(
            t0,
            &AttitudeReading::new(deg(89.0), deg(0.0)),
            rates(30.0, 0.0),
        );
        assert!(near(attached(&r, at, &ages), (90.0, 0.0)));
    }

    /// Freshness is judged at the capture: a reading taken after it is
    /// fresh, one older than the limit at it is stale (rates or not), and
    /// a long limit does not let a rate run on for seconds.
    #[test]
    fn age_is_measured_at_the_capture_and_carrying_is_bounded() {
        let r = Readings::default();
        let t0 = Instant::now();
        let ages = MaxAge::default();
        let a = AttitudeReading::new(deg(0.0), deg(0.0));
        r.store_attitude_with_rates(t0, &a, rates(0.0, 30.0));
        // 250 ms is still fresh; 251 ms is stale and counted, whatever the
        // rates could have carried it to.
        assert!(near(
            attached(&r, t0 + Duration::from_millis(250), &ages),
            (0.0, 7.5)
        ));
        assert_eq!(attached(&r, t0 + Duration::from_millis(251), &ages), None);
        assert_eq!(r.status(t0).attitude.stale, 1);
        // Captured a second before the reading was taken: fresh, carried
        // back by 0.5 s at most.
        let got = attached(&r, t0 - Duration::from_secs(1), &ages);
        assert!(near(got, (0.0, -15.0)), "{got:?}");
        // A 10 s limit: a reading 2 s old is carried 0.5 s, not 2 s.
        let long = MaxAge {
            attitude: Duration::from_secs(10),
            ..ages
        };
        let got = attached(&r, t0 + Duration::from_secs(2), &long);
        assert!(near(got, (0.0, 15.0)), "{got:?}");
        // Depth is judged at the capture too, and without a DVL velocity
        // not carried.
        r.store_depth(t0, &DepthReading::new(0.4));
        let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
        r.attach(&mut f, t0 - Duration::from_millis(100), &ages);
        assert_eq!(f.depth.map(|d| d.z), Some(0.4));
    }

    /// With a DVL velocity and a pitch, a depth reading is carried to the
    /// capture by the climb rate in B (z up): sin θ·v_fwd − cos θ·v_down.
    #[test]
    fn depth_is_carried_to_the_capture_by_the_dvl_s_climb_rate() {
        let ages = MaxAge::default();
        let depth_at = |pitch: f64, v: [f64; 3], ms: i64| {
            let r = Readings::default();
            let t0 = Instant::now() + Duration::from_secs(5);
            r.store_depth(t0, &DepthReading::new(-1.0));
            r.store_velocity(t0, &VelocityReading::new(v[0], v[1], v[2]));
            r.store_attitude(t0, &AttitudeReading::new(deg(pitch), deg(0.0)));
            let at = if ms >= 0 {
                t0 + Duration::from_millis(ms as u64)
            } else {
                t0 - Duration::from_millis((-ms) as u64)
            };
            let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
            r.attach(&mut f, at, &ages);
            f.depth.map(|d| d.z).expect("a depth")
        };
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // Level, descending at 0.5 m/s, captured 0.2 s after the reading:
        // 0.1 m deeper (z falls).
        assert!(close(depth_at(0.0, [0.0, 0.0, 0.5], 200), -1.1));
        // Nose up 30°, 1 m/s ahead: climbing at 0.5 m/s.
        assert!(close(depth_at(30.0, [1.0, 0.0, 0.0], 200), -0.9));
        // Captured before the reading: carried back.
        assert!(close(depth_at(0.0, [0.0, 0.0, 0.5], -100), -0.95));
        // Sideways motion does not change depth.
        assert!(close(depth_at(0.0, [0.0, 0.7, 0.0], 200), -1.0));
    }

    /// An attitude reading with its own std (all in °).
    fn with_std(pitch: f64, yaw: f64, s_pitch: f64, s_yaw: f64) -> AttitudeReading {
        AttitudeReading {
            std: Some(AttitudeStd {
                pitch: deg(s_pitch),
                yaw: deg(s_yaw),
            }),
            ..AttitudeReading::new(deg(pitch), deg(yaw))
        }
    }

    /// The std of the attitude `r` gives a frame captured at `at`.
    fn attached_std(r: &Readings, at: Instant, max_age: &MaxAge) -> Option<AttitudeStd> {
        let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
        r.attach(&mut f, at, max_age);
        f.attitude.expect("an attitude").std
    }

    /// The carry's model in °: σ² + q·|Δ|³/3 + (σ_ω·|Δ|)², q = 20 (°/s²)²/Hz,
    /// σ_ω = 0.5 °/s.
    fn model(std: f64, span: f64) -> f64 {
        (std * std + 20.0 * span.powi(3) / 3.0 + (0.5 * span).powi(2)).sqrt()
    }

    fn close_std(got: Option<AttitudeStd>, pitch: f64, yaw: f64) -> bool {
        got.is_some_and(|s| {
            (s.pitch.deg() - pitch).abs() < 1e-9 && (s.yaw.deg() - yaw).abs() < 1e-9
        })
    }

    /// Audit: a carried attitude kept the std of the reading, as if the
    /// rates held exactly over the carry. It grows by the carry's error:
    /// in quadrature, q·|Δ|³/3 from the angular acceleration plus the
    /// rate's own (σ_ω·|Δ|)², forward and back alike.
    #[test]
    fn a_carried_attitude_s_std_grows_with_the_carry() {
        let r = Readings::default();
        let t0 = Instant::now() + Duration::from_secs(5);
        let ages = MaxAge::default();
        let a = with_std(2.0, 10.0, 0.3, 1.5);
        r.store_attitude_with_rates(t0, &a, rates(-4.0, 30.0));
        // No carry: the reading's own std, bit for bit.
        assert_eq!(attached_std(&r, t0, &ages), a.std);
        // 0.1 s and 0.25 s (the default limit) forward.
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let s1 = attached_std(&r, at(100), &ages);
        assert!(close_std(s1, model(0.3, 0.1), model(1.5, 0.1)), "{s1:?}");
        let s25 = attached_std(&r, at(250), &ages);
        assert!(
            close_std(s25, model(0.3, 0.25), model(1.5, 0.25)),
            "{s25:?}"
        );
        // The numbers docs/vehicle.md gives: pitch 0.3° → 0.315° / 0.458°,
        // yaw 1.5° → 1.503° / 1.539°; the carry alone 0.096° / 0.346°.
        let s25 = s25.unwrap();
        assert!((s25.pitch.deg() - 0.458_03).abs() < 1e-5, "{s25:?}");
        assert!((s25.yaw.deg() - 1.539_41).abs() < 1e-5, "{s25:?}");
        assert!((model(0.0, 0.1) - 0.095_74).abs() < 1e-5);
        assert!((model(0.0, 0.25) - 0.346_11).abs() < 1e-5);
        // A reading newer than the capture by 0.1 s, carried back: widened
        // as much as one 0.1 s older.
        r.store_attitude_with_rates(at(100), &a, rates(-4.0, 30.0));
        let back = attached_std(&r, t0, &ages);
        assert!(
            close_std(back, model(0.3, 0.1), model(1.5, 0.1)),
            "{back:?}"
        );
        // Beyond the 0.5 s a rate is trusted, the turn not made is off in
        // full: 2 s old under a 10 s limit, carried 0.5 s, 1.5 s of 4 °/s
        // and 30 °/s left.
        r.store_attitude_with_rates(t0, &a, rates(-4.0, 30.0));
        let long = MaxAge {
            attitude: Duration::from_secs(10),
            ..ages
        };
        let far = attached_std(&r, t0 + Duration::from_secs(2), &long);
        let add = |std: f64, left: f64| (model(std, 2.0).powi(2) + left * left).sqrt();
        assert!(close_std(far, add(0.3, 6.0), add(1.5, 45.0)), "{far:?}");
        // Without rates: neither carried nor widened (see `carried`).
        r.store_attitude(t0, &a);
        assert_eq!(attached_std(&r, at(200), &ages), a.std);
        // Without a std, and no σ told (`assume_std`): still none (the
        // estimator's σ applies).
        r.store_attitude_with_rates(
            t0,
            &AttitudeReading::new(deg(2.0), deg(10.0)),
            rates(-4.0, 30.0),
        );
        assert_eq!(attached_std(&r, at(200), &ages), None);
        // A std of 0 (which the estimator refuses) is not made acceptable.
        r.store_attitude_with_rates(t0, &with_std(2.0, 10.0, 0.0, 1.5), rates(-4.0, 30.0));
        let s = attached_std(&r, at(200), &ages).unwrap();
        assert_eq!(s.pitch.rad(), 0.0);
        assert!((s.yaw.deg() - model(1.5, 0.2)).abs() < 1e-9, "{s:?}");
    }

    /// A carried depth's std grows by the DVL's error in the climb rate
    /// over the carry: σ_climb² = (sin θ·σ_fwd)² + (cos θ·σ_down)².
    #[test]
    fn a_carried_depth_s_std_grows_with_the_dvl_s_std() {
        let ages = MaxAge::default();
        let depth_at = |std: Option<f64>, v_std: Option<[f64; 3]>, ms: i64| {
            let r = Readings::default();
            let t0 = Instant::now() + Duration::from_secs(5);
            r.store_depth(t0, &DepthReading { z: -1.0, std });
            r.store_velocity(
                t0,
                &VelocityReading {
                    std: v_std.map(BodyVec),
                    ..VelocityReading::new(1.0, 0.0, 0.5)
                },
            );
            r.store_attitude(t0, &AttitudeReading::new(deg(30.0), deg(0.0)));
            let at = if ms >= 0 {
                t0 + Duration::from_millis(ms as u64)
            } else {
                t0 - Duration::from_millis((-ms) as u64)
            };
            let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
            r.attach(&mut f, at, &ages);
            f.depth.expect("a depth")
        };
        let dvl = Some([0.02, 0.01, 0.03]);
        // Nose up 30°: σ_climb² = (0.5·0.02)² + (cos 30°·0.03)² = 0.000775.
        let climb_var = 0.000_775;
        let close = |d: DepthReading, want: f64| d.std.is_some_and(|s| (s - want).abs() < 1e-12);
        let d = depth_at(Some(0.02), dvl, 200);
        assert!(close(d, (0.0004f64 + climb_var * 0.04).sqrt()), "{d:?}");
        assert!((d.std.unwrap() - 0.020_761).abs() < 1e-6, "{d:?}");
        // Carried back 0.1 s: widened by 0.1 s of it.
        let d = depth_at(Some(0.02), dvl, -100);
        assert!(close(d, (0.0004f64 + climb_var * 0.01).sqrt()), "{d:?}");
        // The same carry with a noisier DVL widens more.
        let noisy = depth_at(Some(0.02), Some([0.05, 0.05, 0.1]), 200);
        assert!(noisy.std.unwrap() > d.std.unwrap() + 0.001, "{noisy:?}");
        // No carry, or a DVL without a std: the reading's own std (z
        // carried all the same).
        assert_eq!(depth_at(Some(0.02), dvl, 0).std, Some(0.02));
        let d = depth_at(Some(0.02), None, 200);
        assert_eq!(d.std, Some(0.02));
        let climb = 0.5 * 1.0 - 30f64.to_radians().cos() * 0.5;
        assert!((d.z - (-1.0 + climb * 0.2)).abs() < 1e-12, "{d:?}");
        // A depth without a std keeps none.
        assert_eq!(depth_at(None, dvl, 200).std, None);
    }

    /// The tracker's defaults: pitch 0.3°, yaw 1.5°, depth 0.02 m.
    fn tracker_sigma() -> AssumedStd {
        AssumedStd {
            pitch: deg(0.3),
            yaw: deg(1.5),
            depth_m: 0.02,
        }
    }

    /// Audit: MAVLink's ATTITUDE brings no std, so a carried attitude went
    /// on with none and the estimator took its configured σ unwidened, as
    /// if taken at the capture. Told the σ the estimator assumes, a carried
    /// std-less reading gets it widened as a reading with that std would
    /// be; one not carried, or without rates, keeps none.
    #[test]
    fn a_carried_attitude_without_a_std_gets_the_assumed_sigma_widened() {
        let r = Readings::default();
        let t0 = Instant::now() + Duration::from_secs(5);
        let ages = MaxAge::default();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let bare = AttitudeReading::new(deg(2.0), deg(10.0));
        r.assume_std(Some(tracker_sigma()));
        assert_eq!(r.assumed_std(), Some(tracker_sigma()));
        r.store_attitude_with_rates(t0, &bare, rates(-4.0, 30.0));
        // 0.25 s: pitch 0.3° → 0.458°, yaw 1.5° → 1.539°, exactly as a
        // reading that came with 0.3° / 1.5°.
        let s25 = attached_std(&r, at(250), &ages);
        assert!(
            close_std(s25, model(0.3, 0.25), model(1.5, 0.25)),
            "{s25:?}"
        );
        let s25 = s25.unwrap();
        assert!((s25.pitch.deg() - 0.458_03).abs() < 1e-5, "{s25:?}");
        assert!((s25.yaw.deg() - 1.539_41).abs() < 1e-5, "{s25:?}");
        let own = Readings::default();
        own.store_attitude_with_rates(t0, &with_std(2.0, 10.0, 0.3, 1.5), rates(-4.0, 30.0));
        assert_eq!(Some(s25), attached_std(&own, at(250), &ages));
        // Carried back 0.1 s: widened as much as 0.1 s forward.
        r.store_attitude_with_rates(at(100), &bare, rates(-4.0, 30.0));
        let back = attached_std(&r, t0, &ages);
        assert!(
            close_std(back, model(0.3, 0.1), model(1.5, 0.1)),
            "{back:?}"
        );
        // Not carried (taken at the capture): none, the estimator's σ.
        assert_eq!(attached_std(&r, at(100), &ages), None);
        // Without rates: neither carried nor given a std.
        r.store_attitude(t0, &bare);
        assert_eq!(attached_std(&r, at(250), &ages), None);
        // A reading's own std wins over the assumed one.
        let a = with_std(2.0, 10.0, 0.2, 1.0);
        r.store_attitude_with_rates(t0, &a, rates(-4.0, 30.0));
        let s = attached_std(&r, at(250), &ages);
        assert!(close_std(s, model(0.2, 0.25), model(1.0, 0.25)), "{s:?}");
        // An assumed σ the estimator would refuse is not given.
        r.store_attitude_with_rates(t0, &bare, rates(-4.0, 30.0));
        r.assume_std(Some(AssumedStd {
            pitch: deg(0.0),
            ..tracker_sigma()
        }));
        assert_eq!(attached_std(&r, at(250), &ages), None);
        // Told none: as before any was told.
        r.assume_std(None);
        assert_eq!(r.assumed_std(), None);
        assert_eq!(attached_std(&r, at(250), &ages), None);
    }

    /// A std-less depth carried by a DVL with a std gets the assumed depth
    /// σ widened by the climb rate's error; carried by a DVL without one
    /// (no variance added), or not carried, it keeps none.
    #[test]
    fn a_carried_depth_without_a_std_gets_the_assumed_sigma_widened() {
        let ages = MaxAge::default();
        let depth_at = |std: Option<f64>, v_std: Option<[f64; 3]>, ms: u64| {
            let r = Readings::default();
            r.assume_std(Some(tracker_sigma()));
            let t0 = Instant::now() + Duration::from_secs(5);
            r.store_depth(t0, &DepthReading { z: -1.0, std });
            r.store_velocity(
                t0,
                &VelocityReading {
                    std: v_std.map(BodyVec),
                    ..VelocityReading::new(1.0, 0.0, 0.5)
                },
            );
            r.store_attitude(t0, &AttitudeReading::new(deg(30.0), deg(0.0)));
            let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
            r.attach(&mut f, t0 + Duration::from_millis(ms), &ages);
            f.depth.expect("a depth")
        };
        let dvl = Some([0.02, 0.01, 0.03]);
        // Nose up 30°, 0.2 s: 0.02 m → √(0.02² + 0.000775·0.2²) m, as a
        // reading that came with 0.02 m.
        let d = depth_at(None, dvl, 200);
        let want = (0.0004f64 + 0.000_775 * 0.04).sqrt();
        assert!(d.std.is_some_and(|s| (s - want).abs() < 1e-12), "{d:?}");
        assert!((d.std.unwrap() - 0.020_761).abs() < 1e-6, "{d:?}");
        assert_eq!(d.std, depth_at(Some(0.02), dvl, 200).std);
        // A DVL without a std adds nothing: none (z carried all the same).
        let d = depth_at(None, None, 200);
        assert_eq!(d.std, None);
        assert!(d.z != -1.0, "{d:?}");
        // Not carried: none.
        assert_eq!(depth_at(None, dvl, 0).std, None);
    }

    #[test]
    fn euler_rates_from_body_rates() {
        let (q, rr) = (0.2, 0.5);
        let close = |w: Option<AttitudeRates>, p: f64, y: f64| {
            w.is_some_and(|w| (w.pitch - p).abs() < 1e-12 && (w.yaw - y).abs() < 1e-12)
        };
        // Level: q is the pitch rate, r the yaw rate.
        assert!(close(AttitudeRates::from_body(0.0, 0.0, q, rr), q, rr));
        // Rolled 90° right: the body's pitch axis points down, so q turns
        // the heading and r lowers the nose.
        let w = AttitudeRates::from_body(FRAC_PI_2, 0.0, q, rr);
        assert!(close(w, -rr, q), "{w:?}");
        // Nose up 60°: a yaw about the body's axis turns the heading twice
        // as fast.
        let w = AttitudeRates::from_body(0.0, 60f64.to_radians(), q, rr);
        assert!(close(w, q, 2.0 * rr), "{w:?}");
        // Near straight up, not finite, or beyond a gyro: none.
        assert_eq!(
            AttitudeRates::from_body(0.0, 85f64.to_radians(), q, rr),
            None
        );
        assert_eq!(AttitudeRates::from_body(0.0, 0.0, f64::NAN, rr), None);
        assert_eq!(AttitudeRates::from_body(0.0, 0.0, q, 40.0), None);
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
