//! The frequency rules of MODEL.md ("Beacons are told apart by their
//! frequencies"), in one place: the scene validator refuses a scene that
//! breaks them and the demodulator relies on them, so both call
//! [`check_beacons`].
//!
//! Each blinking beacon's `mod_hz` must give an even whole number of
//! samples per period (sample_hz / mod_hz = 2m) and a whole number of
//! periods per frame (mod_hz / rate_hz), "whole" within 1e-9 relative; then
//! a beacon's samples over one frame hold a constant and its odd harmonics
//! alone. With several beacons none may be steady, and no two may share a
//! frequency or stand in the ratio of two odd numbers (they would share a
//! harmonic).

/// "Whole" within this relative tolerance (MODEL.md).
pub const WHOLE_REL: f64 = 1e-9;

/// A beacon as the rules see it: its name and its frequency (0 = steady).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeaconFreq<'a> {
    pub id: &'a str,
    pub mod_hz: f64,
}

/// Why a set of beacons cannot be told apart (or sampled), naming them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModulationError {
    #[error("sample_hz = {sample_hz} is not a whole multiple of rate_hz = {rate_hz}")]
    SamplesPerFrame { sample_hz: f64, rate_hz: f64 },
    #[error("sample_hz = {sample_hz} > rate_hz = {rate_hz} but no beacon blinks (mod_hz > 0): sample faster only with a modulated beacon")]
    FastWithoutBlink { sample_hz: f64, rate_hz: f64 },
    #[error("beacon \"{id}\": mod_hz = {mod_hz} gives {per_period} samples per period at sample_hz = {sample_hz}, not an even whole number (choose sample_hz / 2m)")]
    SamplesPerPeriod {
        id: String,
        mod_hz: f64,
        sample_hz: f64,
        per_period: f64,
    },
    #[error("beacon \"{id}\": mod_hz = {mod_hz} gives {per_frame} periods per frame at rate_hz = {rate_hz}, not a whole number")]
    PeriodsPerFrame {
        id: String,
        mod_hz: f64,
        rate_hz: f64,
        per_frame: f64,
    },
    #[error("beacon \"{id}\" is steady (mod_hz = 0) among several beacons: each must blink at its own frequency")]
    Steady { id: String },
    #[error("beacons \"{a}\" and \"{b}\" both blink at {mod_hz} Hz")]
    SameFrequency { a: String, b: String, mod_hz: f64 },
    #[error("beacons \"{a}\" ({fa} Hz) and \"{b}\" ({fb} Hz) stand in the ratio {p} : {q} of two odd numbers: they share odd harmonics")]
    OddRatio {
        a: String,
        b: String,
        fa: f64,
        fb: f64,
        p: u64,
        q: u64,
    },
}

impl ModulationError {
    /// The first beacon the error names (`None`: it is the ADC's rate), so
    /// that a reader points at that beacon's line (a scene's, a station
    /// file's).
    pub fn beacon(&self) -> Option<&str> {
        match self {
            ModulationError::SamplesPerFrame { .. } | ModulationError::FastWithoutBlink { .. } => {
                None
            }
            ModulationError::SamplesPerPeriod { id, .. }
            | ModulationError::PeriodsPerFrame { id, .. }
            | ModulationError::Steady { id } => Some(id),
            ModulationError::SameFrequency { a, .. } | ModulationError::OddRatio { a, .. } => {
                Some(a)
            }
        }
    }
}

/// `x` as a whole number if it is one within [`WHOLE_REL`].
pub fn whole(x: f64) -> Option<u64> {
    if !x.is_finite() || !(0.5..=1e15).contains(&x) {
        return None;
    }
    let r = x.round();
    ((x - r).abs() <= WHOLE_REL * r).then_some(r as u64)
}

/// Samples of each channel per frame, N = sample_hz / rate_hz, if whole.
pub fn samples_per_frame(sample_hz: f64, rate_hz: f64) -> Result<u64, ModulationError> {
    whole(sample_hz / rate_hz).ok_or(ModulationError::SamplesPerFrame { sample_hz, rate_hz })
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Check MODEL.md's rules for `beacons` sampled at `sample_hz` in frames of
/// `rate_hz`; returns N, the samples per channel per frame. One steady
/// beacon at N = 1 is spec v1/v2 and passes.
pub fn check_beacons(
    rate_hz: f64,
    sample_hz: f64,
    beacons: &[BeaconFreq<'_>],
) -> Result<u64, ModulationError> {
    let n = samples_per_frame(sample_hz, rate_hz)?;
    let blinking = beacons.iter().any(|b| b.mod_hz > 0.0);
    if n > 1 && !blinking {
        return Err(ModulationError::FastWithoutBlink { sample_hz, rate_hz });
    }
    // m of each blinking beacon: sample_hz / mod_hz = 2m.
    let mut halves = Vec::with_capacity(beacons.len());
    for b in beacons {
        if b.mod_hz <= 0.0 {
            if beacons.len() > 1 {
                return Err(ModulationError::Steady { id: b.id.into() });
            }
            halves.push(0);
            continue;
        }
        let per_period = sample_hz / b.mod_hz;
        let m = match whole(per_period) {
            Some(s) if s % 2 == 0 => s / 2,
            _ => {
                return Err(ModulationError::SamplesPerPeriod {
                    id: b.id.into(),
                    mod_hz: b.mod_hz,
                    sample_hz,
                    per_period,
                })
            }
        };
        let per_frame = b.mod_hz / rate_hz;
        if whole(per_frame).is_none() {
            return Err(ModulationError::PeriodsPerFrame {
                id: b.id.into(),
                mod_hz: b.mod_hz,
                rate_hz,
                per_frame,
            });
        }
        halves.push(m);
    }
    for i in 0..beacons.len() {
        for j in i + 1..beacons.len() {
            let (a, b) = (&beacons[i], &beacons[j]);
            let (ma, mb) = (halves[i], halves[j]);
            if ma == mb {
                return Err(ModulationError::SameFrequency {
                    a: a.id.into(),
                    b: b.id.into(),
                    mod_hz: a.mod_hz,
                });
            }
            // f_a : f_b = m_b : m_a; in lowest terms both odd shares harmonics.
            let g = gcd(ma, mb);
            let (p, q) = (mb / g, ma / g);
            if p % 2 == 1 && q % 2 == 1 {
                return Err(ModulationError::OddRatio {
                    a: a.id.into(),
                    b: b.id.into(),
                    fa: a.mod_hz,
                    fb: b.mod_hz,
                    p,
                    q,
                });
            }
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(id: &str, mod_hz: f64) -> BeaconFreq<'_> {
        BeaconFreq { id, mod_hz }
    }

    #[test]
    fn the_dock_example_passes_and_v2_passes() {
        let dock = [
            b("top", 200.0),
            b("starboard", 250.0),
            b("bottom", 400.0),
            b("port", 500.0),
        ];
        assert_eq!(check_beacons(10.0, 4000.0, &dock), Ok(400));
        assert_eq!(check_beacons(5.0, 5.0, &[b("beacon", 0.0)]), Ok(1));
        // A third of a hertz, as a float: whole within 1e-9.
        assert!(check_beacons(10.0 / 3.0, 4000.0, &[b("a", 4000.0 / 12.0)]).is_ok());
    }

    /// MODEL.md's examples: 200 : 600 = 1 : 3 and 200 : 333⅓ = 3 : 5 are
    /// refused, 200 : 250 = 4 : 5 is not.
    #[test]
    fn the_rules_name_the_beacons() {
        let e = check_beacons(10.0, 4800.0, &[b("a", 200.0), b("b", 600.0)]).unwrap_err();
        assert!(
            matches!(e, ModulationError::OddRatio { p: 1, q: 3, .. }),
            "{e}"
        );
        assert!(
            e.to_string().contains("\"a\"") && e.to_string().contains("\"b\""),
            "{e}"
        );
        let e = check_beacons(10.0, 4000.0, &[b("a", 200.0), b("c", 4000.0 / 12.0)]);
        assert!(
            matches!(e, Err(ModulationError::PeriodsPerFrame { .. })),
            "{e:?}"
        );
        let e = check_beacons(3.0, 4000.0, &[b("a", 200.0)]);
        assert!(
            matches!(e, Err(ModulationError::SamplesPerFrame { .. })),
            "{e:?}"
        );
        let e = check_beacons(10.0 / 3.0, 4000.0, &[b("a", 200.0), b("c", 4000.0 / 12.0)]);
        assert!(
            matches!(e, Err(ModulationError::OddRatio { p: 3, q: 5, .. })),
            "{e:?}"
        );
        assert!(check_beacons(10.0, 4000.0, &[b("a", 200.0), b("b", 250.0)]).is_ok());
        let e = check_beacons(10.0, 4000.0, &[b("a", 200.0), b("b", 200.0)]).unwrap_err();
        assert!(matches!(e, ModulationError::SameFrequency { .. }), "{e}");
        let e = check_beacons(10.0, 4000.0, &[b("a", 200.0), b("s", 0.0)]).unwrap_err();
        assert_eq!(e, ModulationError::Steady { id: "s".into() });
        let e = check_beacons(10.0, 4000.0, &[b("a", 0.0)]).unwrap_err();
        assert!(matches!(e, ModulationError::FastWithoutBlink { .. }), "{e}");
        // 4000 / 300 = 13.3 samples per period; 4000 / 4000 * 2 = odd (1).
        let e = check_beacons(10.0, 4000.0, &[b("x", 300.0)]).unwrap_err();
        assert!(matches!(e, ModulationError::SamplesPerPeriod { .. }), "{e}");
        let e = check_beacons(10.0, 4000.0, &[b("x", 4000.0)]).unwrap_err();
        assert!(matches!(e, ModulationError::SamplesPerPeriod { .. }), "{e}");
        // 15 Hz at 10 Hz frames: 1.5 periods per frame.
        let e = check_beacons(10.0, 4800.0, &[b("x", 15.0)]).unwrap_err();
        assert!(matches!(e, ModulationError::PeriodsPerFrame { .. }), "{e}");
    }

    /// MODEL.md: at most as many beacons as the times 2 divides N — four
    /// at N = 400 (4 kHz at 10 Hz).
    #[test]
    fn four_beacons_at_n_400_and_no_fifth() {
        let four = [b("a", 2000.0), b("b", 1000.0), b("c", 500.0), b("d", 250.0)];
        assert!(check_beacons(10.0, 4000.0, &four).is_ok());
        // Every other even divisor shares its 2-adic order with one of them.
        for m in 1..=200u64 {
            let f = 4000.0 / (2 * m) as f64;
            if four.iter().any(|x| x.mod_hz == f) || whole(f / 10.0).is_none() {
                continue;
            }
            let mut five = four.to_vec();
            five.push(b("e", f));
            assert!(check_beacons(10.0, 4000.0, &five).is_err(), "{f} Hz");
        }
    }
}
