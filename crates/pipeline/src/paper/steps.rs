//! The per-frame steps of the paper's method, each a small pure function
//! over fixed-size arrays (no heap), in the order the estimator runs them:
//! counts → volts − dark offset, temperature correction (eq. 14), the
//! sub-pixel peak, the moments (eq. 1), x from the peak (eqs. 2–3) and the
//! carry-forward of y and z along the bow (eqs. 8–13). Every function says
//! through its return type when a frame cannot give an answer, instead of
//! returning NaN.

use crate::calibration::{Feature, Moment, Origin};
use lightpose_core::light::{temperature_gain, WATER_TEMP_C};
use lightpose_core::{frame::full_scale, COLS, NDET, ROWS};

/// 3 × 3 moment matrix, `m[p][q]`: p the power of the column offset, q of
/// the row offset (0-based; the paper's M33 is `m[2][2]`).
pub type MomentMatrix = [[f64; 3]; 3];

/// Step 1: counts to volts by the frame's own ADC resolution, minus each
/// channel's dark offset. Also says whether any channel sat at full scale.
#[inline]
pub fn signal_volts(
    counts: &[u16; NDET],
    bits: u8,
    v_ref: f64,
    dark: &[f64; NDET],
    out: &mut [f64; NDET],
) -> bool {
    let fs = full_scale(bits);
    let scale = v_ref / fs as f64;
    let mut saturated = false;
    for k in 0..NDET {
        saturated |= counts[k] >= fs;
        out[k] = counts[k] as f64 * scale - dark[k];
    }
    saturated
}

/// Step 2: undo the responsivity's temperature dependence. MODEL.md has
/// V = g_k·g_T(T)·E + o_k, so the offset-free signal is divided by g_T(T)
/// (the paper's eq. 14 as a relative change). `false` when T is not a water
/// temperature (`WATER_TEMP_C`, as for the model and the tracker: at 100 °C
/// g_T would still be 0.70, a range 14 % short at 6 m), and the signal is left
/// untouched.
#[inline]
pub fn correct_temperature(signal: &mut [f64; NDET], temp_c: f64) -> bool {
    if !WATER_TEMP_C.contains(&temp_c) {
        return false;
    }
    let g = temperature_gain(temp_c);
    let inv = 1.0 / g;
    for s in signal.iter_mut() {
        *s *= inv;
    }
    true
}

/// The brightest detector and the sub-pixel position of the peak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    pub r: usize,
    pub c: usize,
    /// Signal of the brightest detector (the paper's PD_max), volts.
    pub value: f64,
    /// Sub-pixel row and column of the peak, 0..4.
    pub row: f64,
    pub col: f64,
}

/// Offset of a peak from the middle of three samples, in −0.5..0.5.
///
/// A Gaussian through the three (a parabola in ln) when all are positive,
/// which is exact for the beam's Gaussian spot; a parabola in the values
/// otherwise. A flat or non-peaked triple (curvature ≥ 0) gives 0: the peak
/// is then no better known than the pixel.
#[inline]
pub fn subpixel_offset(before: f64, mid: f64, after: f64) -> f64 {
    let (a, b, c) = if before > 0.0 && mid > 0.0 && after > 0.0 {
        (before.ln(), mid.ln(), after.ln())
    } else {
        (before, mid, after)
    };
    let curv = a - 2.0 * b + c;
    // Relative threshold: a curvature at rounding level of the values is flat.
    if curv.is_nan() || curv >= -1e-12 * (a.abs() + b.abs() + c.abs() + f64::MIN_POSITIVE) {
        return 0.0;
    }
    let off = (a - c) / (2.0 * curv);
    if off.is_finite() {
        off.clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// Step 3a: the brightest detector, refined to sub-pixel accuracy along its
/// row and its column. On the array's edge there is no neighbour outside,
/// and the peak stays on the pixel in that direction.
#[inline]
pub fn find_peak(img: &[f64; NDET]) -> Peak {
    let mut k = 0;
    for i in 1..NDET {
        if img[i] > img[k] {
            k = i;
        }
    }
    let (r, c) = (k / COLS, k % COLS);
    let v = img[k];
    let dr = if r > 0 && r + 1 < ROWS {
        subpixel_offset(img[k - COLS], v, img[k + COLS])
    } else {
        0.0
    };
    let dc = if c > 0 && c + 1 < COLS {
        subpixel_offset(img[k - 1], v, img[k + 1])
    } else {
        0.0
    };
    Peak {
        r,
        c,
        value: v,
        row: r as f64 + dr,
        col: c as f64 + dc,
    }
}

/// Step 3b: the image moments of eq. 1 about (row0, col0):
/// M_pq = Σ (c − col0)^p (r − row0)^q I / Σ I. `None` when the total
/// intensity is not positive (no light to take moments of).
#[inline]
pub fn moments(img: &[f64; NDET], row0: f64, col0: f64) -> Option<MomentMatrix> {
    let mut m = [[0.0; 3]; 3];
    let mut s = 0.0;
    for r in 0..ROWS {
        let v = r as f64 - row0;
        let vq = [1.0, v, v * v];
        for c in 0..COLS {
            let i = img[r * COLS + c];
            let u = c as f64 - col0;
            let up = [i, u * i, u * u * i];
            s += i;
            for p in 0..3 {
                for q in 0..3 {
                    m[p][q] += up[p] * vq[q];
                }
            }
        }
    }
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let inv = 1.0 / s;
    for row in m.iter_mut() {
        for x in row.iter_mut() {
            *x *= inv;
        }
    }
    Some(m)
}

/// Moments about the sub-pixel peak and about the centre detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BothMoments {
    pub peak: MomentMatrix,
    pub centre: MomentMatrix,
}

/// Step 3 complete: both moment matrices of a frame.
#[inline]
pub fn both_moments(img: &[f64; NDET], peak: &Peak) -> Option<BothMoments> {
    let centre = ((ROWS - 1) as f64 / 2.0, (COLS - 1) as f64 / 2.0);
    Some(BothMoments {
        peak: moments(img, peak.row, peak.col)?,
        centre: moments(img, centre.0, centre.1)?,
    })
}

/// Below this |M22| a ratio by it is noise divided by nothing (the
/// "vanishing M33" of the issue): no ratio is formed.
pub const MIN_M22: f64 = 1e-9;

/// The value of one feature. `None` for a ratio whose M22 vanishes.
#[inline]
pub fn feature_value(f: Feature, m: &BothMoments) -> Option<f64> {
    let mm = match f.origin {
        Origin::Peak => &m.peak,
        Origin::Centre => &m.centre,
    };
    let ratio = |num: f64| {
        let d = mm[2][2];
        if d.abs() < MIN_M22 || !d.is_finite() {
            None
        } else {
            Some(num / d).filter(|v| v.is_finite())
        }
    };
    match f.moment {
        Moment::M10 => Some(mm[1][0]),
        Moment::M01 => Some(mm[0][1]),
        Moment::M12OverM22 => ratio(mm[1][2]),
        Moment::M21OverM22 => ratio(mm[2][1]),
    }
}

/// Step 4a: x from the peak (eq. 3), x = −ln(PD_max / a1) / b1. `None` for a
/// peak that is not positive (the log of no light).
#[inline]
pub fn range_from_peak(pd_max: f64, a1: f64, b1: f64) -> Option<f64> {
    if !(pd_max > 0.0 && a1 > 0.0 && b1 > 0.0) {
        return None;
    }
    let x = -(pd_max / a1).ln() / b1;
    x.is_finite().then_some(x)
}

/// Below this cos θ·cos ψ the bow is nearly across the beam axis and a step
/// in x says nothing about the travel along the bow.
pub const MIN_COS_PRODUCT: f64 = 0.05;

/// Travel along the bow implied by a change dx of x (eqs. 8–9). The paper's
/// R = dx/(cos θ cos ψ) is taken with MODEL.md's sign: travel s is positive
/// when the vehicle moves the way its bow points, and then x decreases
/// (forward axis in B = (−cθcψ, cθsψ, sθ)), so s = −dx/(cθcψ).
#[inline]
pub fn travel_along_bow(dx: f64, pitch_rad: f64, yaw_rad: f64) -> Option<f64> {
    let k = pitch_rad.cos() * yaw_rad.cos();
    if k.is_nan() || k.abs() < MIN_COS_PRODUCT || !dx.is_finite() {
        return None;
    }
    Some(-dx / k)
}

/// The y and z steps of a travel s along the bow (eqs. 10–11):
/// dy = s·cθ·sψ, dz = s·sθ.
#[inline]
pub fn carry_forward(s: f64, pitch_rad: f64, yaw_rad: f64) -> (f64, f64) {
    let (st, ct) = pitch_rad.sin_cos();
    (s * ct * yaw_rad.sin(), s * st)
}

/// A frame through steps 1–3: the corrected image, its peak and moments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prepared {
    pub img: [f64; NDET],
    pub peak: Peak,
    pub moments: BothMoments,
}

/// Steps 1–3 on one frame, or the status that says why the frame gives no
/// pose: a temperature that is not water's or a bad resolution (BadFrame),
/// a peak below `no_light_v` (NoLight), any channel at full scale
/// (Saturated: a clipped peak understates PD_max and skews every moment).
/// The calibration and the estimator both go through here, so that they
/// see frames alike.
#[inline]
pub fn prepare(
    frame: &lightpose_core::Frame,
    v_ref: f64,
    dark: &[f64; NDET],
    default_temp_c: f64,
    no_light_v: f64,
) -> Result<Prepared, lightpose_core::Status> {
    use lightpose_core::Status;
    if !(1..=16).contains(&frame.adc_bits) {
        return Err(Status::BadFrame);
    }
    let mut img = [0.0; NDET];
    let saturated = match frame.amplitudes.as_ref() {
        // A demodulated frame's beacon image has no dark offset (it is the
        // on level minus the off level); a clipped sample spoils it.
        Some(a) => match a.beacon(crate::model::measurement::BEACON) {
            Some(b) => {
                let scale = v_ref / full_scale(frame.adc_bits) as f64;
                for (v, amp) in img.iter_mut().zip(b.amplitude) {
                    *v = amp * scale;
                }
                a.clipped.iter().any(|&c| c > 0)
            }
            None => return Err(Status::NoLight),
        },
        None => signal_volts(&frame.counts, frame.adc_bits, v_ref, dark, &mut img),
    };
    let temp = frame
        .temp_c
        .filter(|t| t.is_finite())
        .unwrap_or(default_temp_c);
    if !correct_temperature(&mut img, temp) {
        return Err(Status::BadFrame);
    }
    let peak = find_peak(&img);
    // NaN peaks (impossible from counts, but guarded) count as no light.
    if peak.value.is_nan() || peak.value < no_light_v {
        return Err(Status::NoLight);
    }
    if saturated {
        return Err(Status::Saturated);
    }
    let moments = both_moments(&img, &peak).ok_or(Status::NoLight)?;
    Ok(Prepared { img, peak, moments })
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{
        array::index, frame::volts_to_counts, Angle, ArrayGeometry, LightParams, Pose,
    };
    use proptest::prelude::*;

    fn image(pose: &Pose) -> [f64; NDET] {
        let mut e = [0.0; NDET];
        LightParams::default().irradiance(&ArrayGeometry::paper(), pose, &mut e);
        e
    }

    #[test]
    fn volts_by_resolution_minus_offset() {
        let dark = [0.15; NDET];
        for bits in [10u8, 12, 16] {
            let fs = full_scale(bits);
            let mut counts = [0u16; NDET];
            counts[3] = fs;
            counts[4] = volts_to_counts(1.15, 5.0, bits);
            let mut out = [0.0; NDET];
            let sat = signal_volts(&counts, bits, 5.0, &dark, &mut out);
            assert!(sat, "{bits} bits: full scale is saturation");
            assert!((out[3] - 4.85).abs() < 1e-12);
            assert!(
                (out[4] - 1.0).abs() <= 5.0 / fs as f64,
                "{bits}: {}",
                out[4]
            );
            assert!((out[0] + 0.15).abs() < 1e-12);
        }
        let mut out = [0.0; NDET];
        assert!(!signal_volts(&[100; NDET], 10, 5.0, &dark, &mut out));
    }

    #[test]
    fn temperature_correction_undoes_eq14() {
        let e = image(&Pose::new(6.0, 0.1, 0.2, Angle::ZERO, Angle::ZERO));
        for t in [5.0, 20.0, 31.5] {
            let mut v = e;
            for x in v.iter_mut() {
                *x *= temperature_gain(t);
            }
            assert!(correct_temperature(&mut v, t));
            for k in 0..NDET {
                assert!((v[k] - e[k]).abs() <= 1e-12 * e[k].abs());
            }
        }
        let mut v = e;
        assert!(!correct_temperature(&mut v, 400.0));
        assert!(!correct_temperature(&mut v, 100.0));
        assert!(!correct_temperature(&mut v, -20.0));
        assert!(!correct_temperature(&mut v, f64::NAN));
        assert_eq!(v, e);
    }

    #[test]
    fn subpixel_is_exact_for_a_gaussian() {
        for true_off in [-0.45, -0.2, 0.0, 0.13, 0.49] {
            let g = |x: f64| 3.0 * (-(x - true_off) * (x - true_off) / (2.0 * 0.8 * 0.8)).exp();
            let off = subpixel_offset(g(-1.0), g(0.0), g(1.0));
            assert!((off - true_off).abs() < 1e-12, "{true_off}: {off}");
        }
    }

    #[test]
    fn flat_peak_stays_on_the_pixel() {
        assert_eq!(subpixel_offset(2.0, 2.0, 2.0), 0.0);
        assert_eq!(subpixel_offset(0.0, 0.0, 0.0), 0.0);
        assert_eq!(subpixel_offset(1.0, 0.5, 1.0), 0.0); // a valley, not a peak
                                                         // non-positive neighbours fall back to the plain parabola
        let off = subpixel_offset(-0.1, 1.0, 0.5);
        assert!(off > 0.0 && off <= 0.5);
    }

    #[test]
    fn peak_moves_the_way_model_md_says() {
        // Positive y moves the spot to the left columns, positive z to the
        // bottom rows (MODEL.md "Frames and pose").
        let centre = find_peak(&image(&Pose::new(6.0, 0.0, 0.0, Angle::ZERO, Angle::ZERO)));
        assert_eq!((centre.r, centre.c), (2, 2));
        assert!((centre.row - 2.0).abs() < 1e-9 && (centre.col - 2.0).abs() < 1e-9);
        let yaw = find_peak(&image(&Pose::new(
            6.0,
            0.0,
            0.0,
            Angle::ZERO,
            Angle::from_deg(8.0),
        )));
        assert!(yaw.col < 2.0 - 0.1, "{yaw:?}");
        let pitch = find_peak(&image(&Pose::new(
            6.0,
            0.0,
            0.0,
            Angle::from_deg(8.0),
            Angle::ZERO,
        )));
        assert!(pitch.row > 2.0 + 0.1, "{pitch:?}");
    }

    #[test]
    fn moments_of_a_point_and_of_nothing() {
        let mut img = [0.0; NDET];
        img[index(1, 3)] = 2.0;
        let m = moments(&img, 2.0, 2.0).unwrap();
        assert!((m[0][0] - 1.0).abs() < 1e-15);
        assert!((m[1][0] - 1.0).abs() < 1e-15); // column 3 is +1 from the centre
        assert!((m[0][1] + 1.0).abs() < 1e-15); // row 1 is −1
        assert!((m[2][2] - 1.0).abs() < 1e-15);
        assert!(moments(&[0.0; NDET], 2.0, 2.0).is_none());
        // About the point itself every moment but M00 vanishes, and a
        // ratio by M22 is refused rather than divided by zero.
        let both = BothMoments {
            peak: moments(&img, 1.0, 3.0).unwrap(),
            centre: m,
        };
        assert_eq!(
            feature_value(Feature::new(Moment::M12OverM22, Origin::Peak), &both),
            None
        );
        assert_eq!(
            feature_value(Feature::new(Moment::M10, Origin::Peak), &both),
            Some(0.0)
        );
        assert_eq!(
            feature_value(Feature::new(Moment::M21OverM22, Origin::Centre), &both),
            Some(-1.0)
        );
    }

    #[test]
    fn range_guards_the_log_of_nothing() {
        let x = range_from_peak(20.0 * (-0.3f64 * 6.0).exp(), 20.0, 0.3).unwrap();
        assert!((x - 6.0).abs() < 1e-12);
        assert_eq!(range_from_peak(0.0, 20.0, 0.3), None);
        assert_eq!(range_from_peak(-0.1, 20.0, 0.3), None);
        assert_eq!(range_from_peak(1.0, 20.0, 0.0), None);
    }

    #[test]
    fn carry_forward_follows_the_bow() {
        // Approaching head-on with nose up: x falls, z rises (MODEL.md).
        let (t, p) = (10f64.to_radians(), 0.0);
        let s = travel_along_bow(-0.1, t, p).unwrap();
        assert!(s > 0.0);
        let (dy, dz) = carry_forward(s, t, p);
        assert!(dy.abs() < 1e-15 && dz > 0.0);
        // The step is the bow direction scaled: (dx, dy, dz) ∥ forward axis.
        let (t, p) = (0.2f64, -0.3f64);
        let s = travel_along_bow(-0.25, t, p).unwrap();
        let (dy, dz) = carry_forward(s, t, p);
        let fwd = [-t.cos() * p.cos(), t.cos() * p.sin(), t.sin()];
        for (d, f) in [-0.25, dy, dz].iter().zip(fwd) {
            assert!((d - s * f).abs() < 1e-12);
        }
        assert_eq!(travel_along_bow(0.1, 1.55, 0.0), None);
        assert_eq!(travel_along_bow(f64::NAN, 0.0, 0.0), None);
    }

    proptest! {
        /// Moments are finite or refused, never NaN, for any image.
        #[test]
        fn moments_never_nan(img in prop::array::uniform25(-1.0f64..5.0), r0 in 0.0f64..4.0, c0 in 0.0f64..4.0) {
            if let Some(m) = moments(&img, r0, c0) {
                prop_assert!(m.iter().flatten().all(|v| v.is_finite()));
            }
            let p = find_peak(&img);
            prop_assert!(p.row.is_finite() && p.col.is_finite());
            prop_assert!((p.row - p.r as f64).abs() <= 0.5 && (p.col - p.c as f64).abs() <= 0.5);
        }

        /// The sub-pixel offset is bounded and finite for any triple.
        #[test]
        fn subpixel_bounded(a in -10.0f64..10.0, b in -10.0f64..10.0, c in -10.0f64..10.0) {
            let o = subpixel_offset(a, b, c);
            prop_assert!(o.is_finite() && o.abs() <= 0.5);
        }
    }
}
