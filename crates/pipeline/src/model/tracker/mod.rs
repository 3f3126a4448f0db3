//! The `"tracker"` estimator: a Kalman filter over pose and its rates (and
//! optionally K_D), measuring the raw counts through the light equation and
//! whatever of the vehicle's own sensors a frame carries (attitude, depth,
//! DVL velocity; spec v2).
//!
//! Why: one frame barely separates y from yaw and z from pitch, and gives
//! no velocity at all (MODEL.md). Following the vehicle through time does
//! both: the motion model (by default surge along the bow plus a small
//! sideslip, so ż = u·sin θ + …) ties attitude to the change of position,
//! so the ridge of one frame is crossed by the next, and surge is a state
//! with its own uncertainty. The vehicle's own sensors pin what the light
//! leaves loose: attitude the angles, depth z (hence pitch), the DVL the
//! velocity; each is fused when a frame has it and refused, with a reason,
//! when it is unusable — never at the cost of the light's update.
//!
//! The room for each part:
//! - `state`: the state vector's layout and the beam term of σx;
//! - `motion`: the prediction (body or world motion model);
//! - `readings`: checks, noise and Kalman updates of the own sensors;
//! - `counts`: the update with the 25 counts (EKF, or sigma points when no
//!   reading pins the attitude);
//! - `start`: the start-up fit (with the readings as priors);
//! - `station`: a docking station's light (spec v3), beacon by beacon,
//!   roll a state;
//! - `bound`: the bound for a tracker along a known track (posterior CRB);
//! - `bank`: trackers in several waters, when told the water is unknown;
//! - `water_check`: one tracker that turns into a bank when, with a DVL,
//!   its counts stop fitting the calibration's water.
//!
//! Fixed-size matrices throughout: no allocation per frame.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod agreement;
mod bank;
mod bound;
mod counts;
mod dvl_check;
mod dvl_heading;
mod motion;
mod offsets;
pub(crate) mod readings;
mod start;
mod state;
mod station;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_fusion;
#[cfg(test)]
mod tests_jump;
mod water_check;
mod which_offset;
mod window;

use std::any::Any;

use lightpose_core::light::temperature_gain;
use lightpose_core::{
    Estimator, Findings, Frame, PoseEstimate, ReadingUse, ReadingUses, Refusal, Status, StdDev,
};

pub use self::bank::WaterBank;
pub use self::bound::{TrackBound, TrackBoundScene, TrackPoint};
use self::counts::CountsInput;
pub(crate) use self::dvl_check::DvlChecks;
use self::readings::{gate_thresholds, FrameReadings, PaperReading};
use self::state::{beam_consider_sigma_x, ln_brightness_per_metre, State, Vs, KD, ROLL, VEL};
pub use self::station::STATION_ROLL_PRIOR_DEG;
pub use self::water_check::WaterWatch;
use crate::model::findings::Found;
use crate::model::measurement::Measurement;
use crate::model::single_frame::ModelEstimator;
use crate::model::solver::Censoring;
use crate::model::SensorModel;
use crate::paper::MomentsEstimator;
use crate::settings::{Dof, ModelConfig, ModelError, Motion, TrackerConfig, READING_CHECK_SLOT_S};
use lightpose_core::light::WATER_TEMP_C;

/// The paper's range law (eqs. 2–3) of the same calibration.
#[derive(Debug, Clone)]
struct PaperRange {
    est: MomentsEstimator,
    /// Residual σ of the law over the calibration's translation grid, m.
    sigma_m: f64,
    /// Its exponent, 1/m: ln-brightness per metre.
    b1: f64,
    /// K_D of the water it was fitted in (the calibration's), m⁻¹.
    k_d0: f64,
}

impl PaperRange {
    /// The law's bias as the tracker reads it, m (1σ): its residual over
    /// the calibration grid times `paper_range_sigma_scale`, the reading's
    /// σ and what σx holds while the range is in x.
    fn bias(&self, scale: f64) -> f64 {
        self.sigma_m * scale
    }
}

/// Kalman tracker (name `"tracker"`).
#[derive(Debug, Clone)]
pub struct Tracker {
    model: SensorModel,
    cfg: TrackerConfig,
    /// The `"model"` estimator's settings and its light check, which the
    /// start-up fit shares.
    init: ModelEstimator,
    /// χ² gates of a reading with 1, 2 and 3 components.
    gate: [f64; 3],
    /// The paper's estimator, for its range (see `paper_range_sigma_scale`).
    paper: Option<PaperRange>,
    /// K_D's doubt in use: the setting, else the model's own.
    k_d_sigma: f64,
    /// The setting's doubt is wider than the calibration's own (the water
    /// is said to differ from the sweep's): a station's tracker then
    /// estimates K_D (`start::started_state`).
    k_d_told_wider: bool,
    state: Option<State>,
    /// The reading check's windows (about the sensors: kept across
    /// restarts).
    agreement: agreement::Agreements,
    /// The sensors' offsets as the last state knew them (about the
    /// sensors: kept across restarts), and a start's priors of them.
    offsets: offsets::Offsets,
    /// The DVL judged by the light: its change of range and its track's
    /// direction (about the sensor: kept across restarts).
    dvl: dvl_check::DvlChecks,
    /// When the last track started, and how many tracks in a row were
    /// lost within [`QUICK_LOSS_S`] of their start (see `restart`).
    started_t: Option<f64>,
    quick_losses: u32,
    /// This tracker is one hypothesis of which sensor is off, being
    /// weighed: it wakes no offset of its own (`which_offset`).
    weighing: bool,
    /// The hypotheses of which sensor is off, while they are weighed.
    which: Option<Box<which_offset::WhichOffset>>,
    /// Spec v3: a docking station's beacons (`with_station`); empty for
    /// one beacon. Shared: trackers are cloned into banks.
    station: std::sync::Arc<[crate::model::light::BeaconLight]>,
    /// The station's names for its estimates (`with_station_names`).
    station_names: Option<&'static lightpose_core::StationNames>,
}

/// A track lost this soon after its start was started onto something
/// wrong; [`QUICK_LOSSES`] such in a row and the next starts from the light
/// alone (an attitude 30° off in pitch or 90° in heading, taken as the
/// start's prior, started track after track onto itself, each lost at
/// once: not one `ok` pose in a minute).
const QUICK_LOSS_S: f64 = 2.0;
const QUICK_LOSSES: u32 = 2;

impl Tracker {
    pub const NAME: &'static str = "tracker";

    pub fn new(model: SensorModel, mut cfg: TrackerConfig) -> Result<Self, ModelError> {
        if cfg.k_d_sigma.is_none() && cfg.estimate_k_d && !(model.k_d_sigma > 0.0) {
            return Err(ModelError::Config(
                "tracker estimate_k_d needs k_d_sigma: the calibration gives K_D no standard error"
                    .into(),
            ));
        }
        let k_d_told_wider = cfg.k_d_sigma.is_some_and(|s| s > model.k_d_sigma);
        let k_d_sigma = *cfg.k_d_sigma.get_or_insert(model.k_d_sigma);
        cfg.validate()?;
        let init_cfg = ModelConfig {
            dof: Dof::Full,
            use_attitude: cfg.use_attitude,
            attitude_sigma_pitch_deg: cfg.attitude_sigma_pitch_deg,
            attitude_sigma_yaw_deg: cfg.attitude_sigma_yaw_deg,
            attitude_envelope_deg: Some(cfg.init_attitude_sigma_deg),
            x_range: cfg.x_range,
            max_saturated: cfg.max_saturated,
            k_d_sigma: Some(if cfg.estimate_k_d { 0.0 } else { k_d_sigma }),
            daylight: cfg.daylight,
            ..ModelConfig::default()
        };
        let init = ModelEstimator::new(model.clone(), init_cfg)?;
        Ok(Tracker {
            model,
            gate: gate_thresholds(cfg.reading_gate_p),
            init,
            paper: None,
            k_d_sigma,
            k_d_told_wider,
            state: None,
            agreement: Default::default(),
            offsets: offsets::Offsets::new(&cfg),
            dvl: Default::default(),
            started_t: None,
            quick_losses: 0,
            weighing: false,
            which: None,
            station: std::sync::Arc::from(Vec::new()),
            station_names: None,
            cfg,
        })
    }

    /// Take over `from`'s histories of the sensors (its channels' and its
    /// readings' checks), which a water bank's member replacing it would
    /// otherwise learn again (a frozen channel read as data for 20 frames,
    /// a biased depth unreported for 5 s, during the bank's start fits).
    pub(crate) fn inherit_checks(&mut self, from: &Tracker) {
        let from = from.active();
        self.init.inherit_channels(&from.init);
        self.agreement = from.agreement;
        self.offsets = from.offsets;
        self.dvl = from.dvl;
    }

    /// Give the tracker the paper's estimator of the same calibration, for
    /// the range it reads off the brightest channel.
    pub fn with_paper(mut self, cal: &crate::calibration::Calibration) -> Self {
        self.paper = Some(PaperRange {
            est: MomentsEstimator::new(cal),
            sigma_m: cal.fits.x.sigma_m,
            b1: cal.fits.x.b1,
            k_d0: self.model.light.k_d,
        });
        self
    }

    /// This tracker in water of K_D `k_d` known to `sigma` (1σ, m⁻¹),
    /// estimated from there on: its light model, start-up fit and K_D state
    /// are there; the paper's law keeps the water it was fitted in. One
    /// member of a [`WaterBank`].
    pub fn in_water(&self, k_d: f64, sigma: f64) -> Result<Self, ModelError> {
        let mut model = self.model.clone();
        model.light.k_d = k_d;
        let cfg = TrackerConfig {
            k_d_sigma: Some(sigma),
            estimate_k_d: true,
            ..self.cfg.clone()
        };
        self.rebuilt(model, cfg)
    }

    /// This tracker told a K_D doubt of `sigma` (1σ, m⁻¹) about the
    /// calibration's water, as if set: what the water check hands a bank.
    pub fn doubting(&self, sigma: f64) -> Result<Self, ModelError> {
        let cfg = TrackerConfig {
            k_d_sigma: Some(sigma),
            ..self.cfg.clone()
        };
        self.rebuilt(self.model.clone(), cfg)
    }

    /// A tracker with `model` and `cfg` and this one's paper range.
    fn rebuilt(&self, model: SensorModel, cfg: TrackerConfig) -> Result<Self, ModelError> {
        let mut t = Tracker::new(model, cfg)?;
        t.paper = self.paper.clone();
        t.station = self.station.clone();
        t.station_names = self.station_names;
        Ok(t)
    }

    /// The water check's window median, when it is full and above
    /// `water_check_nis`: the counts no longer fit the calibration's
    /// water (see `water_check`).
    pub fn water_misfit(&self) -> Option<f64> {
        let span = self.cfg.water_check_frames;
        let s = self.active().state.as_ref()?;
        s.water_nis
            .median(span)
            .filter(|m| *m > self.cfg.water_check_nis)
    }

    /// [`PaperRange::bias`] of this tracker's paper range, if it has one.
    fn paper_bias(&self) -> Option<f64> {
        let scale = self.cfg.paper_range_sigma_scale;
        self.paper.as_ref().map(|p| p.bias(scale))
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.cfg
    }

    /// Current K_D of the filter and its 1σ (when it is estimated; the
    /// state's σ of ln K_D times K_D).
    pub fn k_d(&self) -> Option<(f64, f64)> {
        self.active().state.as_ref().map(|s| {
            let k = state::k_d_of(&s.x);
            (k, k * s.sd(KD))
        })
    }

    /// ln of the counts' density at the innovation (less the constant) of
    /// the frame at time `t`, if the state's last step fused that frame's
    /// counts: what a bank of trackers in different waters weighs them by.
    pub fn counts_log_likelihood(&self, t: f64) -> Option<f64> {
        self.active().state_at(t).and_then(|s| s.counts_ll)
    }

    /// [`Self::counts_log_likelihood`] plus the fused readings' of the
    /// same frame: how well the state explained all of it.
    pub(super) fn frame_log_likelihood(&self, t: f64) -> Option<f64> {
        self.state_at(t)
            .and_then(|s| s.counts_ll.map(|c| c + s.readings_ll))
    }

    /// The state, if its last step was the frame at time `t`.
    fn state_at(&self, t: f64) -> Option<&State> {
        self.state.as_ref().filter(|s| s.t == t)
    }

    /// Start from `frame` (first frame, after a gap, or when lost).
    fn restart(
        &mut self,
        frame: &Frame,
        r: &FrameReadings,
        law: Option<PaperReading>,
    ) -> PoseEstimate {
        self.offsets.start_at(frame.t, &self.cfg);
        if let Some(t0) = self.started_t.take() {
            let quick = frame.t - t0 < QUICK_LOSS_S;
            self.quick_losses = if quick { self.quick_losses + 1 } else { 0 };
        }
        let r = &if self.quick_losses >= QUICK_LOSSES {
            r.for_light_alone(true)
        } else {
            *r
        };
        let paper = match r.attitude.ready() {
            Some(_) => None,
            None => self.paper_range(law),
        };
        let mut started = self.start(frame, r, paper.as_ref().map(|p| &p.range));
        if let (Err(_), Some(d)) = (&started, r.depth.ready()) {
            // A depth the light cannot be fitted with (grossly off: a
            // wrong beacon depth, a sensor zeroed elsewhere) was the start
            // fit's tight prior at every restart, so the track never
            // started (an audit: +5 m gave no pose for a whole minute).
            // The light alone starts it when it puts the depth grossly
            // wrong; the gate judges the depth after.
            let alone = r.for_light_alone(false);
            let retried = self.start(frame, &alone, paper.as_ref().map(|p| &p.range));
            if matches!(&retried, Ok((s, _)) if self.depth_at_odds(s, d)) {
                started = retried;
            }
        }
        if let (Err(_), Some(_)) = (&started, r.attitude.ready()) {
            // Likewise an attitude the light cannot be fitted with at all
            // (a heading 90° off: a compass beside a thruster). A start
            // that fails is no track to count as lost quickly, so the
            // rule of quick losses never came: in the tank minute with
            // such a heading the track stayed lost for 18 s after one
            // that lasted 4 s. The light alone starts it; the gate judges
            // the attitude after.
            let alone = r.for_light_alone(true);
            let retried = self.start(frame, &alone, paper.as_ref().map(|p| &p.range));
            if retried.is_ok() {
                started = retried;
            }
        }
        match started {
            Ok((mut s, uses)) => {
                self.started_t = Some(frame.t);
                if let Some(p) = paper {
                    s.push_paper(p);
                }
                let mut e = self.to_estimate(frame, &s, Status::Initialising);
                e.readings = verdicts(uses);
                self.keep(s);
                e
            }
            Err(st) => {
                let mut e = PoseEstimate::empty(frame.seq, frame.t, st, Self::NAME);
                e.readings = verdicts(unfused(r));
                e
            }
        }
    }

    /// The filter carried to `frame`'s time, or `None` when it must start
    /// again (no state, time going back, or a gap).
    fn carried_to(&mut self, t: f64) -> Option<State> {
        let mut s = self.state.take()?;
        let dt = t - s.t;
        if !(dt.is_finite() && (0.0..=self.cfg.max_gap_s).contains(&dt)) {
            return None;
        }
        self.predict(&mut s, dt);
        s.t = t;
        Some(s)
    }

    /// The paper's range of this frame, where it is read: without an
    /// attitude reading its change (as ẋ) and the range itself (as x); with
    /// one but no DVL reading, its change only (the attitude pins the
    /// light's own range; its change is what the random-walk surge lacks
    /// without a DVL). With an attitude or depth reading the change is
    /// taken less the law's own drift the light model predicts.
    fn read_paper(
        &self,
        s: &mut State,
        frame: &Frame,
        uses: &[ReadingUse; 3],
        law: Option<PaperReading>,
    ) {
        let attitude = uses[0] == ReadingUse::Used;
        if attitude && !(self.cfg.paper_rate_with_attitude && uses[2] != ReadingUse::Used) {
            return;
        }
        let Some(mut c) = self.paper_range(law) else {
            return;
        };
        if self.cfg.paper_rate_geometry && (attitude || uses[1] == ReadingUse::Used) {
            c.model_bias = self.law_bias_at(s, frame);
        }
        s.paper_rate_used = self.update_paper_rate(s, &c) == ReadingUse::Used;
        s.push_paper(c);
        if attitude {
            return;
        }
        match self.update_paper_range(s, &c.range) {
            ReadingUse::Used => {
                s.paper_x = self.paper_bias();
                s.paper_refused = 0;
            }
            // The law read an image with a channel known frozen: its range
            // judges nothing of the track (a stuck centre channel restarted
            // the track every five frames: 42 `ok` of 127 against 62).
            ReadingUse::Refused(Refusal::Gate) if self.init.frozen_mask() != 0 => {
                s.paper_refused = 0;
            }
            ReadingUse::Refused(Refusal::Gate) => {
                s.paper_refused = s.paper_refused.saturating_add(1);
            }
            _ => {}
        }
    }

    /// Whether the light's own range has disagreed with the track for
    /// `reading_gate_restart` frames in a row: the track is on the wrong
    /// side of a ridge, as after a jump no vehicle can make (the looping
    /// simulation's 4 m back to the start). Why: without an attitude
    /// reading the counts of the far pose fit a near one turned away (x
    /// 4 m short, pitch and yaw 20° off: a counts NIS of 2.4 on the first
    /// frame, ~1 after), so the counts' gate never refused them, and 119
    /// of 239 `ok` poses of six zigzags in a row were beyond 3σ (0 of 189
    /// with this check, `ok` 10 frames after each jump); the paper's range
    /// read 8 m against the track's 4 every frame (ν ≈ 6σ, refused). The
    /// gate's 5σ already passes the law's off-axis bias (σ 0.59 m in the
    /// tank), so a refusal in a row is no bias of the law's. Only a run
    /// of refusals: one bad frame is not a jump.
    fn jumped(&self, s: &State) -> bool {
        s.paper_refused >= self.cfg.reading_gate_restart
    }

    /// Whether a gated sensor has disagreed with the filter for so long
    /// that the filter or the sensor is wrong (the frame's counts judge
    /// which, in `estimate_frame`).
    fn lost_to_readings(&self, s: &mut State, uses: &[ReadingUse; 3]) -> bool {
        for (n, u) in s.gated.iter_mut().zip(uses) {
            *n = match u {
                ReadingUse::Refused(Refusal::Gate) => n.saturating_add(1),
                ReadingUse::Used => 0,
                _ => *n,
            };
        }
        s.gated.iter().any(|n| *n >= self.cfg.reading_gate_restart)
    }

    /// The status of an estimate from an updated state.
    fn status_of(&self, s: &State, applied: bool, n_sat: usize, uses: &[ReadingUse; 3]) -> Status {
        let x = s.x[0];
        if !applied {
            unusable(n_sat, self.cfg.max_saturated)
        } else if s.paper_refused > 0 {
            // The light's own range contradicts the track (`jumped`): not
            // a pose to trust until it agrees again or the track restarts.
            Status::Diverged
        } else if s.frames <= self.cfg.init_frames || self.surge_of(s).1 > self.cfg.surge_max_sigma
        {
            // Until surge is known too, not every field is (FORMATS.md `ok`).
            Status::Initialising
        } else if x < self.cfg.x_range[0] || x > self.cfg.x_range[1] {
            Status::OutOfRange
        } else if n_sat > self.cfg.max_saturated {
            Status::Saturated
        } else if self.cfg.flag_unobservable
            && uses[0] != ReadingUse::Used
            && s.station_seen.count() < 2
        {
            Status::Unobservable
        } else {
            Status::Ok
        }
    }

    /// Whether a steady beacon's counts by day (`daylight` set) leave the
    /// position too uncertain to be called `ok`: σ of x, y or z above the
    /// setting's `max_sigma_m` (the ambient's level, unknown every frame,
    /// takes the part of the light its shape explains).
    fn daylight_refuses(&self, s: &State, meas: &Measurement) -> bool {
        let Some(d) = self.cfg.daylight.filter(|_| !meas.is_amplitude()) else {
            return false;
        };
        (0..3).any(|i| !(s.p[(i, i)].sqrt() <= d.max_sigma_m))
    }

    /// Surge and its 1σ: the body model's u, or the world model's velocity
    /// along the bow; the σ with the paper rate's drift when it was read.
    fn surge_of(&self, s: &State) -> (f64, f64) {
        let x = &s.x;
        let p = &s.p;
        let (surge, var_s) = match self.cfg.motion {
            Motion::Body => (x[VEL], p[(VEL, VEL)]),
            Motion::World => {
                // Surge = forward axis · velocity, forward = (−cθcψ, cθsψ, sθ).
                let (st, ct) = x[3].sin_cos();
                let (sp, cp) = x[4].sin_cos();
                let fwd = [-ct * cp, ct * sp, st];
                let v = [x[VEL], x[VEL + 1], x[VEL + 2]];
                let surge = fwd[0] * v[0] + fwd[1] * v[1] + fwd[2] * v[2];
                let mut g = Vs::zeros();
                g[VEL] = fwd[0];
                g[VEL + 1] = fwd[1];
                g[VEL + 2] = fwd[2];
                g[3] = st * cp * v[0] - st * sp * v[1] + ct * v[2];
                g[4] = ct * sp * v[0] + ct * cp * v[1];
                (surge, (g.transpose() * p * g)[(0, 0)])
            }
        };
        // The paper range's change reads ẋ with the law's bias drifting in
        // between, a drift that follows the off-axis geometry over seconds:
        // weighed as noise of each reading it would average away over the
        // filter's ~1 s of memory, but successive readings share it.
        // Surge, which those readings make, holds it whole. Without it the
        // held-out approach's surge covered 1–4 % of runs (±2σ) as the
        // vehicle slowed: a bias of 0.17 m/s against a σ of 0.06.
        let drift = if s.paper_rate_used {
            self.cfg.paper_rate_drift_mps
        } else {
            0.0
        };
        (surge, var_s.max(0.0).sqrt().hypot(drift))
    }

    fn to_estimate(&self, frame: &Frame, s: &State, status: Status) -> PoseEstimate {
        let mut e = PoseEstimate::empty(frame.seq, frame.t, status, Self::NAME);
        let x = &s.x;
        let p = &s.p;
        let sd = |i: usize| lightpose_core::finite(s.sd(i));
        e.x = lightpose_core::finite(x[0]);
        e.y = lightpose_core::finite(x[1]);
        e.z = lightpose_core::finite(x[2]);
        e.pitch_deg = lightpose_core::finite(x[3].to_degrees());
        e.yaw_deg = lightpose_core::finite(x[4].to_degrees());
        let (surge, surge_sd) = self.surge_of(s);
        // Until the frames have said something about it, surge is the
        // start-up's guess (0 ± `init_velocity_sigma`): null, not a number
        // (FORMATS.md: a field the estimator does not know yet).
        let known = surge_sd <= self.cfg.surge_max_sigma;
        e.surge = lightpose_core::finite(surge).filter(|_| known);
        // K_D's doubt is in P (estimated or considered), x–K_D covariance
        // and all, so σx needs no term of its own for it.
        // With the paper's range in x, its error is a bias that frames do
        // not average away (its on-axis law, off the axis): σx holds that
        // bias whole (the law's residual over the calibration grid, scaled
        // as the reading's σ: 0.59 m in the tank) in place of the beam term
        // (the same off-axis dimming, already in that residual), and the
        // other pose axes their share of it (`paper_bias_share`).
        // A station's beacons see y and z themselves: no one beam's term.
        let beam_x = match s.paper_x {
            Some(sm) => sm,
            None if s.roll_free => 0.0,
            None => beam_consider_sigma_x(x, p, self.model.light.sigma_b.rad()),
        };
        let temp_x = self.temperature_bias_x(frame, x);
        let sdb = |i: usize| sd(i).map(|v| v.hypot(paper_bias_share(s, i)));
        e.std = StdDev {
            x: sd(0).map(|s| s.hypot(beam_x).hypot(temp_x)),
            y: sdb(1),
            z: sdb(2),
            pitch: sdb(3).map(f64::to_degrees),
            yaw: sdb(4).map(f64::to_degrees),
            surge: lightpose_core::finite(surge_sd).filter(|_| known),
            roll: s
                .roll
                .and_then(|(_, sd)| lightpose_core::finite(sd.to_degrees())),
        };
        e.roll_deg = s
            .roll
            .and_then(|(r, _)| lightpose_core::finite(r.to_degrees()));
        if s.roll_free {
            e.roll_deg = lightpose_core::finite(x[ROLL].to_degrees());
            e.std.roll = sd(ROLL).map(f64::to_degrees);
        }
        e.station = s.station_seen;
        e
    }

    /// The roll `frame` is taken at (rad) and its 1σ: its attitude
    /// reading's when that passed its checks, else the settings' prior
    /// (`roll_sigma_deg`); None (roll 0, spec v1/v2) without either.
    fn roll_of(&self, frame: &Frame, r: &FrameReadings) -> Option<(f64, f64)> {
        let c = &self.cfg;
        crate::settings::roll_of(
            frame,
            r.attitude.ready().is_some(),
            c.attitude_sigma_roll_deg,
            c.roll_sigma_deg,
        )
    }

    /// The range bias of a temperature read `temp_sigma_c` wrong (1σ, m):
    /// every channel scaled by σ_T·|g_T'|/g_T, read as ln-brightness per
    /// metre of range, K_D + 2/x. A bias of the whole run, which frames do
    /// not average, so σx holds it as it holds K_D's doubt (the Cramér–Rao
    /// bounds carry the same gain doubt as a state).
    fn temperature_bias_x(&self, frame: &Frame, x: &Vs) -> f64 {
        let Some(sigma_t) = self.cfg.temp_sigma_c.filter(|s| *s > 0.0) else {
            return 0.0;
        };
        let slope = lightpose_core::light::temperature_gain_slope(water_temp_of(frame));
        lightpose_core::finite(sigma_t * slope / ln_brightness_per_metre(x)).unwrap_or(0.0)
    }
}

/// The water temperature of `frame`, °C: its own when it is one water can
/// have, else the calibration's reference (20 °C, where g_T = 1).
fn water_temp_of(frame: &Frame) -> f64 {
    frame
        .temp_c
        .filter(|t| WATER_TEMP_C.contains(t))
        .unwrap_or(lightpose_core::light::T_REF_C)
}

/// The temperature gain g_T of `frame` (see `water_temp_of`).
pub(super) fn gain_of(frame: &Frame) -> f64 {
    temperature_gain(water_temp_of(frame))
}

/// The status of a frame the filter could not use: `saturated` when more
/// than `max_saturated` channels were clipped (the sensor's limit, as the
/// `model` estimator says it), else `diverged` (the filter's).
fn unusable(clipped: usize, max_saturated: usize) -> Status {
    if clipped > max_saturated {
        Status::Saturated
    } else {
        Status::Diverged
    }
}

/// What the paper range's bias in x does to pose component `i` (1σ): the
/// range pulled x by up to its bias `paper_x`, and with it every component
/// the update moves along with x, by P_ix/P_xx of it (the posterior's
/// sensitivity to a bias in one reading, the same for every component).
/// Why: with depth alone pitch rides on x through the light (a range too
/// far reads as a spot dimmed by pitch), and its ±2σ covered 90.1 % on the
/// dive while the law's bias grew to 0.3 m; with this share, 94.6 % (98.3 % with
/// the whole residual as the bias, `paper_range_sigma_scale` 1.0).
/// Only the pose: a constant bias shifts position, not its rate, and the
/// bias's drift is in surge's σ already (`paper_rate_drift_mps`).
fn paper_bias_share(s: &State, i: usize) -> f64 {
    let p = &s.p;
    match s.paper_x {
        Some(b) if p[(0, 0)] > 0.0 && (1..5).contains(&i) => {
            lightpose_core::finite(p[(i, 0)] / p[(0, 0)] * b).unwrap_or(0.0)
        }
        _ => 0.0,
    }
}

/// The verdicts of readings that were checked but never fused (no update
/// happened): refusals stay, a ready reading was not used.
fn unfused(r: &FrameReadings) -> [ReadingUse; 3] {
    let keep = |u: ReadingUse| match u {
        ReadingUse::Used => ReadingUse::Ignored,
        u => u,
    };
    [
        keep(r.attitude.if_fused()),
        keep(r.depth.if_fused()),
        keep(r.velocity.if_fused()),
    ]
}

fn verdicts(u: [ReadingUse; 3]) -> ReadingUses {
    ReadingUses {
        attitude: u[0],
        depth: u[1],
        velocity: u[2],
    }
}

impl Tracker {
    /// One frame through this tracker alone (see `which_offset` for the
    /// hypotheses of which sensor is off).
    fn estimate_one(&mut self, frame: &Frame) -> PoseEstimate {
        // Once per frame: the counts update and the report share it.
        self.init.observe_channels(frame);
        let meas = Measurement::of(&self.model, frame, self.init.frozen_mask());
        let mut e = self.estimate_frame(frame, &meas);
        // A station's estimate says what it saw even where the track has
        // no state yet (a frame too dark to start from).
        if e.station.station == 0 {
            if let Some(a) = self.station_amps(frame) {
                e.station = self.station_seen(a);
            }
        }
        e.excluded_channels = Censoring::excluded_mask(&meas.kinds);
        let span = (self.cfg.reading_check_s / READING_CHECK_SLOT_S).round() as usize;
        e.agreement = self.agreement.report(span, self.cfg.reading_check_limit);
        self.dvl.report(&mut e.agreement);
        self.after_frame_checks(&e);
        e
    }

    /// The tracker whose state stands for this one's: itself, or while
    /// the hypotheses of which sensor is off are weighed, the heaviest.
    fn active(&self) -> &Tracker {
        match &self.which {
            Some(w) => w.heavier(),
            None => self,
        }
    }
}

impl Estimator for Tracker {
    fn name(&self) -> &'static str {
        Self::NAME
    }
    fn std_with_every_ok_pose(&self) -> bool {
        true
    }

    fn estimate(&mut self, frame: &Frame) -> PoseEstimate {
        if self.which.is_some() {
            return self.estimate_weighing(frame);
        }
        self.estimate_one(frame)
    }

    fn reset(&mut self) {
        self.state = None;
        (self.started_t, self.quick_losses) = (None, 0);
        self.init.reset();
        self.agreement = Default::default();
        self.offsets = offsets::Offsets::new(&self.cfg);
        self.dvl = Default::default();
        (self.weighing, self.which) = (false, None);
    }

    /// K_D while it is estimated (`estimate_k_d`, or from the first DVL
    /// reading with `estimate_k_d_with_velocity`).
    fn water_k_d(&self) -> Option<f64> {
        self.active()
            .state
            .as_ref()
            .filter(|s| s.k_d_free)
            .map(|s| state::k_d_of(&s.x))
    }

    fn depth_offset(&self) -> Option<(f64, f64)> {
        Tracker::depth_offset(self)
    }

    fn pitch_offset_deg(&self) -> Option<(f64, f64)> {
        Tracker::pitch_offset_deg(self)
    }

    /// The channels' histories and the DVL checks' verdicts.
    fn findings(&self) -> Option<Findings> {
        let t = self.active();
        Found {
            channels: t.init.channels(),
            dvl: Some(t.dvl.verdicts()),
        }
        .boxed()
    }

    fn take_findings(&mut self, found: &(dyn Any + Send)) {
        if let Some(w) = self.which.as_mut() {
            w.take_findings(found);
        }
        if let Some(f) = Found::of(found) {
            self.init.take_channels(f);
            // With the checks off nothing would update a verdict taken
            // over: STATUS would say refused for good (a review).
            if self.cfg.dvl_check {
                self.dvl = f.dvl.unwrap_or(self.dvl);
            }
        }
    }
}

impl Tracker {
    /// One frame through the filter (see [`Estimator::estimate`]), its
    /// channels read and classified as `meas`.
    fn estimate_frame(&mut self, frame: &Frame, meas: &Measurement) -> PoseEstimate {
        let mut readings = FrameReadings::check(frame, &self.cfg);
        // Issue 8: a temperature that is not water's is a bad frame, as in
        // the model estimator; the update used to correct such a frame as
        // if at 20 °C (up to 10 % off in brightness, a jump in range).
        if frame.adc_bits != self.model.adc_bits
            || frame.temp_c.is_some_and(|t| !WATER_TEMP_C.contains(&t))
        {
            let mut e = PoseEstimate::empty(frame.seq, frame.t, Status::BadFrame, Self::NAME);
            e.readings = verdicts(unfused(&readings));
            return e;
        }
        // The paper law's reading of the frame, light only: the paper's
        // range and rate read it, and the DVL checks.
        // A station's images are no one beacon's spot: no paper law.
        let amps = self.station_amps(frame);
        let law = match amps {
            Some(_) => None,
            None => self.law_reading(frame, meas),
        };
        // The DVL's and the attitude's readings as the frame gives them,
        // for the DVL checks after the update (refused or not).
        let dvl_seen = self.dvl_sample(frame.t, &readings, law);
        if self.apply_dvl_verdict(&mut readings) {
            // The DVL is refused from this frame on, and the state followed
            // it (its velocity, the track it drew, what the offsets learned
            // meanwhile): start again from the light without it (on the
            // tank dock with the DVL turned 180°, x 1.3 m off at p95 when
            // carried on, 0.05 m from the restart).
            self.state = None;
            self.doubt_all_offsets();
        }
        let Some(mut s) = self.carried_to(frame.t) else {
            return self.restart(frame, &readings, law);
        };
        // The motion above moved the state at the last frame's roll; this
        // frame's readings and counts are taken at its own.
        s.roll = self.roll_of(frame, &readings);
        s.counts_ll = None;
        s.counts_nis = None;
        s.readings_ll = 0.0;
        let (uses, innov) = self.update_readings(&mut s, &readings);
        self.agreement.push(&innov, &uses, frame.t);
        s.attitude_fused = uses[0] == ReadingUse::Used;
        if let Some(a) = amps {
            s.station_seen = self.station_seen(a);
            let fused = s.attitude_fused;
            self.station_roll_readings(&mut s, frame, fused);
        }
        if !s.attitude_fused {
            self.bound_unmeasured_attitude(&mut s);
        }
        // A DVL ties successive ranges together independently of the
        // light, so the brightness along the track measures K_D (Beer's
        // law): optionally, from the first velocity reading on, K_D is
        // estimated (its doubt so far is already in P).
        if self.cfg.estimate_k_d_with_velocity
            && self.k_d_sigma > 0.0
            && uses[2] == ReadingUse::Used
        {
            s.k_d_free = true;
        }
        s.paper_x = None;
        s.paper_rate_used = false;
        self.read_paper(&mut s, frame, &uses, law);
        // A frame without light cannot judge a sensor the gate keeps
        // refusing (below): the state and the refusal stand until one can.
        let lost = self.lost_to_readings(&mut s, &uses);
        // A frame without light says nothing of pose; the readings still
        // keep the filter on course.
        let dark = match amps {
            Some(_) => s.station_seen.seen == 0,
            None => !self.init.has_light(frame),
        };
        if dark {
            let seen = s.station_seen;
            self.keep(s);
            let mut e = PoseEstimate::empty(frame.seq, frame.t, Status::NoLight, Self::NAME);
            e.readings = verdicts(uses);
            e.station = seen;
            return e;
        }
        let gt = gain_of(frame);
        let n_sat = meas
            .kinds
            .iter()
            .filter(|k| **k == Censoring::Saturated)
            .count();
        let inp = CountsInput {
            gt,
            meas,
            ambient: self.init.ambient_for(frame),
            pinned: uses[0] == ReadingUse::Used,
        };
        let applied = match amps {
            Some(a) => {
                let seen = s.station_seen.seen;
                self.update_station(&mut s, a, gt, seen).applied
            }
            None => self.update_counts(&mut s, &inp),
        };
        if self.jumped(&s) {
            // The track is not the vehicle's: start again from this frame,
            // as when the filter has lost it (its `initialising` frames
            // step the autopilot's reset_counter at the next `ok` pose).
            self.doubt_all_offsets();
            return self.restart(frame, &readings, law);
        }
        if lost {
            // An estimated offset of a sensor refused frame after frame may
            // be what changed (the sensor re-zeroed or remounted, or an
            // offset learned wrong): its doubt goes back to the setting's
            // prior, in this state and for a restart, so that the gate
            // takes the sensor again and the light learns the offset anew
            // (with no walk a wrong pitch offset was kept for good).
            self.doubt_offsets_of_refused(&mut s);
            // A sensor the gate has refused frame after frame: either the
            // filter is lost, or the sensor is wrong (a depth sensor zeroed
            // on another day, a mis-set beacon depth). The light judges:
            // when the counts still fit the state, the sensor is the odd
            // one out and stays refused; a restart would take its reading
            // into the start fit as a prior and make its bias the state's
            // (depth 0.2 m off: x p95 0.37–0.72 m on a minute's run, 0.02–0.05
            // with the light judging).
            let light_backs =
                applied && s.counts_nis.is_some_and(|n| n <= self.cfg.water_check_nis);
            if !light_backs {
                self.doubt_all_offsets();
                return self.restart(frame, &readings, law);
            }
            let limit = self.cfg.reading_gate_restart;
            s.gated
                .iter_mut()
                .filter(|n| **n >= limit)
                .for_each(|n| *n = 0);
        }
        if applied {
            s.rejected = 0;
            // The water check reads only frames whose change of range a
            // DVL fixed (`water_check`), with a K_D held, not estimated,
            // and no channel clipped: a saturated channel is a bound, and
            // in clear water at the closest point of a pass its misfit
            // (up to 3.7 per channel) is the clipping's, not the water's.
            let watched = self.cfg.water_check_frames > 0 && !s.k_d_free;
            if let (Some(nis), ReadingUse::Used, true, 0) = (s.counts_nis, uses[2], watched, n_sat)
            {
                s.water_nis.push(nis, self.cfg.water_check_frames);
            }
        } else {
            s.rejected += 1;
            if s.rejected >= self.cfg.max_rejected {
                // The filter has lost the vehicle: start again from this
                // frame, doubting what it learned of the sensors' offsets.
                self.doubt_all_offsets();
                return self.restart(frame, &readings, law);
            }
        }
        s.frames = s.frames.saturating_add(1);
        let sane = s.is_finite()
            && s.x[0] > 0.0
            && s.x[3].abs() < 1.4
            && s.x[4].abs() < 1.4
            && s.x[ROLL].abs() < 1.4;
        if !sane {
            self.state = None;
            let status = unusable(n_sat, self.cfg.max_saturated);
            let mut e = PoseEstimate::empty(frame.seq, frame.t, status, Self::NAME);
            e.readings = verdicts(uses);
            return e;
        }
        if applied {
            self.observe_dvl(frame.t, &s, dvl_seen);
        }
        let mut status = self.status_of(&s, applied, n_sat, &uses);
        if status == Status::Ok && self.daylight_refuses(&s, meas) {
            status = Status::Daylight;
        }
        let mut e = self.to_estimate(frame, &s, status);
        e.readings = verdicts(uses);
        self.keep(s);
        e
    }

    /// The offsets of the sensors `s` has refused `reading_gate_restart`
    /// times in a row back to their prior doubt (see `estimate_frame`).
    fn doubt_offsets_of_refused(&mut self, s: &mut State) {
        let limit = self.cfg.reading_gate_restart;
        for o in offsets::Offset::ALL {
            if s.gated[o.reading()] >= limit && self.offsets.told(o, &self.cfg) {
                let (i, full) = (o.index(), self.offsets.sigma(o, &self.cfg).powi(2));
                // More variance on the diagonal keeps P positive.
                s.p[(i, i)] = s.p[(i, i)].max(full);
                self.offsets.doubt(o, &self.cfg);
            }
        }
    }

    /// Every told offset's memory back to its prior doubt: a filter that
    /// lost the vehicle may have learned them wrong, and a restart would
    /// otherwise take them as known (with no walk, a pitch offset for good).
    fn doubt_all_offsets(&mut self) {
        for o in offsets::Offset::ALL {
            if self.offsets.told(o, &self.cfg) {
                self.offsets.doubt(o, &self.cfg);
            }
        }
    }

    /// Keep `s` as the filter's state, and what it knows of the sensors'
    /// offsets for a later start.
    fn keep(&mut self, s: State) {
        self.offsets.keep(&s, &self.cfg);
        self.state = Some(s);
    }

    /// The depth sensor's offset and its 1σ (m), while it is estimated
    /// (`depth_offset_sigma_m` above 0): what STATUS and the replay
    /// summary report.
    pub fn depth_offset(&self) -> Option<(f64, f64)> {
        let t = self.active();
        t.offsets.report(offsets::Offset::Depth, &t.cfg)
    }

    /// The attitude sensor's pitch offset and its 1σ (°), while it is
    /// estimated (`pitch_offset_sigma_deg` above 0).
    pub fn pitch_offset_deg(&self) -> Option<(f64, f64)> {
        let t = self.active();
        t.offsets
            .report(offsets::Offset::Pitch, &t.cfg)
            .map(|(m, sd)| (m.to_degrees(), sd.to_degrees()))
    }
}
