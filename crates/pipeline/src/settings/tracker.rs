//! The tracker's table, `[estimator.tracker]`: every key with its default
//! and why it is what it is (its checks: `checks.rs`).

use serde::{Deserialize, Serialize};

use super::DaylightConfig;

/// How the tracker moves the vehicle between frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Motion {
    /// Velocity in the beacon frame, unrelated to attitude.
    World,
    /// Surge along the bow plus a small sideslip.
    Body,
}

/// Settings of the tracker (a TOML table with every key optional).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// White-acceleration spectral density of the position, (m/s²)²/Hz.
    pub accel_psd: f64,
    /// White angular-acceleration spectral density, (°/s²)²/Hz.
    pub ang_accel_psd_deg: f64,
    /// Estimate K_D as a slowly varying random walk (turbid or changing
    /// water); otherwise it is the calibration's value, fixed.
    pub estimate_k_d: bool,
    /// Estimate K_D from the first DVL reading on: the DVL gives the
    /// change of range independently of the light, so the brightness
    /// along the track measures K_D. Off by default: in water whose K_D
    /// is the calibration's it costs range accuracy early in a run (the
    /// estimate wanders within K_D's doubt until the track has covered a
    /// few metres); in other water it gains a lot (docs/estimators.md).
    /// Not with `k_d_sigma = 0` (K_D known exactly).
    pub estimate_k_d_with_velocity: bool,
    /// 1σ of K_D about the calibration's value, m⁻¹ (0: known exactly):
    /// the filter's prior when K_D is estimated, else the doubt of a
    /// consider state (carried in P, K_D itself never moved). Unset: the
    /// calibration's own standard error of K_D (the water of the sweep);
    /// in other water say how far it may be off (MODEL.md's Monte Carlo
    /// spread is 0.015, which `lightpose montecarlo` and `bench` tell it).
    /// The tracker holds ln K_D, with this doubt as σ/K_D (its first-order
    /// spread), so no sigma point is a water with K_D < 0; a doubt wider
    /// than a quarter of K_D is a bank of waters (`water_bank`) spread
    /// over ±2 ln(1 + σ/K_D), which reaches K_D + σ at +1σ. On a
    /// docking station's light a doubt wider than the calibration's is
    /// estimated, as `estimate_k_d` does: the beacons' geometry gives the
    /// range, so the light tells K_D (docs/docking.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_d_sigma: Option<f64>,
    /// 1σ by which the frames' temperature may be off the photodiodes'
    /// for a whole run, °C (unset: 0, the reading believed). Read wrong,
    /// it scales every channel alike (0.37 %/°C, MODEL.md's g_T), which the
    /// light reads as range: σx holds that range bias whole,
    /// σ_T·|g_T'|/g_T / (K_D + 2/x), since frames do not average it away.
    /// MODEL.md's Monte Carlo spread is 3 °C (the reported temperature
    /// stays T0), which `lightpose montecarlo` and `bench` tell it. Why:
    /// in the calibrated water with all three sensors, x's ±2σ covered
    /// 70–76 % of those runs (RMS 0.023 m against a σ of 0.009–0.016).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temp_sigma_c: Option<f64>,
    /// Told a doubt about the water wider than `WaterBank::WIDE_LN_K_D`
    /// (k_d_sigma above a quarter of K_D), run a bank of seven trackers in waters
    /// spread over it, each estimating K_D within its cell, weighed by how
    /// well each explains the counts, and report their mixture (7× the
    /// cost). Why: one tracker linearizes Beer's law at one K_D, and told
    /// ±0.3 about 0.09 its x was beyond 3σ on 160 of 165 `ok` frames in
    /// water of K_D 0.29 (the bank: 11 of 295; docs/estimators.md, "K_D").
    pub water_bank: bool,
    /// Frames of the water check (0: off): the median over this many
    /// frames with a DVL reading fused and no channel clipped of the
    /// counts' normalized innovation squared per channel (at most
    /// `WATER_CHECK_MAX_FRAMES`; 25 is 5 s at MODEL.md's 5 Hz: at a faster
    /// frame rate successive frames' misfits are less independent, so
    /// give it more). Above `water_check_nis`, the water
    /// is taken to be unlike the calibration's and the tracker goes on as
    /// a bank of waters told `water_check_doubt` (`water_bank`), which
    /// learns it. Why: untold, water of K_D 0.19 about a tank's 0.09 put
    /// x 1.1 m off, reported `ok`; the DVL fixes the change of range
    /// independently of the light, so a wrong K_D no longer hides in x and
    /// shows as a misfit (docs/estimators.md, "The water check"). Only
    /// with one tracker holding K_D (no `estimate_k_d`, no wide doubt).
    pub water_check_frames: usize,
    /// The water check's limit on that median (about 1 in the
    /// calibration's water).
    pub water_check_nis: f64,
    /// The K_D doubt (1σ, m⁻¹) the bank is told when the check fires:
    /// what an operator who takes a calibration into unknown water sets.
    pub water_check_doubt: f64,
    /// Seconds of the reading check (0: off; at most
    /// `READING_CHECK_MAX_S`): the mean of each own-sensor reading
    /// component's normalized innovation ν/√S over this long, in slots of
    /// 0.2 s (one frame each at MODEL.md's 5 Hz; the frames of a slot
    /// averaged at a faster rate, so that the window is a time, not a
    /// count of ever more correlated frames). Past `reading_check_limit`
    /// the reading is reported as disagreeing with the light
    /// (PoseEstimate::agreement: STATUS, the replay summary, a warning).
    /// Report only: nothing fused changes. Why: a biased depth or pitch
    /// reading goes whole into the pose, every pose `ok`, the gate silent
    /// (docs/estimators.md, "Biased readings").
    pub reading_check_s: f64,
    /// The reading check's limit on |mean ν/√S| (0 for a reading as good
    /// as its σ, whose mean over 25 white slots has a σ of 0.2).
    pub reading_check_limit: f64,
    /// Judge the DVL by the light's own range (`model/tracker/dvl_check.rs`):
    /// a DVL whose change of range over 5 s the light's contradicts (under a
    /// third of it or another sign, or over five times it, which no water
    /// the beacon is seen through does, beyond the law's wander and noise),
    /// or whose track turns from the light's by over 20° (with an attitude
    /// reading, over 10 s), is refused (`refused_light`) until they agree
    /// again.
    /// Why: a DVL mounted backwards was fused on every frame, the AHRS
    /// blamed, x 2.9 m off on `ok` poses (docs/estimators.md, "A DVL set
    /// up wrong").
    pub dvl_check: bool,
    /// Random-walk density of K_D, (m⁻¹)²/s (the tracker's ln K_D walks
    /// by this over K_D²).
    pub k_d_walk_psd: f64,
    /// Say `unobservable`, not `ok`, on a frame without an attitude
    /// reading. Off by default: with the body motion model, the
    /// sigma-point update and the beam term in σx, the std of every field
    /// covers the truth without the sensor (±2σ 92–99.8 % on the paper's
    /// cases, lightpose bench, 2000 runs). It was on while the EKF's
    /// coverage there was 76–87 % on the ridges; docs/estimators.md.
    pub flag_unobservable: bool,
    /// Frames without an attitude reading use the sigma-point update (see
    /// `update_sigma`) instead of the EKF's; the cost is 13 evaluations of
    /// the light equation instead of one with its Jacobian.
    pub sigma_points_without_attitude: bool,
    /// Motion model: `body` (surge along the bow plus a small sideslip,
    /// the default) or `world` (constant velocity in B, no tie between
    /// velocity and attitude).
    pub motion: Motion,
    /// Body model: 1σ of the sideslip (right and down, m/s) and its
    /// correlation time (s). 0.25 m/s: at sea the water moves the vehicle
    /// over the ground (currents of 0.1–0.3 m/s), and a looser tie keeps
    /// the filter honest on the ridge; 0.05–0.1 made the ±2σ coverage of
    /// the ridges 57–85 % without the sensor (the paper's trajectories'
    /// own sideslip is ≤ 0.05 m/s RMS). With the sensor it hardly matters
    /// (y, yaw RMS 0.04 m, 0.58° at 0.05 vs 0.06 m, 0.8° at 0.25).
    pub side_sigma: f64,
    pub side_tau_s: f64,
    /// The sideslip's correlation time (s) while the attitude is measured
    /// (the last frame's attitude reading was fused). `side_tau_s`'s 2 s
    /// is looser than a vehicle: without the attitude the sideslip also
    /// carries what a pitch or yaw off along the ridge does to the
    /// predicted motion (u·δθ), and 10 s there took z on the tank zigzag
    /// from 1.13× to 1.79× the paper's. With the attitude that error is
    /// gone, and 10 s is the vehicle's own: with the DVL z's ±2σ covered
    /// 97.8–97.9 % at 2 s (its σ the sideslip's margin), 96.2–96.7 % at
    /// 10 s; with the attitude sensor alone y's and yaw's 95 % half-width
    /// narrowed 8–10 % (docs/estimators.md, "The sideslip's memory").
    pub side_tau_with_attitude_s: f64,
    /// Surge is given (with its std) once its 1σ is at most this, m/s;
    /// before, it is null and the status `initialising` (FORMATS.md: `ok`
    /// means every field is trustworthy): right after a start without a
    /// DVL it is only the start-up's guess (0 ± `init_velocity_sigma`),
    /// as the paper's method gives none until its window is full. 0.15:
    /// a 95 % half-width of 0.3 m/s, under the paper's 0.5 m/s cruise, so
    /// that what is given says how fast the vehicle closes in; reached
    /// 1.6–2.2 s after a start without a DVL on the paper's runs (the
    /// paper's window: 1.8 s), 3.6–4.2 s on the tests' synthetic zigzag,
    /// at once with a DVL. At 0.35 the first 0.6–1 s of surge were mostly
    /// the start's guess (held-out dive: p95 0.24 m/s against the paper's
    /// 0.15 over each one's own frames).
    pub surge_max_sigma: f64,
    /// Start-up 1σ of velocity (m/s, 0.001–10) and of angular rates (°/s,
    /// 0.001–1000).
    pub init_velocity_sigma: f64,
    pub init_rate_sigma_deg: f64,
    /// Start-up attitude envelope without a sensor: pitch = yaw = 0 ± this
    /// (0.001–90°).
    pub init_attitude_sigma_deg: f64,
    /// Use `Frame.attitude` when present, with these 1σ unless the reading
    /// gives its own `std` (MODEL.md's sensor: 0.3° pitch, 1.5° yaw).
    pub use_attitude: bool,
    pub attitude_sigma_pitch_deg: f64,
    pub attitude_sigma_yaw_deg: f64,
    /// Spec v3: the attitude sensor's roll 1σ (degrees; MODEL.md's 0.3°),
    /// for a frame whose attitude reading has roll (a frame's `std` has
    /// none for roll).
    pub attitude_sigma_roll_deg: f64,
    /// Spec v3: a frame without a roll reading is taken at roll 0 ± this
    /// (degrees, 1σ; a vehicle in waves rolls a few degrees, 5 is a fair
    /// figure), whose doubt goes into every other axis' σ and is reported
    /// as `std.roll`. Unset: roll is exactly 0 and not reported, as in
    /// spec v1/v2 (the default, so that v1/v2 logs give what they gave).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub roll_sigma_deg: Option<f64>,
    /// Spec v3: roll's random walk on a docking station (the state the
    /// station's beacons estimate), (°)²/s.
    pub roll_walk_psd_deg: f64,
    /// Use `Frame.depth` when present, with this 1σ (m) unless the reading
    /// gives its own (MODEL.md's sensor: 0.02 m).
    pub use_depth: bool,
    pub depth_sigma_m: f64,
    /// Where the depth sensor sits relative to the dome centre, in the body
    /// frame V (forward, right, down), metres. A frame's `depth.z` is the
    /// sensor's z in B; the tracker compares it with z + (R_BV·lever)_z,
    /// its own attitude included (docs/spec-notes.md). Default: at the
    /// dome centre.
    pub depth_lever_arm_m: [f64; 3],
    /// How far off the depth readings may be as a whole, 1σ (m): the
    /// beacon's depth as configured, the surface pressure the autopilot
    /// took at boot, the water's density, the tide over the beacon since.
    /// 0 (the default): the readings are taken as unbiased (MODEL.md's
    /// sensor) and the filter fuses them as they are. Above 0 the filter
    /// holds the offset as a state, with this prior, which the light
    /// estimates where it sees z (with the attitude sensor: the spot's
    /// elevation at a known pitch); reported in STATUS and the replay
    /// summary (docs/estimators.md, "Sensor offsets").
    pub depth_offset_sigma_m: f64,
    /// How fast that offset drifts, a random walk's density (m²/s): the
    /// tide over the beacon moves a pressure depth by up to 1–2 cm a
    /// minute where it is large. Default 1e-6: 1σ 0.008 m in a minute,
    /// 0.06 m in an hour; at most 1. Only with `depth_offset_sigma_m` above 0.
    pub depth_offset_walk_psd: f64,
    /// How far off the attitude sensor's pitch may be as a whole, 1σ (°):
    /// an AHRS mounted askew of the dome, a level calibration taken on a
    /// slope. 0 (the default): believed. Above 0 a state with this prior
    /// that the light estimates (with depth: the spot's elevation at a
    /// known z), constant; reported in STATUS and the replay summary
    /// (docs/estimators.md, "Sensor offsets").
    pub pitch_offset_sigma_deg: f64,
    /// The depth offset's prior (1σ, m) from the frame the reading check
    /// calls depth or pitch disagreeing, when `depth_offset_sigma_m` is
    /// 0: the filter then estimates the offset from there on, as if told
    /// this. Only while depth and attitude readings both come (the light
    /// tells a depth offset from z only at a known pitch). 0: a call only
    /// reports (docs/estimators.md, "Offsets learned when the check calls").
    pub called_depth_offset_sigma_m: f64,
    /// The same for the pitch offset (1σ, °), when
    /// `pitch_offset_sigma_deg` is 0.
    pub called_pitch_offset_sigma_deg: f64,
    /// Use `Frame.velocity` (DVL, body frame) when present, with this 1σ
    /// per component (m/s) unless the reading gives its own (MODEL.md's
    /// DVL: 0.02 m/s).
    pub use_velocity: bool,
    pub velocity_sigma_mps: f64,
    /// Innovation gate of each reading: the probability with which a
    /// reading that agrees with the filter's prediction (χ² with one
    /// degree of freedom per component) is refused anyway. 1e-6 refuses
    /// beyond χ² 23.9 (depth), 27.6 (attitude) and 30.7 (DVL), i.e. ≈ 5σ.
    pub reading_gate_p: f64,
    /// After this many readings of one sensor in a row refused by the gate,
    /// the filter takes itself to be lost and starts again from the
    /// current frame, with the readings in its start fit.
    pub reading_gate_restart: u32,
    /// A depth reading with |z| beyond this (m), or a DVL component beyond
    /// `velocity_limit_mps` (m/s), is implausible and refused whatever the
    /// filter believes: the beacon could not be seen from there, and no
    /// vehicle that docks moves that fast.
    pub depth_limit_m: f64,
    pub velocity_limit_mps: f64,
    /// Start-up without an attitude or depth reading: besides the fit that
    /// reads the spot's offset as position (attitude 0), also try the one
    /// that reads it as attitude (on the beam axis), and keep the better.
    pub start_both_ways: bool,
    /// Start-up without an attitude reading: a prior that the vehicle is
    /// within this angle (1σ, degrees) of the beam axis, i.e. y, z ~
    /// N(0, (x·tan σ)²) (a depth reading replaces it on z). Absent: none.
    pub init_lateral_sigma_deg: Option<f64>,
    /// While no attitude reading is fused: pitch and yaw (about level and
    /// the beam axis) are held within this angle (1σ, degrees). On a frame
    /// where the filter's σ of either is larger, that angle is read as 0
    /// with the variance that takes its σ back to the setting; within it,
    /// nothing is done, so a run whose σ stays within is untouched. Why:
    /// near the beam axis the light says nothing, to first order, of how a
    /// spot off the dome's centre splits between yaw and y (or pitch and
    /// z), and the filter's σ of both angles grew by about 0.8°/s, past
    /// 40° within a minute. The counts' sigma points (±√3σ) then reached
    /// past the dome's span, an update ran off along the ridge (yaw 48°
    /// off) and the track was lost near 50 s on every minute-long run
    /// without sensors. A vehicle that sees the beacon on its dome faces
    /// it within the detectors' span, ±2Δ = ±30°, taken as 2σ: 15°.
    /// 0: off.
    pub unmeasured_attitude_sigma_deg: f64,
    /// Frames whose attitude no reading pins: take the paper's range (its
    /// on-axis brightness law, eqs. 2–3, from the same calibration) as a
    /// measurement of x, with 1σ = `paper_range_sigma_scale` times the
    /// law's residual over the calibration's translation grid (plus the
    /// counts' own noise). Why: one frame cannot tell a far vehicle on the
    /// beam axis from a near one off it (brightness trades range against
    /// the off-axis angle, and the ridges leave that angle loose), and the
    /// law carries the assumption the paper makes, that the vehicle is
    /// near the axis, with its measured error (docs/estimators.md).
    pub paper_range: bool,
    /// 1.0 (the law's residual as the calibration measured it) by default:
    /// σx holds that bias, and it must hold wherever in the calibrated
    /// volume the vehicle is. At 0.5 it held only near the axis: with the
    /// truth 3° (lateral) and 5° (attitude, 1σ) off the runs' axis, x's ±2σ
    /// covered 66 % of the dive (`ridge_diag` with `OFF_AXIS`), 93 % at 1.0.
    pub paper_range_sigma_scale: f64,
    /// With the paper's range in use: also its change over the last
    /// `paper_rate_frames` frames that had one, as a measurement of ẋ, with
    /// the counts' noise of both ends and `paper_rate_drift_mps` (1σ) for
    /// the law's bias drifting in between; that drift, which successive
    /// readings share, is also in the reported surge σ whole (and in the
    /// `surge_max_sigma` test on it). It moves only x and the
    /// velocities. Why: the law's error is mostly a bias that changes only
    /// as the off-axis geometry does, so the difference of two ranges is
    /// far steadier than either; it is what the paper's surge (a slope over
    /// its window) lives on, and without it the tracker's surge lagged a
    /// vehicle that slows (docs/estimators.md). A span longer than
    /// `max_gap_s` (frames slower than 1.5 Hz at 3 frames) is not used.
    pub paper_rate: bool,
    /// `paper_rate` also on frames whose attitude a reading pins but whose
    /// velocity no DVL reading gives: the range's change only (the light's
    /// own range is unbiased there, so the paper's range is not read).
    /// Why: with the attitude sensor alone the random-walk surge lagged a
    /// vehicle that slows, and its ±2σ covered 89.5 % of the tank dock
    /// (`ridge_diag`, 200 runs); with the change read, 98.4 %, and the
    /// dock's surge end RMS 0.088 → 0.046 m/s (docs/estimators.md).
    pub paper_rate_with_attitude: bool,
    /// The paper range's change, less the change of the law's own bias
    /// between its two frames as the light model predicts it at the state
    /// (the law read off the model's frame there, minus x): the law's
    /// error follows the geometry, which an attitude or depth reading
    /// pins, so on frames with one the rate reads ẋ, not ẋ plus the drift.
    /// Without either the state's geometry lies on the ridges and the
    /// predicted change follows their error, so it is not taken there (the
    /// held-out dive's surge p95 went 0.091 → 0.149 m/s). Why: with the
    /// attitude sensor alone the tank dive's surge carried the law's
    /// drift, end RMS 0.080 m/s (bias 0.07); with it 0.043; with depth
    /// alone 0.078 → 0.035 (`ridge_diag`, 200 runs; docs/estimators.md).
    pub paper_rate_geometry: bool,
    pub paper_rate_frames: usize,
    pub paper_rate_drift_mps: f64,
    /// Range of x for which an estimate is `ok`.
    pub x_range: [f64; 2],
    /// Frames after (re)start reported as `initialising`.
    pub init_frames: u32,
    /// Gauss–Newton iterations of the iterated update. 1 (a plain EKF
    /// update) by default: at 5 Hz the prediction is close enough that
    /// further iterations changed neither the Monte Carlo half-widths nor
    /// the coverage (lightpose bench, 400 runs, all three cases, with and
    /// without the attitude sensor) but cost ~2.4× the time (≈ 120 → 50 µs).
    pub update_iterations: usize,
    /// Normalized innovation squared per measurement above which a frame
    /// is not used; this many such frames in a row restart the filter.
    pub nis_gate: f64,
    pub max_rejected: u32,
    /// A gap in time longer than this restarts the filter (seconds).
    pub max_gap_s: f64,
    /// More channels at full scale than this gives `saturated`.
    pub max_saturated: usize,
    /// `[estimator.tracker.daylight]`: as the model's (a steady beacon by
    /// day: the ambient level marginalized in every update).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub daylight: Option<DaylightConfig>,
}

/// The most frames `water_check_frames` may span (a fixed ring).
pub const WATER_CHECK_MAX_FRAMES: usize = 64;

/// The reading check's slot: its window holds one mean per slot.
pub const READING_CHECK_SLOT_S: f64 = 0.2;

/// The longest `reading_check_s`: as many slots as the ring holds.
pub const READING_CHECK_MAX_S: f64 = WATER_CHECK_MAX_FRAMES as f64 * READING_CHECK_SLOT_S;

/// The most frames `paper_rate_frames` may span (the tracker keeps that
/// many paper ranges, in a fixed ring: no allocation per frame).
pub const PAPER_RATE_MAX_FRAMES: usize = 8;

impl Default for TrackerConfig {
    fn default() -> Self {
        TrackerConfig {
            accel_psd: 0.005,
            ang_accel_psd_deg: 20.0,
            estimate_k_d: false,
            estimate_k_d_with_velocity: false,
            k_d_sigma: None,
            temp_sigma_c: None,
            k_d_walk_psd: 1e-6,
            flag_unobservable: false,
            sigma_points_without_attitude: true,
            motion: Motion::Body,
            side_sigma: 0.25,
            side_tau_s: 2.0,
            side_tau_with_attitude_s: 10.0,
            unmeasured_attitude_sigma_deg: 15.0,
            surge_max_sigma: 0.15,
            init_velocity_sigma: 0.7,
            init_rate_sigma_deg: 10.0,
            init_attitude_sigma_deg: 10.0,
            use_attitude: true,
            attitude_sigma_pitch_deg: 0.3,
            attitude_sigma_yaw_deg: 1.5,
            attitude_sigma_roll_deg: 0.3,
            roll_sigma_deg: None,
            roll_walk_psd_deg: 1.0,
            use_depth: true,
            depth_sigma_m: 0.02,
            depth_lever_arm_m: [0.0; 3],
            depth_offset_sigma_m: 0.0,
            depth_offset_walk_psd: 1e-6,
            pitch_offset_sigma_deg: 0.0,
            called_depth_offset_sigma_m: 0.3,
            called_pitch_offset_sigma_deg: 2.0,
            use_velocity: true,
            velocity_sigma_mps: 0.02,
            reading_gate_p: 1e-6,
            reading_gate_restart: 5,
            depth_limit_m: 20.0,
            velocity_limit_mps: 5.0,
            start_both_ways: true,
            init_lateral_sigma_deg: Some(6.0),
            paper_range: true,
            paper_range_sigma_scale: 1.0,
            paper_rate: true,
            paper_rate_with_attitude: true,
            paper_rate_geometry: true,
            paper_rate_frames: 3,
            paper_rate_drift_mps: 0.05,
            water_bank: true,
            water_check_frames: 25,
            water_check_nis: 1.7,
            water_check_doubt: 0.3,
            reading_check_s: 5.0,
            reading_check_limit: 1.0,
            dvl_check: true,
            x_range: [3.0, 12.0],
            init_frames: 5,
            update_iterations: 1,
            nis_gate: 25.0,
            max_rejected: 3,
            max_gap_s: 2.0,
            max_saturated: 4,
            daylight: None,
        }
    }
}

impl TrackerConfig {
    /// The tracker's part of [`EstimatorSettings::in_water_known_to`]:
    /// an unset `k_d_sigma` takes `sigma_k_d`, an unset `temp_sigma_c`
    /// `sigma_temp_c`; set ones stay.
    pub fn in_water_known_to(mut self, sigma_k_d: f64, sigma_temp_c: f64) -> Self {
        self.k_d_sigma.get_or_insert(sigma_k_d);
        self.temp_sigma_c.get_or_insert(sigma_temp_c);
        self
    }
}
