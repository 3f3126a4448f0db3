//! The light equation of MODEL.md with its analytic derivatives with respect
//! to pose (x, y, z, θ, ψ), K_D and (spec v3) roll φ, in counts.
//!
//! Why analytic: Gauss–Newton, the EKF and the Cramér–Rao bound all need
//! ∂count/∂pose at every frame, and finite differences would cost six extra
//! model evaluations and lose digits near the beam axis. The chain goes
//! through the three quantities the light equation is written in — the
//! distance d, the beam angle α and the incidence angle β of each detector —
//! and uses α² and β² (smooth everywhere) rather than α and β (which have
//! cone points on the axis).

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::{Angle, NDET};
use nalgebra::{SMatrix, SVector};

use super::SensorModel;

/// Columns of the gradient: x, y, z, pitch, yaw (rad), K_D.
pub const NGRAD: usize = 6;

/// ∂count_k/∂(x, y, z, θ, ψ, K_D), one row per detector.
pub type PoseJacobian = SMatrix<f64, NDET, NGRAD>;

/// Pose as a plain vector: x, y, z in metres, pitch and yaw in radians.
pub type PoseVec = SVector<f64, 5>;

/// Build a core `Pose` from a pose vector.
#[inline]
pub fn to_pose(q: &PoseVec) -> lightpose_core::Pose {
    lightpose_core::Pose::new(
        q[0],
        q[1],
        q[2],
        Angle::from_rad(q[3]),
        Angle::from_rad(q[4]),
    )
}

/// Pose vector of a core `Pose`.
#[inline]
pub fn from_pose(p: &lightpose_core::Pose) -> PoseVec {
    PoseVec::new(p.x, p.y, p.z, p.pitch.rad(), p.yaw.rad())
}

#[inline]
fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn mat_vec(r: &[[f64; 3]; 3], v: &[f64; 3]) -> [f64; 3] {
    [dot(&r[0], v), dot(&r[1], v), dot(&r[2], v)]
}

#[inline]
fn mat_mat(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let col = |j: usize| [b[0][j], b[1][j], b[2][j]];
    let (c0, c1, c2) = (col(0), col(1), col(2));
    a.map(|row| [dot(&row, &c0), dot(&row, &c1), dot(&row, &c2)])
}

/// R_BV and its derivatives with respect to θ, ψ and φ, in that order.
type Rotations = [[[f64; 3]; 3]; 4];

/// R_BV = R0·Rz(ψ)·Ry(θ)·Rx(φ) (MODEL.md) and its derivatives with respect
/// to θ, ψ and φ.
#[inline]
fn rotations(theta: f64, psi: f64, phi: f64) -> Rotations {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    let r = [
        [-cp * ct, sp, -cp * st],
        [sp * ct, cp, sp * st],
        [st, 0.0, -ct],
    ];
    let r_t = [
        [cp * st, 0.0, -cp * ct],
        [-sp * st, 0.0, sp * ct],
        [ct, 0.0, st],
    ];
    let r_p = [
        [sp * ct, cp, sp * st],
        [cp * ct, -sp, cp * st],
        [0.0, 0.0, 0.0],
    ];
    // ∂(M·Rx(φ))/∂φ at φ = 0: column 1 → M's column 2, column 2 → −column 1.
    let roll_d = |m: &[[f64; 3]; 3]| m.map(|row| [0.0, row[2], -row[1]]);
    if phi == 0.0 {
        // Roll 0 is the v1/v2 matrices bit for bit (no ±0 from 0·x).
        return [r, r_t, r_p, roll_d(&r)];
    }
    // M·Rx(φ): column 1 → cφ·M1 + sφ·M2, column 2 → −sφ·M1 + cφ·M2 (as
    // core's `Attitude::r_bv`); the θ and ψ derivatives turn the same way.
    let (sr, cr) = phi.sin_cos();
    let roll = |m: &[[f64; 3]; 3]| {
        m.map(|row| {
            [
                row[0],
                cr * row[1] + sr * row[2],
                -sr * row[1] + cr * row[2],
            ]
        })
    };
    let rolled = roll(&r);
    [rolled, roll(&r_t), roll(&r_p), roll_d(&rolled)]
}

/// Expected counts of every channel at pose `q` (noise-free, unclamped,
/// unrounded), with `k_d` in place of the model's K_D and `gt` the
/// temperature gain g_T. Also returns the irradiance E_k (volts).
/// Roll 0 (spec v1/v2; see [`predict_rolled`]).
pub fn predict(
    m: &SensorModel,
    q: &PoseVec,
    k_d: f64,
    gt: f64,
) -> (SVector<f64, NDET>, [f64; NDET]) {
    predict_rolled(m, q, 0.0, k_d, gt)
}

/// As [`predict`], plus ∂count/∂(x, y, z, θ, ψ, K_D), at roll 0.
pub fn predict_with_grad(
    m: &SensorModel,
    q: &PoseVec,
    k_d: f64,
    gt: f64,
) -> (SVector<f64, NDET>, [f64; NDET], PoseJacobian) {
    let (c, e, j, _) = eval::<true, false>(m, None, q, 0.0, k_d, gt);
    (c, e, j)
}

/// As [`predict`] with the vehicle rolled by `roll` (radians; MODEL.md's
/// φ, starboard side down). Why roll is beside the pose vector rather
/// than in it: one Gaussian beacon barely sees roll, so the estimators
/// take it from the attitude reading (or a prior) and carry its doubt
/// into the other axes' σ rather than fit it (see docs/estimators.md).
pub fn predict_rolled(
    m: &SensorModel,
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> (SVector<f64, NDET>, [f64; NDET]) {
    predict_beacon(m, None, q, roll, k_d, gt)
}

/// As [`predict_rolled`], plus ∂count/∂(x, y, z, θ, ψ, K_D) and ∂count/∂φ.
pub fn predict_with_grad_rolled(
    m: &SensorModel,
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> (
    SVector<f64, NDET>,
    [f64; NDET],
    PoseJacobian,
    SVector<f64, NDET>,
) {
    predict_beacon_with_grad(m, None, q, roll, k_d, gt)
}

/// Where one beacon of a station stands in the frame D the pose is in
/// (spec v3, MODEL.md "Several beacons"): its position c_b and the turn
/// from D into its beam frame, whose +x is its optical axis. One beacon at
/// D's origin along +x_D is no placement at all (`None` below): D = B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// c_b in D, m.
    pub c: [f64; 3],
    /// Rows: the beam frame's axes in D, the optical axis first, so that a
    /// vector w of D is (row_i · w) in the beam frame. The beam is round,
    /// so which pair is taken across the axis does not matter.
    pub to_beam: [[f64; 3]; 3],
}

impl Placement {
    /// A beacon at `c` whose axis is (cos θa·cos ψa, cos θa·sin ψa, sin θa).
    pub fn new(c: [f64; 3], axis_yaw: Angle, axis_pitch: Angle) -> Self {
        let (st, ct) = axis_pitch.sin_cos();
        let (sp, cp) = axis_yaw.sin_cos();
        Placement {
            c,
            to_beam: [
                [ct * cp, ct * sp, st],
                [-sp, cp, 0.0],
                [-st * cp, -st * sp, ct],
            ],
        }
    }

    /// Whether this is D's origin along +x_D exactly (the v2 beacon).
    pub fn is_origin(&self) -> bool {
        self.c == [0.0; 3] && self.to_beam == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    }
}

/// One beacon of a station as the light equation sees it: its own V1 and
/// σ_b (the sensor model's σ_R, scattering and K_D are the water's and the
/// array's, shared by every beacon), where it stands, and how far its
/// image may be off the light equation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeaconLight {
    pub v1: f64,
    pub sigma_b: Angle,
    pub place: Placement,
    /// The image's model error relative to the light predicted for it
    /// (what the estimators add beside the demodulator's σ): what the
    /// station's calibration measured from its residuals
    /// (`CalibratedBeacon::model_rel`), or
    /// [`AMPLITUDE_MODEL_REL`](crate::model::measurement::AMPLITUDE_MODEL_REL)
    /// where nothing measured it (a scene's own beacons).
    pub model_rel: f64,
}

/// As [`predict_rolled`] for one beacon of a station (`None`: the sensor
/// model's own beacon at D's origin, bit for bit [`predict_rolled`]).
pub fn predict_beacon(
    m: &SensorModel,
    b: Option<&BeaconLight>,
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> (SVector<f64, NDET>, [f64; NDET]) {
    let (c, e, _, _) = eval::<false, false>(m, b, q, roll, k_d, gt);
    (c, e)
}

/// As [`predict_with_grad_rolled`] for one beacon of a station: the pose
/// is the vehicle's in D, and ∂/∂φ is a column like the others (a station
/// sees roll).
pub fn predict_beacon_with_grad(
    m: &SensorModel,
    b: Option<&BeaconLight>,
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> (
    SVector<f64, NDET>,
    [f64; NDET],
    PoseJacobian,
    SVector<f64, NDET>,
) {
    eval::<true, true>(m, b, q, roll, k_d, gt)
}

/// The light equation's constants for one evaluation: the same for every
/// detector (K_D may differ from the model's, see [`predict`]).
#[derive(Clone, Copy)]
struct Beam {
    v1: f64,
    /// σ_b and σ_R in radians.
    sb: f64,
    sr: f64,
    /// ω, and σ_R² + σ_h² (σ_R² without scattering).
    omega: f64,
    st2: f64,
    /// σ_R² / (σ_R² + σ_h²).
    ratio: f64,
    k_d: f64,
}

impl Beam {
    #[inline]
    fn new(m: &SensorModel, b: Option<&BeaconLight>, k_d: f64) -> Self {
        let l = &m.light;
        let (v1, sigma_b) = b.map_or((l.v1, l.sigma_b), |b| (b.v1, b.sigma_b));
        let sb = sigma_b.rad();
        let sr = l.sigma_r.rad();
        let (omega, st2) = match l.scattering {
            Some(s) => (s.omega, sr * sr + s.sigma_h.rad() * s.sigma_h.rad()),
            None => (0.0, sr * sr),
        };
        let ratio = sr * sr / st2;
        Beam {
            v1,
            sb,
            sr,
            omega,
            st2,
            ratio,
            k_d,
        }
    }
}

/// Where one detector sits as the beacon sees it: its body normal `n`, that
/// normal in the beam frame `mk`, its position `pk`, and the three
/// quantities the equation is written in (distance d, beam angle α,
/// incidence angle β, with ρ, cos β and sin β that the derivatives reuse).
#[derive(Clone, Copy)]
struct Sight {
    n: [f64; 3],
    mk: [f64; 3],
    pk: [f64; 3],
    d: f64,
    rho: f64,
    alpha: f64,
    c: f64,
    s: f64,
    beta: f64,
}

/// Detector `n` on the dome of radius `rh` at position `p` turned by `r`;
/// `None` at the beacon itself, where the equation has no meaning.
#[inline]
fn sight(r: &[[f64; 3]; 3], p: &[f64; 3], rh: f64, n: [f64; 3]) -> Option<Sight> {
    let mk = mat_vec(r, &n);
    let pk = [p[0] + rh * mk[0], p[1] + rh * mk[1], p[2] + rh * mk[2]];
    let d = dot(&pk, &pk).sqrt();
    if !(d > 1e-9) || !d.is_finite() {
        return None;
    }
    let rho = (pk[1] * pk[1] + pk[2] * pk[2]).sqrt();
    let alpha = rho.atan2(pk[0]);
    let mp = dot(&mk, &pk);
    let c = -mp / d;
    let cross = [
        mk[1] * pk[2] - mk[2] * pk[1],
        mk[2] * pk[0] - mk[0] * pk[2],
        mk[0] * pk[1] - mk[1] * pk[0],
    ];
    let s = dot(&cross, &cross).sqrt() / d;
    let beta = s.atan2(c);
    Some(Sight {
        n,
        mk,
        pk,
        d,
        rho,
        alpha,
        c,
        s,
        beta,
    })
}

/// The irradiance E = A·bracket of one detector, with the factors its
/// derivatives reuse: A = V1·beam·e^(−K_D d)/d², the direct (g_r) and
/// scattered (g_t) acceptance, and the scattered fraction f = 1 − e^(−ωK_D d).
#[derive(Clone, Copy)]
struct Irradiance {
    a: f64,
    g_r: f64,
    g_t: f64,
    escat: f64,
    f: f64,
    bracket: f64,
    e: f64,
}

#[inline]
fn irradiance(b: &Beam, s: &Sight) -> Irradiance {
    let beam = (-s.alpha * s.alpha / (2.0 * b.sb * b.sb)).exp();
    let att = (-b.k_d * s.d).exp();
    let path = att / (s.d * s.d);
    let a = b.v1 * beam * path;
    let (g_r, g_t) = if s.beta < std::f64::consts::FRAC_PI_2 {
        let b2 = s.beta * s.beta;
        (
            (-b2 / (2.0 * b.sr * b.sr)).exp(),
            (-b2 / (2.0 * b.st2)).exp(),
        )
    } else {
        (0.0, 0.0)
    };
    let escat = (-b.omega * b.k_d * s.d).exp();
    let f = 1.0 - escat;
    let bracket = (1.0 - f) * g_r + f * b.ratio * g_t;
    Irradiance {
        a,
        g_r,
        g_t,
        escat,
        f,
        bracket,
        e: a * bracket,
    }
}

/// ∂E/∂(x, y, z, θ, ψ, K_D) of one detector, in volts, and (when `ROLL`)
/// ∂E/∂φ: the partials of E in d, α² and β², chained through how each pose
/// coordinate moves p_k and turns m_k.
#[inline]
fn gradient<const ROLL: bool>(
    b: &Beam,
    s: &Sight,
    e: &Irradiance,
    rot: &Rotations,
    rh: f64,
    tr: &[[f64; 3]; 3],
) -> ([f64; NGRAD], f64) {
    let (a, d, pk) = (e.a, s.d, s.pk);
    let (bracket, f, g_r, g_t) = (e.bracket, e.f, e.g_r, e.g_t);
    let (k_d, omega, ratio) = (b.k_d, b.omega, b.ratio);
    // ∂/∂d, ∂/∂(α²), ∂/∂(β²) of E, then chain through ∂d, ∂α², ∂β².
    let db_dd = omega * k_d * e.escat * (ratio * g_t - g_r);
    let de_dd = a * (-(k_d + 2.0 / d) * bracket + db_dd);
    let de_da2 = -a * bracket / (2.0 * b.sb * b.sb);
    let de_db2 = -a * ((1.0 - f) * g_r / (2.0 * b.sr * b.sr) + f * ratio * g_t / (2.0 * b.st2));
    let de_dk = a * (-d * bracket + omega * d * e.escat * (ratio * g_t - g_r));

    // α/ρ → 1/p_x on the axis; behind the beacon on the axis the beam
    // factor is exp(−π²/2σ_b²) ≈ 0 and its gradient is taken as zero.
    let rho = s.rho;
    let a_over_rho = if rho > 1e-12 * d {
        s.alpha / rho
    } else if pk[0] > 0.0 {
        1.0 / pk[0]
    } else {
        0.0
    };
    let d2 = d * d;
    // ∂(α²)/∂p_k = 2(α/ρ)·(−ρ², p_x p_y, p_x p_z)/d²
    let da2_dpk = [
        -2.0 * a_over_rho * rho * rho / d2,
        2.0 * a_over_rho * pk[0] * pk[1] / d2,
        2.0 * a_over_rho * pk[0] * pk[2] / d2,
    ];
    // β/sin β → 1 as β → 0.
    let b_over_s = if s.s > 1e-12 { s.beta / s.s } else { 1.0 };

    // Derivatives of p_k and of the beam-frame normal m_k per pose
    // coordinate: position moves p_k only (along D's axes as the beam frame
    // sees them, `tr`); attitude turns both.
    let mt = mat_vec(&rot[1], &s.n);
    let mpsi = mat_vec(&rot[2], &s.n);
    let mphi = if ROLL {
        mat_vec(&rot[3], &s.n)
    } else {
        [0.0; 3]
    };
    let dpk: [[f64; 3]; 6] = [
        tr[0],
        tr[1],
        tr[2],
        [rh * mt[0], rh * mt[1], rh * mt[2]],
        [rh * mpsi[0], rh * mpsi[1], rh * mpsi[2]],
        [rh * mphi[0], rh * mphi[1], rh * mphi[2]],
    ];
    let dm: [[f64; 3]; 6] = [[0.0; 3], [0.0; 3], [0.0; 3], mt, mpsi, mphi];
    let chain = |j: usize| {
        let dd = dot(&pk, &dpk[j]) / d;
        let da2 = dot(&da2_dpk, &dpk[j]);
        // c = −m·p/d ⇒ dc = −(dm·p + m·dp)/d − c·dd/d
        let dc = -(dot(&dm[j], &pk) + dot(&s.mk, &dpk[j])) / d - s.c * dd / d;
        let db2 = -2.0 * b_over_s * dc;
        de_dd * dd + de_da2 * da2 + de_db2 * db2
    };
    let mut out = [0.0; NGRAD];
    for j in 0..5 {
        out[j] = chain(j);
    }
    out[5] = de_dk;
    (out, if ROLL { chain(5) } else { 0.0 })
}

/// The light equation for every detector at pose `q` rolled by `roll`:
/// counts, irradiance and, when `GRAD`, ∂count/∂(x, y, z, θ, ψ, K_D) and
/// (when `ROLL` too) ∂count/∂φ.
#[inline]
fn eval<const GRAD: bool, const ROLL: bool>(
    m: &SensorModel,
    b: Option<&BeaconLight>,
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> (
    SVector<f64, NDET>,
    [f64; NDET],
    PoseJacobian,
    SVector<f64, NDET>,
) {
    let mut counts = SVector::<f64, NDET>::zeros();
    let mut irr = [0.0; NDET];
    let mut jac = PoseJacobian::zeros();
    let mut jac_roll = SVector::<f64, NDET>::zeros();
    let beam = Beam::new(m, b, k_d);
    let cpv = m.counts_per_volt();
    let mut rot = rotations(q[3], q[4], roll);
    let mut p = [q[0], q[1], q[2]];
    // D's axes as the beam frame sees them: ∂p_k/∂(x, y, z).
    let mut tr = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    if let Some(place) = b.map(|b| &b.place).filter(|pl| !pl.is_origin()) {
        // Into the beam frame: p' = T(p − c), R' = T·R (and its derivatives).
        let t = &place.to_beam;
        let w = [p[0] - place.c[0], p[1] - place.c[1], p[2] - place.c[2]];
        p = mat_vec(t, &w);
        for r in rot.iter_mut() {
            *r = mat_mat(t, r);
        }
        tr = [
            [t[0][0], t[1][0], t[2][0]],
            [t[0][1], t[1][1], t[2][1]],
            [t[0][2], t[1][2], t[2][2]],
        ];
    }
    let rh = m.geometry.radius_m;
    for k in 0..NDET {
        let scale = m.gain[k] * gt * cpv;
        let off = m.offset_v[k] * cpv;
        let Some(s) = sight(&rot[0], &p, rh, m.geometry.normal(k).0) else {
            // At the beacon itself the equation has no meaning; the solver
            // keeps poses away from here, so any value that is finite will do.
            counts[k] = off;
            continue;
        };
        let e = irradiance(&beam, &s);
        irr[k] = e.e;
        counts[k] = scale * e.e + off;
        if !GRAD || e.a == 0.0 {
            continue;
        }
        let (de, de_roll) = gradient::<ROLL>(&beam, &s, &e, &rot, rh, &tr);
        for j in 0..NGRAD {
            jac[(k, j)] = scale * de[j];
        }
        jac_roll[k] = scale * de_roll;
    }
    (counts, irr, jac, jac_roll)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{LightParams, Pose, Scattering};

    #[test]
    fn matches_core_light_equation() {
        let m = SensorModel::default();
        for pose in [
            Pose::new(4.5, 0.0, 0.0, Angle::ZERO, Angle::ZERO),
            Pose::new(7.0, 0.4, -0.3, Angle::from_deg(8.0), Angle::from_deg(-11.0)),
            Pose::new(6.0, -0.3, 0.5, Angle::from_deg(-4.0), Angle::from_deg(6.0))
                .with_roll(Angle::from_deg(9.0)),
            Pose::new(3.0, 0.2, 0.1, Angle::ZERO, Angle::ZERO).with_roll(Angle::from_deg(-40.0)),
        ] {
            let mut e = [0.0; NDET];
            m.light.irradiance(&m.geometry, &pose, &mut e);
            let (c, irr) = predict_rolled(&m, &from_pose(&pose), pose.roll.rad(), m.light.k_d, 1.0);
            for k in 0..NDET {
                assert!((irr[k] - e[k]).abs() <= 1e-12 * e[k].max(1e-6), "{k}");
                let want = (e[k] + 0.15) * m.counts_per_volt();
                assert!((c[k] - want).abs() < 1e-9);
            }
        }
    }

    fn check_fd(m: &SensorModel, q: PoseVec) {
        let kd = m.light.k_d;
        let (_, _, jac) = predict_with_grad(m, &q, kd, 1.0);
        for j in 0..NGRAD {
            let h = if j < 3 { 1e-6 } else { 1e-7 };
            let (cp, cm) = if j < 5 {
                let mut qp = q;
                let mut qm = q;
                qp[j] += h;
                qm[j] -= h;
                (predict(m, &qp, kd, 1.0).0, predict(m, &qm, kd, 1.0).0)
            } else {
                (predict(m, &q, kd + h, 1.0).0, predict(m, &q, kd - h, 1.0).0)
            };
            for k in 0..NDET {
                let fd = (cp[k] - cm[k]) / (2.0 * h);
                let an = jac[(k, j)];
                let tol = 1e-5 * (an.abs() + fd.abs()) + 1e-5;
                assert!(
                    (fd - an).abs() < tol,
                    "q = {q:?}, col {j}, det {k}: analytic {an}, fd {fd}"
                );
            }
        }
    }

    /// At roll 0 the rolled evaluation is the v1/v2 one bit for bit (the
    /// regression logs compare poses byte for byte).
    #[test]
    fn roll_zero_is_the_v2_model_bit_for_bit() {
        let m = SensorModel::default();
        let q = PoseVec::new(6.2, 0.3, -0.2, 0.1, -0.15);
        let (c0, e0, j0) = predict_with_grad(&m, &q, m.light.k_d, 1.0);
        let (c1, e1, j1, jr) = predict_with_grad_rolled(&m, &q, 0.0, m.light.k_d, 1.0);
        assert_eq!(c0, c1);
        assert_eq!(e0, e1);
        assert_eq!(j0, j1);
        assert!(jr.iter().any(|v| *v != 0.0), "roll moves an off-axis image");
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config {
            cases: 64,
            rng_algorithm: proptest::test_runner::RngAlgorithm::ChaCha,
            rng_seed: proptest::test_runner::RngSeed::Fixed(40),
            ..Default::default()
        })]
        /// ∂count/∂φ and the other columns at a rolled pose match central
        /// differences of the rolled model.
        #[test]
        fn roll_gradient_matches_finite_differences(
            x in 2.0f64..9.0, y in -0.6f64..0.6, z in -0.6f64..0.6,
            th in -0.3f64..0.3, ps in -0.3f64..0.3, phi in -0.5f64..0.5,
        ) {
            let m = SensorModel::default();
            let kd = m.light.k_d;
            let q = PoseVec::new(x, y, z, th, ps);
            let (_, _, jac, jr) = predict_with_grad_rolled(&m, &q, phi, kd, 1.0);
            let h = 1e-7;
            let cp = predict_rolled(&m, &q, phi + h, kd, 1.0).0;
            let cm = predict_rolled(&m, &q, phi - h, kd, 1.0).0;
            for k in 0..NDET {
                let fd = (cp[k] - cm[k]) / (2.0 * h);
                let tol = 1e-5 * (jr[k].abs() + fd.abs()) + 1e-5;
                proptest::prop_assert!((fd - jr[k]).abs() < tol, "det {}: {} vs {}", k, jr[k], fd);
            }
            for j in 3..5 {
                let (mut qp, mut qm) = (q, q);
                qp[j] += h;
                qm[j] -= h;
                let cp = predict_rolled(&m, &qp, phi, kd, 1.0).0;
                let cm = predict_rolled(&m, &qm, phi, kd, 1.0).0;
                for k in 0..NDET {
                    let fd = (cp[k] - cm[k]) / (2.0 * h);
                    let an = jac[(k, j)];
                    let tol = 1e-5 * (an.abs() + fd.abs()) + 1e-5;
                    proptest::prop_assert!((fd - an).abs() < tol, "col {} det {}", j, k);
                }
            }
        }
    }

    /// A beacon of a station: off D's origin, its axis turned; what the
    /// simulator computes (MODEL.md: d = |p_k − c_b|, α off its axis,
    /// cos β = n·(c_b − p_k)/d) through core's light equation.
    fn placed() -> BeaconLight {
        BeaconLight {
            v1: 4.0,
            sigma_b: Angle::from_deg(20.0),
            place: Placement::new(
                [0.0, -0.5, 0.3],
                Angle::from_deg(-5.0),
                Angle::from_deg(3.0),
            ),
            model_rel: crate::model::measurement::AMPLITUDE_MODEL_REL,
        }
    }

    #[test]
    fn a_placed_beacon_is_the_light_equation_seen_from_it() {
        let m = SensorModel {
            light: LightParams {
                k_d: 0.2,
                ..LightParams::default()
            },
            ..SensorModel::default()
        };
        let b = placed();
        let axis = b.place.to_beam[0];
        let light = LightParams {
            v1: b.v1,
            sigma_b: b.sigma_b,
            ..m.light
        };
        for pose in [
            Pose::new(5.0, 0.1, -0.2, Angle::from_deg(4.0), Angle::from_deg(-6.0))
                .with_roll(Angle::from_deg(7.0)),
            Pose::new(
                2.0,
                -0.4,
                0.5,
                Angle::from_deg(-10.0),
                Angle::from_deg(12.0),
            ),
        ] {
            let (_, irr) =
                predict_beacon(&m, Some(&b), &from_pose(&pose), pose.roll.rad(), 0.2, 1.0);
            let att = pose.attitude();
            let p = pose.position().0;
            for k in 0..NDET {
                let n = att.to_beam(&m.geometry.normal(k)).0;
                let r = m.geometry.radius_m;
                let w: [f64; 3] = std::array::from_fn(|i| p[i] + r * n[i] - b.place.c[i]);
                let d = dot(&w, &w).sqrt();
                let cross = |a: &[f64; 3], v: &[f64; 3]| {
                    let x = [
                        a[1] * v[2] - a[2] * v[1],
                        a[2] * v[0] - a[0] * v[2],
                        a[0] * v[1] - a[1] * v[0],
                    ];
                    dot(&x, &x).sqrt()
                };
                let view = lightpose_core::light::DetectorView {
                    d,
                    alpha: cross(&axis, &w).atan2(dot(&axis, &w)),
                    beta: (cross(&n, &w) / d).atan2(-dot(&n, &w) / d),
                };
                let want = light.irradiance_at(&view);
                assert!(
                    (irr[k] - want).abs() <= 1e-12 * want.max(1e-9),
                    "{k}: {} vs {want}",
                    irr[k]
                );
            }
        }
    }

    /// Every column of a placed beacon's Jacobian, roll's too, matches
    /// central differences.
    #[test]
    fn a_placed_beacon_s_jacobian_matches_finite_differences() {
        let m = SensorModel::default();
        let b = placed();
        let kd = m.light.k_d;
        for (q, roll) in [
            (PoseVec::new(5.0, 0.2, -0.1, 0.05, -0.1), 0.12),
            (PoseVec::new(1.5, -0.3, 0.4, -0.2, 0.25), -0.3),
        ] {
            let (_, _, jac, jr) = predict_beacon_with_grad(&m, Some(&b), &q, roll, kd, 1.0);
            let at =
                |q: &PoseVec, roll: f64, kd: f64| predict_beacon(&m, Some(&b), q, roll, kd, 1.0).0;
            for j in 0..7 {
                let h = if j < 3 { 1e-6 } else { 1e-7 };
                let (cp, cm) = match j {
                    0..=4 => {
                        let (mut qp, mut qm) = (q, q);
                        qp[j] += h;
                        qm[j] -= h;
                        (at(&qp, roll, kd), at(&qm, roll, kd))
                    }
                    5 => (at(&q, roll, kd + h), at(&q, roll, kd - h)),
                    _ => (at(&q, roll + h, kd), at(&q, roll - h, kd)),
                };
                for k in 0..NDET {
                    let fd = (cp[k] - cm[k]) / (2.0 * h);
                    let an = if j < 6 { jac[(k, j)] } else { jr[k] };
                    let tol = 1e-5 * (an.abs() + fd.abs()) + 1e-5;
                    assert!((fd - an).abs() < tol, "col {j} det {k}: {an} vs {fd}");
                }
            }
        }
    }

    /// One beacon at D's origin along +x_D is the v2 beacon, bit for bit.
    #[test]
    fn a_beacon_at_the_origin_is_the_v2_beacon_bit_for_bit() {
        let m = SensorModel::default();
        let b = BeaconLight {
            v1: m.light.v1,
            sigma_b: m.light.sigma_b,
            place: Placement::new([0.0; 3], Angle::ZERO, Angle::ZERO),
            model_rel: crate::model::measurement::AMPLITUDE_MODEL_REL,
        };
        assert!(b.place.is_origin());
        let q = PoseVec::new(6.2, 0.3, -0.2, 0.1, -0.15);
        let a = predict_with_grad_rolled(&m, &q, 0.05, m.light.k_d, 1.0);
        let c = predict_beacon_with_grad(&m, Some(&b), &q, 0.05, m.light.k_d, 1.0);
        assert_eq!(a, c);
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let mut m = SensorModel::default();
        let poses = [
            PoseVec::new(4.5, 0.0, 0.0, 0.0, 0.0),
            PoseVec::new(6.2, 0.3, -0.2, 0.1, -0.15),
            PoseVec::new(8.5, -0.6, 0.8, -0.26, 0.26),
            PoseVec::new(2.0, 0.05, 0.01, 0.02, 0.4),
        ];
        for q in poses {
            check_fd(&m, q);
        }
        m.light = LightParams {
            scattering: None,
            ..LightParams::default()
        };
        for q in poses {
            check_fd(&m, q);
        }
        m.light.scattering = Some(Scattering {
            omega: 1.3,
            sigma_h: Angle::from_deg(35.0),
        });
        m.light.k_d = 0.2;
        for q in poses {
            check_fd(&m, q);
        }
    }
}
