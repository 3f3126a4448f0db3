//! The paper's published Monte Carlo figures (Eren et al. 2017, section 3.1,
//! as transcribed in shared/reference/PAPER-RESULTS.md), so that a summary
//! can put ours beside theirs for the same case. These are reference data
//! quoted from the paper, not results of this code.

use crate::montecarlo::McError;
use std::fmt;
use std::path::Path;

/// One of the paper's three Monte Carlo cases.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaperCase {
    /// Case I: diving motion in the tank (K_D = 0.09).
    DiveClear,
    /// Case II: 3-D zigzag in the tank (K_D = 0.09).
    ZigzagClear,
    /// Case II in Portsmouth Harbor water (K_D = 0.2).
    ZigzagTurbid,
}

/// A published number; `below` for the paper's "< ±1°".
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figure {
    pub value: f64,
    pub below: bool,
}

const fn v(value: f64) -> Option<Figure> {
    Some(Figure {
        value,
        below: false,
    })
}
const fn lt(value: f64) -> Option<Figure> {
    Some(Figure { value, below: true })
}

impl fmt::Display for Figure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.below {
            write!(f, "<{}", self.value)
        } else {
            write!(f, "{}", self.value)
        }
    }
}

/// The paper's figures of one case, per axis x, y, z, pitch, yaw (degrees
/// for the angles); the paper gives none for surge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperFigures {
    pub final_error: [Option<Figure>; 5],
    pub ci_start: [Option<Figure>; 5],
    pub ci_end: [Option<Figure>; 5],
}

impl PaperCase {
    pub const ALL: [PaperCase; 3] = [
        PaperCase::DiveClear,
        PaperCase::ZigzagClear,
        PaperCase::ZigzagTurbid,
    ];

    /// The `--case` word of `lightpose montecarlo`, named for the water.
    pub const fn as_str(self) -> &'static str {
        match self {
            PaperCase::DiveClear => "dive-clear",
            PaperCase::ZigzagClear => "zigzag-clear",
            PaperCase::ZigzagTurbid => "zigzag-turbid",
        }
    }

    /// The `--case` word of `lightpose bench`, named for the scene file
    /// (`trade::CASES`). This and [`PaperCase::as_str`] are the one
    /// mapping between the two spellings: each command takes both.
    pub const fn scene_name(self) -> &'static str {
        match self {
            PaperCase::DiveClear => "dive-tank",
            PaperCase::ZigzagClear => "zigzag-tank",
            PaperCase::ZigzagTurbid => "zigzag-harbour",
        }
    }

    /// The case either spelling names (`dive-clear` or `dive-tank`, …).
    pub fn named(s: &str) -> Option<PaperCase> {
        PaperCase::ALL
            .into_iter()
            .find(|c| c.as_str() == s || c.scene_name() == s)
    }

    /// Title as the paper names it.
    pub fn title(self) -> &'static str {
        match self {
            PaperCase::DiveClear => "Case I: dive, clear water (K_D = 0.09 1/m), paper Figure 6",
            PaperCase::ZigzagClear => {
                "Case II: zigzag, clear water (K_D = 0.09 1/m), paper Figure 7"
            }
            PaperCase::ZigzagTurbid => {
                "Case II: zigzag, turbid water (K_D = 0.2 1/m), paper Figure 8"
            }
        }
    }

    /// `--case`: "auto" → `Ok(None)` is not decided here (the caller
    /// detects); "none" → no comparison; else one of [`PaperCase::ALL`]
    /// in either spelling ([`PaperCase::named`]).
    pub fn parse(s: &str) -> Result<Option<PaperCase>, McError> {
        if s == "none" {
            return Ok(None);
        }
        PaperCase::named(s)
            .map(Some)
            .ok_or_else(|| McError::UnknownCase(s.to_string()))
    }

    /// The paper's case that a run is, from the trajectory's file name
    /// (`dive*` or `zigzag*`) and the scene's K_D (0.09 or 0.2, within
    /// 0.005); `None` for anything else.
    pub fn detect(trajectory: &Path, k_d: f64) -> Option<PaperCase> {
        let stem = trajectory.file_stem()?.to_str()?.to_ascii_lowercase();
        let clear = (k_d - 0.09).abs() < 0.005;
        let turbid = (k_d - 0.2).abs() < 0.005;
        if stem.starts_with("dive") && clear {
            Some(PaperCase::DiveClear)
        } else if stem.starts_with("zigzag") && clear {
            Some(PaperCase::ZigzagClear)
        } else if stem.starts_with("zigzag") && turbid {
            Some(PaperCase::ZigzagTurbid)
        } else {
            None
        }
    }

    /// Section 3.1.1–3.1.3 of the paper (PAPER-RESULTS.md).
    pub fn figures(self) -> PaperFigures {
        match self {
            PaperCase::DiveClear => PaperFigures {
                final_error: [v(0.02), v(0.02), v(0.18), v(5.0), v(1.0)],
                ci_start: [v(0.83), v(0.18), v(0.22), v(2.0), v(2.0)],
                ci_end: [v(0.43), v(0.2), v(0.28), lt(1.0), lt(1.0)],
            },
            PaperCase::ZigzagClear => PaperFigures {
                final_error: [v(0.13), v(0.13), v(0.05), v(3.0), v(4.0)],
                ci_start: [v(0.83), v(0.18), v(0.2), v(2.0), v(3.0)],
                ci_end: [v(0.46), v(0.3), v(0.28), lt(1.0), lt(1.0)],
            },
            PaperCase::ZigzagTurbid => PaperFigures {
                final_error: [v(0.26), v(0.17), v(0.01), v(3.0), v(4.0)],
                ci_start: [None; 5],
                ci_end: [v(0.36), v(0.8), v(0.86), v(8.0), v(9.0)],
            },
        }
    }
}

/// How far ours is from a published figure, as a factor ≥ 1 (for "< a"
/// figures only an excess counts); `None` when either is zero or absent.
pub fn factor(ours: f64, paper: Option<Figure>) -> Option<f64> {
    let p = paper?;
    if !(ours.is_finite() && ours > 0.0 && p.value > 0.0) {
        return None;
    }
    if p.below && ours <= p.value {
        return Some(1.0);
    }
    Some((ours / p.value).max(p.value / ours))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_the_three_cases_and_nothing_else() {
        let d = |f: &str, k| PaperCase::detect(Path::new(f), k);
        assert_eq!(
            d("config/trajectories/dive.csv", 0.09),
            Some(PaperCase::DiveClear)
        );
        assert_eq!(d("zigzag.csv", 0.09), Some(PaperCase::ZigzagClear));
        assert_eq!(d("zigzag.csv", 0.2), Some(PaperCase::ZigzagTurbid));
        assert_eq!(d("dive.csv", 0.2), None);
        assert_eq!(d("spiral.csv", 0.09), None);
        assert_eq!(PaperCase::parse("none").unwrap(), None);
        assert_eq!(
            PaperCase::parse("zigzag-turbid").unwrap(),
            Some(PaperCase::ZigzagTurbid)
        );
        assert!(PaperCase::parse("zigzag").is_err());
    }

    #[test]
    fn each_case_is_named_in_both_spellings() {
        for c in PaperCase::ALL {
            assert_eq!(PaperCase::named(c.as_str()), Some(c));
            assert_eq!(PaperCase::named(c.scene_name()), Some(c));
            assert_eq!(PaperCase::parse(c.scene_name()).unwrap(), Some(c));
        }
        assert_eq!(
            PaperCase::parse("dive-tank").unwrap(),
            Some(PaperCase::DiveClear)
        );
        assert_eq!(
            PaperCase::named("zigzag-harbour"),
            Some(PaperCase::ZigzagTurbid)
        );
        assert_eq!(PaperCase::named("harbour"), None);
    }

    #[test]
    fn factor_is_symmetric_and_respects_upper_bounds() {
        assert_eq!(factor(0.4, v(0.2)), Some(2.0));
        assert_eq!(factor(0.1, v(0.2)), Some(2.0));
        assert_eq!(factor(0.5, lt(1.0)), Some(1.0));
        assert_eq!(factor(3.0, lt(1.0)), Some(3.0));
        assert_eq!(factor(0.0, v(1.0)), None);
    }
}
