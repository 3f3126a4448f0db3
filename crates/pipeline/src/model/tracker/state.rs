//! The tracker's state vector, its covariance and the bookkeeping that goes
//! with them, in one place so that every step (motion, readings, counts)
//! names the same indices.

use nalgebra::{SMatrix, SVector};

/// State: x, y, z, θ, ψ, three velocities (body model: surge u, sideslip
/// right v and down w; world model: ẋ, ẏ, ż), θ̇, ψ̇, ln K_D, the depth
/// sensor's offset, the attitude sensor's pitch offset, and (spec v3, last
/// so that every index before it stays) roll.
pub(super) const NS: usize = 14;
/// Index of the first velocity component.
pub(super) const VEL: usize = 5;
/// Paper ranges kept for their change over `paper_rate_frames`.
pub(super) const PAPER_RING: usize = crate::settings::PAPER_RATE_MAX_FRAMES;
/// Index of ln K_D. Why the logarithm: K_D is positive, and a doubt as
/// wide as turbid water's (±0.3 m⁻¹ about the tank's 0.09) put the sigma
/// points at K_D < 0, where the light equation had to be clamped at 0
/// (biasing the predicted brightness up); in ln K_D every point is a
/// water, and a doubt is a factor (`ln_k_d_sigma`).
pub(super) const KD: usize = 10;

/// Index of the depth sensor's offset (m): what its readings are off by
/// as a whole (`TrackerConfig::depth_offset_sigma_m`). Held at 0 with no
/// doubt unless that setting asks for it, and then a state the light
/// estimates (`offsets`).
pub(super) const DOFF: usize = 11;
/// Index of the attitude sensor's pitch offset (rad; the same for
/// `pitch_offset_sigma_deg`).
pub(super) const POFF: usize = 12;
/// Index of roll φ (rad). A state only on a docking station's light
/// (`State::roll_free`, see `station`): one beacon barely sees roll, so
/// there it is held at 0 with no doubt and roll is the consider
/// parameter `State::roll`, exactly as before the state had it.
pub(super) const ROLL: usize = 13;

/// The least K_D the state holds, m⁻¹: clearer than any natural water
/// (the clearest ocean's is ~0.02), so that a calibration's K_D of 0 still
/// has a logarithm.
pub(super) const MIN_K_D: f64 = 1e-3;

/// ln K_D as the state holds it.
pub(super) fn ln_k_d(k_d: f64) -> f64 {
    k_d.max(MIN_K_D).ln()
}

/// K_D of state `x`, m⁻¹.
pub(super) fn k_d_of(x: &Vs) -> f64 {
    x[KD].exp()
}

/// A doubt of `sigma_k_d` (m⁻¹, 1σ) about `k_d` as one tracker's state
/// carries it, in ln K_D: σ/K_D, the first-order spread of ln K_D, so that
/// the σ of K_D the filter works with (K_D times it) is the one told.
/// Only doubts up to `WaterBank::WIDE_LN_K_D` (a quarter of K_D) are one
/// tracker's; wider ones are a bank's (`ln_k_d_reach`). Why not ln(1 +
/// σ/K_D), which it was: at MODEL.md's Monte Carlo doubt (σ/K_D 0.17 in
/// the tank) that is 0.154, where the Gaussian draw's ln K_D spreads 0.17,
/// and x with all three sensors covered 92.8–93.1 % (bench, 400 runs;
/// 89–92 % over the first second); σ/K_D: 93.4–94.1 %.
pub(super) fn ln_k_d_sigma(k_d: f64, sigma_k_d: f64) -> f64 {
    sigma_k_d / k_d.max(MIN_K_D)
}

/// How far in ln K_D a told doubt of `sigma_k_d` reaches on either side
/// of `k_d`: ln(1 + σ/K_D), so that +1σ is K_D + σ exactly (turbid water,
/// the side that matters) and −1σ K_D/(1 + σ/K_D), above 0 however wide
/// the doubt. Where a bank of waters puts its members (`WaterBank`).
pub(super) fn ln_k_d_reach(k_d: f64, sigma_k_d: f64) -> f64 {
    (sigma_k_d / k_d.max(MIN_K_D)).ln_1p()
}

pub(super) type Vs = SVector<f64, NS>;
pub(super) type Ms = SMatrix<f64, NS, NS>;

#[derive(Debug, Clone, Copy)]
pub(super) struct State {
    pub x: Vs,
    pub p: Ms,
    pub t: f64,
    pub frames: u32,
    /// Frames in a row whose counts the gate refused.
    pub rejected: u32,
    /// Per reading (attitude, depth, velocity): readings in a row that the
    /// innovation gate refused.
    pub gated: [u32; 3],
    /// The paper's range of the frame read as x and refused by the gate,
    /// frames in a row (a jump no vehicle makes: `Tracker::jumped`).
    pub paper_refused: u32,
    /// K_D is estimated. Otherwise it is a *consider* state (Schmidt):
    /// its doubt and its covariance with the rest are carried in P, so every
    /// σ includes what K_D's doubt does to it, but no update moves K_D away
    /// from the calibration's value.
    pub k_d_free: bool,
    /// Per offset (depth, pitch: `offsets::Offset` order), estimated. An
    /// offset not estimated is a consider state of variance
    /// `offsets::HELD_VAR`: never moved, but its covariance with the rest
    /// carries how the state would move with it, so that waking it later
    /// (`which_offset`) gives the state's true doubt.
    pub offset_free: [bool; 2],
    /// The paper's range went into this frame's x, with this 1σ of its
    /// error (the law's residual over the calibration grid): see
    /// `Tracker::to_estimate`.
    pub paper_x: Option<f64>,
    /// The paper range's change went into this frame's velocity, so
    /// surge's σ holds its drift (`paper_rate_drift_mps`): see
    /// `Tracker::surge_of`.
    pub paper_rate_used: bool,
    /// This frame's attitude reading was fused: the next step's sideslip
    /// is the vehicle's own (`side_tau_with_attitude_s`).
    pub attitude_fused: bool,
    /// The last frames' paper ranges, newest at `paper_head`, for their
    /// change (`paper_rate`).
    pub last_paper: [Option<super::readings::PaperReading>; PAPER_RING],
    pub paper_head: usize,
    /// ln of the counts' density at this frame's innovation (less its
    /// constant), when the counts were fused: how well the state's water
    /// and pose explain the frame (`Tracker::counts_log_likelihood`).
    pub counts_ll: Option<f64>,
    /// This frame's counts' normalized innovation squared per channel,
    /// when they were fused.
    pub counts_nis: Option<f64>,
    /// ln of the fused readings' densities at their innovations this frame
    /// (less the constants), summed: with `counts_ll`, how well the state
    /// explains the whole frame (`Tracker::frame_log_likelihood`).
    pub readings_ll: f64,
    /// The last frames' `counts_nis` with a DVL reading fused (the water
    /// check, `water_check_frames`).
    pub water_nis: super::window::FrameWindow,
    /// Spec v3: the roll this frame is taken at (rad) and its 1σ: the
    /// attitude reading's, or the settings' prior (`settings::roll_of`).
    /// Why not a state: one beacon barely sees roll, so it is a *consider*
    /// parameter, held at what the frame says, whose doubt the counts'
    /// update carries into every other axis (`counts`). None: roll exactly
    /// 0, spec v1/v2's filter bit for bit.
    pub roll: Option<(f64, f64)>,
    /// Spec v3: roll is the state's `ROLL`, estimated from a station's
    /// beacons (`roll` is then unused). False for one beacon.
    pub roll_free: bool,
    /// Spec v3: the station's beacons this frame saw (the default, "not a
    /// station", for one beacon).
    pub station_seen: lightpose_core::StationSeen,
}

impl State {
    pub fn new(x: Vs, p: Ms, t: f64) -> Self {
        State {
            x,
            p,
            t,
            frames: 1,
            rejected: 0,
            gated: [0; 3],
            paper_refused: 0,
            k_d_free: false,
            offset_free: [false; 2],
            paper_x: None,
            paper_rate_used: false,
            attitude_fused: false,
            last_paper: [None; PAPER_RING],
            paper_head: 0,
            counts_ll: None,
            counts_nis: None,
            readings_ll: 0.0,
            water_nis: Default::default(),
            roll: None,
            roll_free: false,
            station_seen: Default::default(),
        }
    }

    /// The roll the light model is evaluated at (rad): 0 without one.
    pub fn roll_rad(&self) -> f64 {
        if self.roll_free {
            return self.x[ROLL];
        }
        self.roll.map_or(0.0, |(r, _)| r)
    }

    /// The body axes in B at the state's pitch, yaw and roll, with their
    /// derivatives in θ and ψ ([`body_axes`], [`body_axes_derivatives`]).
    /// The sideslip states are along the rolled axes (right and down as
    /// the DVL reads them).
    pub fn axes(&self) -> ([[f64; 3]; 3], [[[f64; 3]; 3]; 2]) {
        let (t, p) = (self.x[3], self.x[4]);
        let (a, d) = (body_axes(t, p), body_axes_derivatives(t, p));
        let phi = self.roll_rad();
        if phi == 0.0 {
            return (a, d);
        }
        (roll_axes(&a, phi), d.map(|d| roll_axes(&d, phi)))
    }

    /// Every number finite: what a step must leave behind.
    pub fn is_finite(&self) -> bool {
        self.x.iter().all(|v| v.is_finite()) && self.p.iter().all(|v| v.is_finite())
    }

    /// Give K_D the doubt `sigma_k_d` (1σ) about its current value in P. The
    /// range so far was found with K_D at that value, so it is only as good
    /// as that value: brightness ∝ e^(−K_D·x)/x² pins K_D·x + 2·ln x, i.e.
    /// δx = −x·δK_D/(K_D + 2/x), which goes in as the x–K_D covariance.
    /// Without it the filter took x as known to its σ and K_D as an
    /// independent doubt, and x's ±2σ covered 51–79 % with the attitude
    /// sensor (ridge_diag, estimate_k_d = true).
    pub fn doubt_k_d(&mut self, sigma_k_d: f64) {
        let k = k_d_of(&self.x);
        let sl = ln_k_d_sigma(k, sigma_k_d);
        let sk2 = sl * sl;
        let r = self.x[0].max(0.1);
        // ∂x/∂ln K_D = K_D·∂x/∂K_D.
        let g = -r * k / (k + 2.0 / r);
        for j in 0..NS {
            self.p[(KD, j)] = 0.0;
            self.p[(j, KD)] = 0.0;
        }
        self.p[(KD, KD)] = sk2;
        self.p[(0, 0)] += g * g * sk2;
        self.p[(0, KD)] = g * sk2;
        self.p[(KD, 0)] = g * sk2;
    }

    /// A Kalman gain as this state may apply it: with K_D, or an offset, a
    /// consider state, its row is zero (it stays; the Joseph form then keeps
    /// P honest).
    pub fn consider<const M: usize>(&self, k: &mut SMatrix<f64, NS, M>) {
        if !self.k_d_free {
            k.row_mut(KD).fill(0.0);
        }
        for (i, free) in [DOFF, POFF, ROLL].into_iter().zip([
            self.offset_free[0],
            self.offset_free[1],
            self.roll_free,
        ]) {
            if !free {
                k.row_mut(i).fill(0.0);
            }
        }
    }

    /// Keep `p` as the newest paper range.
    pub fn push_paper(&mut self, p: super::readings::PaperReading) {
        self.paper_head = (self.paper_head + 1) % PAPER_RING;
        self.last_paper[self.paper_head] = Some(p);
    }

    /// The paper range `back` frames before the newest (0: the newest).
    pub fn paper_back(&self, back: usize) -> Option<super::readings::PaperReading> {
        self.last_paper[(self.paper_head + PAPER_RING - back % PAPER_RING) % PAPER_RING]
    }

    /// 1σ of state component `i`.
    pub fn sd(&self, i: usize) -> f64 {
        self.p[(i, i)].max(0.0).sqrt()
    }
}

/// What the ridges' doubt does to range, m (1σ), for the reported σx.
///
/// Why: the beam factor exp(−α²/2σ_b²) is even in the vehicle's off-axis
/// angle α, so a spread of the estimate across the beam axis (wide y or z,
/// as without an attitude sensor) leaves the spot's brightness, hence
/// range, uncertain in a way that has no linear correlation with y or z,
/// so no Gaussian filter's covariance carries it. With α² ≈ (y² + z²)/x²
/// and (y, z) ~ N(μ, Σ), Var(α²) = (4·μᵀΣμ + 2·tr Σ²)/x⁴ (a quadratic
/// form's variance); the first term is the linear part, already in P
/// through the x–y and x–z covariances, so only 2·tr Σ² is added here.
/// ln-brightness moves by half of that over σ_b², and range by that over
/// K_D + 2/x. With an attitude sensor Σ is centimetres and this vanishes.
pub(super) fn beam_consider_sigma_x(x: &Vs, p: &Ms, sigma_b_rad: f64) -> f64 {
    let r = x[0].max(0.1);
    let (syy, szz, syz) = (p[(1, 1)], p[(2, 2)], p[(1, 2)]);
    let tr_s2 = syy * syy + szz * szz + 2.0 * syz * syz;
    let var_q = (2.0 * tr_s2).max(0.0) / r.powi(4);
    let sd_ln_b = var_q.sqrt() / (2.0 * sigma_b_rad * sigma_b_rad);
    let v = sd_ln_b / ln_brightness_per_metre(x);
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// How fast the spot's ln-brightness falls with range at the state, per
/// metre: Beer's law and the inverse square, K_D + 2/x. What turns a
/// brightness doubt (the beam's, the temperature's gain) into range.
pub(super) fn ln_brightness_per_metre(x: &Vs) -> f64 {
    k_d_of(x) + 2.0 / x[0].max(0.1)
}

/// The body axes in B (columns of R_BV: forward, right, down) at pitch θ
/// and yaw ψ (MODEL.md's R0·Rz(ψ)·Ry(θ)).
#[inline]
pub(super) fn body_axes(theta: f64, psi: f64) -> [[f64; 3]; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    [
        [-cp * ct, sp * ct, st],
        [sp, cp, 0.0],
        [-cp * st, sp * st, -ct],
    ]
}

/// Axes (or their derivatives) in the order of [`body_axes`] turned by
/// roll φ about the forward axis: R_BV's columns of M·Rx(φ) (MODEL.md),
/// right → cφ·right + sφ·down, down → −sφ·right + cφ·down.
#[inline]
pub(super) fn roll_axes(a: &[[f64; 3]; 3], phi: f64) -> [[f64; 3]; 3] {
    let (sr, cr) = phi.sin_cos();
    let mix = |u: f64, v: f64, i: usize| u * a[1][i] + v * a[2][i];
    [
        a[0],
        [mix(cr, sr, 0), mix(cr, sr, 1), mix(cr, sr, 2)],
        [mix(-sr, cr, 0), mix(-sr, cr, 1), mix(-sr, cr, 2)],
    ]
}

/// ∂(body axes)/∂θ and ∂(body axes)/∂ψ, in the order of [`body_axes`].
#[inline]
pub(super) fn body_axes_derivatives(theta: f64, psi: f64) -> [[[f64; 3]; 3]; 2] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    [
        [
            [cp * st, -sp * st, ct],
            [0.0, 0.0, 0.0],
            [-cp * ct, sp * ct, st],
        ],
        [
            [sp * ct, cp * ct, 0.0],
            [cp, -sp, 0.0],
            [sp * st, cp * st, 0.0],
        ],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A told doubt's reach in ln K_D: +1σ is K_D + σ exactly, −1σ is
        /// K_D/(1 + σ/K_D) (above 0 however wide the doubt); one tracker's
        /// σ in ln K_D is σ/K_D, which the reach matches to first order.
        #[test]
        fn a_k_d_doubt_in_ln_k_d_reaches_k_d_plus_sigma(k in 0.01f64..2.0, r in 0.0f64..50.0) {
            let sigma = k * r;
            let s = ln_k_d_reach(k, sigma);
            let up = (ln_k_d(k) + s).exp();
            let down = (ln_k_d(k) - s).exp();
            prop_assert!((up - (k + sigma)).abs() <= 1e-9 * (k + sigma));
            prop_assert!(down > 0.0 && (down - k / (1.0 + r)).abs() <= 1e-9 * k);
            let one = ln_k_d_sigma(k, sigma);
            prop_assert!((one * k - sigma).abs() <= 1e-12 * (1.0 + sigma));
            if r < 0.01 {
                prop_assert!((s - one).abs() <= r * r);
            }
        }
    }
}
