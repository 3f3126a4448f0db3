//! What the paper's linear fits read: a moment of the 3 × 3 moment matrix
//! about an origin (`m12/m22@peak`), as the calibration file names it.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Where a moment is taken about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Origin {
    /// The brightest pixel, refined to sub-pixel accuracy (the paper's eq. 1).
    Peak,
    /// The centre detector (2, 2) of the array.
    Centre,
}

/// A scalar taken from the 3 × 3 moment matrix. Indices are 0-based
/// `M_pq`, p the power of the column offset (across the array, as y and yaw
/// move the spot), q that of the row offset (as z and pitch move it). The
/// paper's 1-based M21, M12, M23, M32, M33 are M10, M01, M12, M21, M22 here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Moment {
    M10,
    M01,
    /// M12 / M22 (the paper's M23/M33).
    M12OverM22,
    /// M21 / M22 (the paper's M32/M33).
    M21OverM22,
}

/// A moment about an origin: what a linear fit maps to a pose quantity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Feature {
    pub moment: Moment,
    pub origin: Origin,
}

impl Feature {
    pub const fn new(moment: Moment, origin: Origin) -> Self {
        Feature { moment, origin }
    }

    /// Candidates for pitch and yaw (the paper's moment ratios).
    pub const RATIOS: [Feature; 4] = [
        Feature::new(Moment::M12OverM22, Origin::Peak),
        Feature::new(Moment::M21OverM22, Origin::Peak),
        Feature::new(Moment::M12OverM22, Origin::Centre),
        Feature::new(Moment::M21OverM22, Origin::Centre),
    ];
    /// Candidates for y and z (the paper's first-order moments).
    pub const FIRST: [Feature; 4] = [
        Feature::new(Moment::M10, Origin::Peak),
        Feature::new(Moment::M01, Origin::Peak),
        Feature::new(Moment::M10, Origin::Centre),
        Feature::new(Moment::M01, Origin::Centre),
    ];
}

impl fmt::Display for Feature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let m = match self.moment {
            Moment::M10 => "m10",
            Moment::M01 => "m01",
            Moment::M12OverM22 => "m12/m22",
            Moment::M21OverM22 => "m21/m22",
        };
        let o = match self.origin {
            Origin::Peak => "peak",
            Origin::Centre => "centre",
        };
        write!(f, "{m}@{o}")
    }
}

impl TryFrom<String> for Feature {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        let (m, o) = s.split_once('@').ok_or_else(|| {
            format!("feature \"{s}\" must be MOMENT@ORIGIN, e.g. \"m12/m22@peak\"")
        })?;
        let moment = match m {
            "m10" => Moment::M10,
            "m01" => Moment::M01,
            "m12/m22" => Moment::M12OverM22,
            "m21/m22" => Moment::M21OverM22,
            _ => {
                return Err(format!(
                    "unknown moment \"{m}\" (m10, m01, m12/m22, m21/m22)"
                ))
            }
        };
        let origin = match o {
            "peak" => Origin::Peak,
            "centre" => Origin::Centre,
            _ => return Err(format!("unknown origin \"{o}\" (peak, centre)")),
        };
        Ok(Feature { moment, origin })
    }
}

impl From<Feature> for String {
    fn from(f: Feature) -> String {
        f.to_string()
    }
}
