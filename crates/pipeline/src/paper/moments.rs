//! The paper's estimator (Algorithm 1): per frame, the steps of
//! [`steps`] with the coefficients of a [`Calibration`]; between
//! frames, y and z carried forward along the bow (eqs. 8–13) and surge from
//! the slope of x over a window. All state is in fixed arrays, so a frame
//! costs no heap allocation.

use super::steps;
use crate::calibration::{Calibration, LinearFit, RangeFit, MAX_SURGE_WINDOW};
use lightpose_core::{Estimator, Frame, PoseEstimate, Status, NDET};

/// What the estimator needs of a calibration, unpacked once.
#[derive(Debug, Clone)]
struct Coeffs {
    dark: [f64; NDET],
    v_ref: f64,
    default_temp_c: f64,
    x: RangeFit,
    pitch: LinearFit,
    yaw: LinearFit,
    y: LinearFit,
    z: LinearFit,
    /// [lo, hi] with the margins already added.
    x_ok: [f64; 2],
    y_ok: [f64; 2],
    z_ok: [f64; 2],
    pitch_ok: [f64; 2],
    yaw_ok: [f64; 2],
    no_light_v: f64,
    window: usize,
    max_gap_s: f64,
}

/// Samples of (t, x) for the surge slope, oldest overwritten first.
#[derive(Debug, Clone, Copy)]
struct Ring {
    t: [f64; MAX_SURGE_WINDOW],
    x: [f64; MAX_SURGE_WINDOW],
    len: usize,
    head: usize,
}

impl Ring {
    const fn new() -> Self {
        Ring {
            t: [0.0; MAX_SURGE_WINDOW],
            x: [0.0; MAX_SURGE_WINDOW],
            len: 0,
            head: 0,
        }
    }

    fn push(&mut self, cap: usize, t: f64, x: f64) {
        self.t[self.head] = t;
        self.x[self.head] = x;
        self.head = (self.head + 1) % cap;
        self.len = (self.len + 1).min(cap);
    }

    /// Least-squares slope dx/dt over the samples held, and its 1σ for a
    /// per-sample σ of x. Over a full window this is the smoothed velocity:
    /// it has a smaller variance than the difference of the window's ends
    /// (the moving average of step velocities), for the same delay.
    fn slope(&self, sigma_x: f64) -> Option<(f64, f64)> {
        let n = self.len as f64;
        let (mut st, mut sx) = (0.0, 0.0);
        for i in 0..self.len {
            st += self.t[i];
            sx += self.x[i];
        }
        let (mt, mx) = (st / n, sx / n);
        let (mut stt, mut stx) = (0.0, 0.0);
        for i in 0..self.len {
            let dt = self.t[i] - mt;
            stt += dt * dt;
            stx += dt * (self.x[i] - mx);
        }
        if stt.is_nan() || stt <= 1e-12 {
            return None;
        }
        let s = stx / stt;
        s.is_finite().then_some((s, sigma_x / stt.sqrt()))
    }
}

/// Carried state between frames.
#[derive(Debug, Clone, Copy)]
struct Track {
    /// y, z after the last usable frame.
    yz: Option<(f64, f64)>,
    last_x: f64,
    last_t: f64,
    ring: Ring,
}

impl Track {
    const fn new() -> Self {
        Track {
            yz: None,
            last_x: 0.0,
            last_t: f64::NEG_INFINITY,
            ring: Ring::new(),
        }
    }
}

/// The image-moments estimator of the paper.
#[derive(Debug, Clone)]
pub struct MomentsEstimator {
    k: Coeffs,
    track: Track,
}

/// Name in POSE messages.
pub const NAME: &str = "moments";

impl MomentsEstimator {
    /// Unpack a calibration (which `Calibration::load` has already checked).
    pub fn new(cal: &Calibration) -> Self {
        let c = &cal.coverage;
        let l = &cal.limits;
        let widen = |r: [f64; 2], m: f64| [r[0] - m, r[1] + m];
        MomentsEstimator {
            k: Coeffs {
                dark: cal.dark_offsets(),
                v_ref: cal.scene.v_ref,
                default_temp_c: cal.scene.default_temp_c,
                x: cal.fits.x.clone(),
                pitch: cal.fits.pitch.clone(),
                yaw: cal.fits.yaw.clone(),
                y: cal.fits.y.clone(),
                z: cal.fits.z.clone(),
                x_ok: widen(c.x_m, l.margin_x_m),
                y_ok: widen(c.y_m, l.margin_yz_m),
                z_ok: widen(c.z_m, l.margin_yz_m),
                pitch_ok: widen(c.pitch_deg, l.margin_angle_deg),
                yaw_ok: widen(c.yaw_deg, l.margin_angle_deg),
                no_light_v: l.no_light_v,
                window: l.surge_window.clamp(2, MAX_SURGE_WINDOW),
                max_gap_s: l.max_gap_s,
            },
            track: Track::new(),
        }
    }

    /// The paper's range of one frame (steps 1–4's x: the brightest
    /// channel through eqs. 2–3), the same as `estimate` gives, but
    /// without touching the track that its y, z and surge carry: what the
    /// tracker reads of the law, of the frames and of its own model's.
    pub fn range_of(&self, frame: &lightpose_core::Frame) -> Option<f64> {
        if !frame.t.is_finite() {
            return None;
        }
        self.prepared(frame).ok().and_then(|p| self.range(&p))
    }

    /// Steps 1–3 of `frame` with this calibration's coefficients.
    fn prepared(&self, frame: &lightpose_core::Frame) -> Result<steps::Prepared, Status> {
        let k = &self.k;
        steps::prepare(frame, k.v_ref, &k.dark, k.default_temp_c, k.no_light_v)
    }

    /// Step 4's x: the peak through the range law (eqs. 2–3).
    fn range(&self, p: &steps::Prepared) -> Option<f64> {
        steps::range_from_peak(p.peak.value, self.k.x.a1, self.k.x.b1)
    }
}

fn inside(v: f64, r: [f64; 2]) -> bool {
    v >= r[0] && v <= r[1]
}

impl Estimator for MomentsEstimator {
    fn name(&self) -> &'static str {
        NAME
    }

    fn reset(&mut self) {
        self.track = Track::new();
    }

    fn estimate(&mut self, frame: &Frame) -> PoseEstimate {
        let k = &self.k;
        let empty = |st| PoseEstimate::empty(frame.seq, frame.t, st, NAME);
        if !frame.t.is_finite() {
            return empty(Status::BadFrame);
        }
        // Time going backwards or a long gap: what was carried no longer
        // describes this frame's vehicle.
        if frame.t <= self.track.last_t || frame.t - self.track.last_t > k.max_gap_s {
            self.track = Track::new();
        }

        // Steps 1–3: volts, offset, temperature, peak, moments.
        let p = match self.prepared(frame) {
            Ok(p) => p,
            Err(st) => return empty(st),
        };

        // Step 4: x, pitch, yaw, and y, z as measured in this image.
        let Some(x) = self.range(&p) else {
            return empty(Status::NoLight);
        };
        let m = p.moments;
        let mut est = empty(Status::Ok);
        est.x = Some(x);
        est.std.x = Some(k.x.sigma_m);
        let feat = |f: &LinearFit| steps::feature_value(f.feature, &m).map(|v| f.eval(v));
        let (Some(pitch_deg), Some(yaw_deg)) = (feat(&k.pitch), feat(&k.yaw)) else {
            // M22 vanished: the ratios, and everything after them, are unknown.
            est.status = Status::BadFrame;
            return est;
        };
        est.pitch_deg = Some(pitch_deg);
        est.yaw_deg = Some(yaw_deg);
        est.std.pitch = Some(k.pitch.sigma);
        est.std.yaw = Some(k.yaw.sigma);
        let (pitch, yaw) = (pitch_deg.to_radians(), yaw_deg.to_radians());

        // Steps 5: y, z from the first moments once, then carried forward
        // along the bow by each change of x (eqs. 8–13).
        let tr = &mut self.track;
        let yz = match tr.yz {
            None => match (feat(&k.y), feat(&k.z)) {
                (Some(y), Some(z)) => Some((y, z)),
                _ => None,
            },
            Some((y, z)) => match steps::travel_along_bow(x - tr.last_x, pitch, yaw) {
                Some(s) => {
                    let (dy, dz) = steps::carry_forward(s, pitch, yaw);
                    Some((y + dy, z + dz))
                }
                // Bow across the axis: hold y, z rather than divide by ~0.
                None => Some((y, z)),
            },
        };
        tr.yz = yz;
        tr.last_x = x;
        tr.last_t = frame.t;
        if let Some((y, z)) = yz {
            est.y = Some(y);
            est.z = Some(z);
        }

        // Step 6: surge = travel rate along the bow = −(dx/dt)/(cθ cψ).
        tr.ring.push(k.window, frame.t, x);
        let cos_k = pitch.cos() * yaw.cos();
        if tr.ring.len >= k.window && cos_k.abs() >= steps::MIN_COS_PRODUCT {
            if let Some((slope, sd)) = tr.ring.slope(k.x.sigma_m) {
                est.surge = Some(-slope / cos_k);
                est.std.surge = Some(sd / cos_k.abs());
            }
        }

        est.status = if !inside(x, k.x_ok)
            || !inside(pitch_deg, k.pitch_ok)
            || !inside(yaw_deg, k.yaw_ok)
            || est.y.is_some_and(|y| !inside(y, k.y_ok))
            || est.z.is_some_and(|z| !inside(z, k.z_ok))
        {
            Status::OutOfRange
        } else if est.surge.is_none() || est.y.is_none() {
            Status::Initialising
        } else {
            Status::Ok
        };
        est
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::file::tests::sample;
    use lightpose_core::{frame::volts_to_counts, Angle, ArrayGeometry, LightParams, Pose};

    /// A noise-free frame of the default light model at `pose`.
    fn frame(seq: u64, pose: &Pose, bits: u8) -> Frame {
        let mut e = [0.0; NDET];
        LightParams::default().irradiance(&ArrayGeometry::paper(), pose, &mut e);
        let mut counts = [0u16; NDET];
        for (c, v) in counts.iter_mut().zip(e) {
            *c = volts_to_counts(v + 0.15, 5.0, bits);
        }
        Frame {
            seq,
            t: seq as f64 * 0.2,
            adc_bits: bits,
            counts,
            temp_c: Some(20.0),
            truth: None,
            attitude: None,
            depth: None,
            velocity: None,
            amplitudes: None,
        }
    }

    fn on_axis(x: f64) -> Pose {
        Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO)
    }

    #[test]
    fn dark_and_saturated_frames_give_a_status_not_nan() {
        let mut e = MomentsEstimator::new(&sample());
        let mut f = frame(0, &on_axis(6.0), 10);
        f.counts = [31; NDET];
        assert_eq!(e.estimate(&f).status, Status::NoLight);
        f.counts = [0; NDET];
        let est = e.estimate(&f);
        assert_eq!(est.status, Status::NoLight);
        assert!(est.x.is_none());
        let f = frame(2, &on_axis(2.0), 10);
        assert_eq!(e.estimate(&f).status, Status::Saturated);
        let mut f = frame(3, &on_axis(6.0), 10);
        f.temp_c = Some(1e6);
        assert_eq!(e.estimate(&f).status, Status::BadFrame);
        f.temp_c = None; // falls back to the default temperature
        assert_ne!(e.estimate(&f).status, Status::BadFrame);
    }

    #[test]
    fn range_of_is_estimate_s_x() {
        let cal = sample();
        let (mut e, probe) = (MomentsEstimator::new(&cal), MomentsEstimator::new(&cal));
        for (i, x) in [8.0, 6.5, 5.0, 2.0].into_iter().enumerate() {
            let f = frame(i as u64, &on_axis(x), 10);
            assert_eq!(probe.range_of(&f), e.estimate(&f).x, "at {x} m");
        }
        // No light, or no time: no range, as `estimate` says.
        let mut dark = frame(9, &on_axis(6.0), 10);
        dark.counts = [0; NDET];
        assert_eq!(probe.range_of(&dark), None);
        let mut timeless = frame(9, &on_axis(6.0), 10);
        assert!(probe.range_of(&timeless).is_some());
        timeless.t = f64::NAN;
        assert_eq!(probe.range_of(&timeless), None);
    }

    #[test]
    fn first_frames_initialise_then_surge_appears() {
        let cal = sample();
        let mut e = MomentsEstimator::new(&cal);
        for i in 0..cal.limits.surge_window as u64 {
            // Approaching at 0.5 m/s.
            let est = e.estimate(&frame(i, &on_axis(8.0 - 0.1 * i as f64), 12));
            assert!(est.x.is_some() && est.y.is_some() && est.pitch_deg.is_some());
            if i + 1 < cal.limits.surge_window as u64 {
                assert_eq!(est.status, Status::Initialising, "frame {i}");
                assert!(est.surge.is_none());
            } else {
                // sample() is not a fit of this light model, so only the
                // sign of surge is asserted here: approaching is positive.
                assert!(est.surge.is_some_and(|s| s > 0.0), "{est:?}");
            }
        }
        e.reset();
        let est = e.estimate(&frame(0, &on_axis(8.0), 12));
        assert_eq!(est.status, Status::Initialising);
    }

    #[test]
    fn a_long_gap_restarts_the_track() {
        let mut e = MomentsEstimator::new(&sample());
        for i in 0..12 {
            e.estimate(&frame(i, &on_axis(8.0 - 0.1 * i as f64), 10));
        }
        let mut f = frame(12, &on_axis(6.8), 10);
        f.t += 10.0;
        let est = e.estimate(&f);
        assert!(est.surge.is_none());
        assert_eq!(est.status, Status::Initialising);
    }

    #[test]
    fn surge_slope_of_a_line() {
        let mut r = Ring::new();
        for i in 0..20 {
            r.push(10, i as f64 * 0.2, 8.0 - 0.1 * i as f64);
        }
        let (s, sd) = r.slope(0.1).unwrap();
        assert!((s + 0.5).abs() < 1e-12 && sd > 0.0);
    }
}
