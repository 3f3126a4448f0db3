//! Uncertainty analysis of the pose estimators: the paper's Monte Carlo
//! total propagated uncertainty (section 3.1), its tables and its plots.
//!
//! It is a library rather than part of the CLI so that `lightpose
//! montecarlo`, a later trade table over every estimator and the tests all
//! run the same engine:
//!
//! - [`montecarlo`]: the ensemble engine (parallel, deterministic for a seed);
//! - [`stats`]: per-step ensemble statistics and coverage;
//! - [`paper`]: the paper's published figures and which case a run is;
//! - [`report`]: the per-step CSV and `summary.md`;
//! - [`plot`]: Figures 6–8 style plots, PNG and SVG, with a bundled font;
//! - [`bound`]: a scene's Cramér–Rao bound along a trajectory.

pub mod bound;
pub mod montecarlo;
pub mod paper;
pub mod plot;
pub mod report;
pub mod stats;

pub use montecarlo::{run, Axis, Draw, McConfig, McError, McResult, AXES, NAXES};
pub use paper::PaperCase;
