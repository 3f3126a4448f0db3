//! Choosing an estimator by name, so that replay, the daemon and the Monte
//! Carlo accept the same `--estimator` words and get the same object.

use crate::calibration::Calibration;
use crate::moments::MomentsEstimator;
use lightpose_core::Estimator;

/// Names `build_estimator` accepts.
pub const NAMES: &[&str] = &["auto", "moments"];

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BuildError {
    #[error("unknown estimator \"{name}\" (known: {known})")]
    Unknown { name: String, known: String },
}

/// The estimator called `name` for calibration `cal`. "auto" is the best
/// one this calibration supports (today the paper's moments estimator).
pub fn build_estimator(name: &str, cal: &Calibration) -> Result<Box<dyn Estimator>, BuildError> {
    match name {
        "auto" | "moments" => Ok(Box::new(MomentsEstimator::new(cal))),
        _ => Err(BuildError::Unknown {
            name: name.to_string(),
            known: NAMES.join(", "),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::tests::sample;

    #[test]
    fn names() {
        let cal = sample();
        assert_eq!(build_estimator("auto", &cal).unwrap().name(), "moments");
        assert_eq!(build_estimator("moments", &cal).unwrap().name(), "moments");
        let e = build_estimator("kalman", &cal).err().unwrap().to_string();
        assert_eq!(e, "unknown estimator \"kalman\" (known: auto, moments)");
    }
}
