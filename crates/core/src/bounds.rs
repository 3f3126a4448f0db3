//! The bounds a physical number read from a file must keep (finite
//! always, and within what physics or the ADC allows), shared by the scene
//! files the simulator reads and the calibrations the estimators run on: a
//! light model a scene could not hold is no calibration either. Generous on
//! purpose: they refuse nonsense (negative, NaN, inf, 1e300), they do not
//! judge realism.

use std::fmt;

/// Lowest ADC reference, V: no ADC resolves anything against less than a millivolt.
pub const MIN_V_REF: f64 = 1e-3;
/// Highest ADC reference, V: far above any ADC's (the board configurations' limit too).
pub const MAX_V_REF: f64 = 50.0;
/// Brightest beacon as a multiple of v_ref: saturating by six orders of
/// magnitude at 1 m is still a test scene, more is a typo.
pub const MAX_V1_PER_V_REF: f64 = 1e6;
/// Murkiest water, m⁻¹: the muddiest estuaries reach ~10; at 100 light dies within centimetres.
pub const MAX_K_D: f64 = 100.0;
/// The most a doubt of K_D may be, m⁻¹ (an estimator's setting, a Monte
/// Carlo's spread): a harbour's own K_D is about 1, so past 10 it is a
/// mistake, and a bank of waters at e^(±3σ/K_D) overflows.
pub const MAX_K_D_DOUBT: f64 = 10.0;
/// The most a doubt of the water temperature may be, °C (likewise).
pub const MAX_TEMP_DOUBT_C: f64 = 50.0;
/// Largest ω: ω·K_D is a scattering coefficient, at most tens of times K_D even in turbid water.
pub const MAX_OMEGA: f64 = 1e3;
/// Largest dome radius, m: bigger than any vehicle that could carry the dome.
pub const MAX_RADIUS_M: f64 = 10.0;
/// Largest channel gain: channels spread about 1, a thousandfold is another detector.
pub const MAX_GAIN: f64 = 1e3;
/// Widest spacing of the dome's channels, °: 2 × 22.5° from the centre
/// reaches the horizon, so the dome stays a hemisphere.
pub const MAX_SPACING_DEG: f64 = 22.5;

/// The interval a number must lie in, with its unit and why, for the message.
#[derive(Clone, Copy)]
pub struct Within {
    lo: f64,
    hi: f64,
    /// Whether the low and the high end are excluded.
    open: (bool, bool),
    unit: &'static str,
    why: &'static str,
}

impl Within {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64, unit: &'static str) -> Within {
        Within {
            lo,
            hi,
            open: (false, false),
            unit,
            why: "",
        }
    }
    /// `(lo, hi]`.
    pub const fn above(lo: f64, hi: f64, unit: &'static str) -> Within {
        Within {
            open: (true, false),
            ..Within::closed(lo, hi, unit)
        }
    }
    /// `(lo, hi)`.
    pub const fn open(lo: f64, hi: f64, unit: &'static str) -> Within {
        Within {
            open: (true, true),
            ..Within::closed(lo, hi, unit)
        }
    }
    pub const fn why(self, why: &'static str) -> Within {
        Within { why, ..self }
    }
    pub fn contains(&self, x: f64) -> bool {
        let lo = if self.open.0 {
            x > self.lo
        } else {
            x >= self.lo
        };
        let hi = if self.open.1 {
            x < self.hi
        } else {
            x <= self.hi
        };
        x.is_finite() && lo && hi
    }
}

impl fmt::Display for Within {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (l, r) = (
            if self.open.0 { '(' } else { '[' },
            if self.open.1 { ')' } else { ']' },
        );
        write!(f, "in {l}{}, {}{r}{}", self.lo, self.hi, self.unit)?;
        if !self.why.is_empty() {
            write!(f, " ({})", self.why)?;
        }
        Ok(())
    }
}

/// An angular width: a Gaussian 1σ that stays inside a hemisphere.
pub const WIDTH_DEG: Within = Within::open(0.0, 90.0, "°");

impl Within {
    /// `x` if it lies within, else why not (for a one-line error).
    pub fn check(&self, x: f64) -> Result<f64, String> {
        if self.contains(x) {
            Ok(x)
        } else {
            Err(format!("{} is impossible: must be {self}", shown(x)))
        }
    }
}

/// `x` as a message shows it: in exponent form when huge or tiny (1e300,
/// not three hundred digits).
pub fn shown(x: f64) -> String {
    if x != 0.0 && !(1e-6..1e9).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_open_or_closed_and_never_nan() {
        let w = Within::above(0.0, 1.0, " m");
        assert!(!w.contains(0.0) && w.contains(1.0) && w.contains(0.5));
        assert!(!w.contains(f64::NAN) && !w.contains(f64::INFINITY));
        assert!(Within::closed(0.0, 1.0, "").contains(0.0));
        assert!(!Within::open(0.0, 1.0, "").contains(1.0));
        assert_eq!(
            WIDTH_DEG.check(90.0).unwrap_err(),
            "90 is impossible: must be in (0, 90)°"
        );
        assert_eq!(shown(1e300), "1e300");
        assert_eq!(shown(-2.5e-9), "-2.5e-9");
        assert_eq!(shown(0.44), "0.44");
        assert_eq!(shown(f64::NAN), "NaN");
    }
}
