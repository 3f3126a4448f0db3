//! The light equation of MODEL.md: what irradiance (in volts of an ideal
//! channel) reaches each detector for a given pose and water. The simulator
//! adds gains, offsets, noise and the ADC; model-based estimators invert it.

use crate::{Angle, ArrayGeometry, Pose, NDET};

/// Forward-scattered halo (MODEL.md): f = 1 − exp(−ω·K_D·d), widened
/// response σ_T² = σ_R² + σ_h².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scattering {
    pub omega: f64,
    pub sigma_h: Angle,
}

impl Default for Scattering {
    fn default() -> Self {
        Scattering {
            omega: 0.5,
            sigma_h: Angle::from_deg(20.0),
        }
    }
}

/// Parameters of the beacon, the water and the detectors' angular response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightParams {
    /// Source strength, V·m².
    pub v1: f64,
    /// Gaussian beam width (1σ off the beam axis).
    pub sigma_b: Angle,
    /// Detector angular response width (1σ).
    pub sigma_r: Angle,
    /// Diffuse attenuation coefficient, 1/m.
    pub k_d: f64,
    /// `None`: no scattering term is computed at all.
    pub scattering: Option<Scattering>,
}

impl Default for LightParams {
    /// The paper's tank with scattering on (MODEL.md defaults).
    fn default() -> Self {
        LightParams {
            v1: 135.0,
            sigma_b: Angle::from_deg(12.0),
            sigma_r: Angle::from_deg(18.0),
            k_d: 0.09,
            scattering: Some(Scattering::default()),
        }
    }
}

/// Where detector k sits relative to the beacon: its distance d, its angle α
/// off the beam axis and the angle β between its normal and the beacon.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DetectorView {
    pub d: f64,
    pub alpha: f64,
    pub beta: f64,
}

/// Compute d, α, β for every detector at `pose`.
#[inline]
pub fn views(geom: &ArrayGeometry, pose: &Pose, out: &mut [DetectorView; NDET]) {
    let att = pose.attitude();
    let p = pose.position();
    for (k, v) in out.iter_mut().enumerate() {
        let n_b = att.to_beam(&geom.normal(k));
        let pk = p.add(&crate::BeamVec([
            geom.radius_m * n_b.0[0],
            geom.radius_m * n_b.0[1],
            geom.radius_m * n_b.0[2],
        ]));
        let d = pk.norm();
        // Angles through atan2 keep full precision near 0 and 180°.
        let lat = (pk.0[1] * pk.0[1] + pk.0[2] * pk.0[2]).sqrt();
        let alpha = lat.atan2(pk.0[0]);
        let cos_b = -n_b.dot(&pk) / d;
        let cross = [
            n_b.0[1] * pk.0[2] - n_b.0[2] * pk.0[1],
            n_b.0[2] * pk.0[0] - n_b.0[0] * pk.0[2],
            n_b.0[0] * pk.0[1] - n_b.0[1] * pk.0[0],
        ];
        let sin_b = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt() / d;
        let beta = sin_b.atan2(cos_b);
        *v = DetectorView { d, alpha, beta };
    }
}

/// G(β; σ) = exp(−β²/2σ²) for β < 90°, else 0.
#[inline]
pub fn response(beta: f64, sigma: f64) -> f64 {
    if beta < std::f64::consts::FRAC_PI_2 {
        (-beta * beta / (2.0 * sigma * sigma)).exp()
    } else {
        0.0
    }
}

impl LightParams {
    /// Irradiance E_k at one detector from its view.
    #[inline]
    pub fn irradiance_at(&self, v: &DetectorView) -> f64 {
        // d = 0 or NaN (the beacon inside the dome): no meaningful light.
        if v.d.is_nan() || v.d <= 0.0 {
            return 0.0;
        }
        let sb = self.sigma_b.rad();
        let sr = self.sigma_r.rad();
        let beam = (-v.alpha * v.alpha / (2.0 * sb * sb)).exp();
        let path = (-self.k_d * v.d).exp() / (v.d * v.d);
        let direct = response(v.beta, sr);
        let bracket = match self.scattering {
            None => direct,
            Some(s) => {
                let f = 1.0 - (-s.omega * self.k_d * v.d).exp();
                let sh = s.sigma_h.rad();
                let st2 = sr * sr + sh * sh;
                (1.0 - f) * direct + f * (sr * sr / st2) * response(v.beta, st2.sqrt())
            }
        };
        self.v1 * beam * path * bracket
    }

    /// Irradiance at every detector for `pose`, row-major.
    pub fn irradiance(&self, geom: &ArrayGeometry, pose: &Pose, out: &mut [f64; NDET]) {
        let mut v = [DetectorView::default(); NDET];
        views(geom, pose, &mut v);
        for (e, view) in out.iter_mut().zip(v.iter()) {
            *e = self.irradiance_at(view);
        }
    }
}

/// Reported temperatures (°C) that are taken as water's; outside it a
/// frame is `bad_frame` for every estimator, and a temperature sensor that
/// reads it gives its fallback instead. Issue 8: the window used to end at
/// −5 °C, the end of the operating envelope itself, so in −5 °C water the
/// temperature sensor's own noise (0.1 °C) made half the frames
/// `bad_frame`; the lower end now leaves room for that noise.
pub const WATER_TEMP_C: std::ops::RangeInclusive<f64> = -10.0..=60.0;

/// Reference temperature of the responsivity model, °C.
pub const T_REF_C: f64 = 20.0;

/// g_T(T) = (576 − 2T)/(576 − 2·T_ref): the paper's eq. 14 as a relative
/// change of responsivity.
#[inline]
pub fn temperature_gain(t_c: f64) -> f64 {
    (576.0 - 2.0 * t_c) / (576.0 - 2.0 * T_REF_C)
}

/// |dg_T/dT| / g_T at `t_c`, 1/°C: how much a temperature read wrong by
/// 1 °C scales every channel (0.37 %/°C at 20 °C). The Cramér–Rao bounds'
/// and the tracker's gain doubt from a temperature doubt.
#[inline]
pub fn temperature_gain_slope(t_c: f64) -> f64 {
    2.0 / (576.0 - 2.0 * t_c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::array::index;

    fn on_axis(x: f64) -> Pose {
        Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO)
    }

    #[test]
    fn model_md_reference_counts() {
        // MODEL.md: 962 counts at 4.5 m and 190 at 8.5 m, centre detector,
        // scattering on, 0.15 V offset, 10 bits over 5 V.
        let p = LightParams::default();
        let g = ArrayGeometry::paper();
        for (x, want) in [(4.5, 962.0), (8.5, 190.0)] {
            let mut e = [0.0; NDET];
            p.irradiance(&g, &on_axis(x), &mut e);
            let counts = ((e[index(2, 2)] + 0.15) / 5.0 * 1023.0).round();
            assert_eq!(counts, want, "x = {x}");
        }
    }

    #[test]
    fn inverse_square_and_beer_on_axis() {
        let p = LightParams {
            scattering: None,
            ..LightParams::default()
        };
        let g = ArrayGeometry::paper();
        for x in [1.0, 3.0, 7.5, 20.0] {
            let mut e = [0.0; NDET];
            p.irradiance(&g, &on_axis(x), &mut e);
            let d = x - 0.229;
            let want = 135.0 * (-0.09 * d).exp() / (d * d);
            assert!((e[index(2, 2)] / want - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn temperature_factor() {
        assert_eq!(temperature_gain(20.0), 1.0);
        assert!((temperature_gain(30.0) - 516.0 / 536.0).abs() < 1e-15);
    }

    #[test]
    fn response_cuts_off_behind() {
        assert_eq!(response(std::f64::consts::FRAC_PI_2 + 1e-9, 0.3), 0.0);
        assert!((response(0.3, 0.3) - (-0.5f64).exp()).abs() < 1e-15);
    }
}
