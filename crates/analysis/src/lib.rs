//! Uncertainty analysis of the pose estimators: the paper's Monte Carlo
//! total propagated uncertainty (section 3.1), its tables and its plots.
//!
//! It is a library rather than part of the CLI so that `lightpose
//! montecarlo`, a later trade table over every estimator and the tests all
//! run the same engine:
//!
//! - [`axis`]: the six judged quantities, their names and units;
//! - [`montecarlo`]: the ensemble engine (parallel, deterministic for a seed);
//! - [`stats`]: per-step ensemble statistics and coverage;
//! - [`paper`]: the paper's published figures and which case a run is;
//! - [`report`]: the per-step CSV and `summary.md`;
//! - [`plot`]: Figures 6–8 style plots, PNG and SVG, with a bundled font;
//! - [`bound`]: a scene's Cramér–Rao bound along a trajectory;
//! - [`sensors`]: which own sensors (attitude, depth, DVL) a run carries;
//! - [`trade`]: the trade table of every estimator and sensor set;
//! - [`sea`]: its open sea (spec v3): blinking or steady, night or day;
//! - [`dock`]: its docking station (spec v3): the whole pose, roll in;
//! - [`dock_plot`]: a docking approach plotted (track, ±2σ, beacons seen).

pub mod axis;
pub mod bound;
pub mod dock;
pub mod dock_plot;
pub mod montecarlo;
pub mod paper;
pub mod plot;
pub mod report;
pub mod sea;
pub mod sea_plot;
pub mod sensors;
pub mod stats;
pub mod trade;

pub use axis::{Axis, AXES, NAXES};
pub use montecarlo::{run, Draw, McConfig, McError, McResult};
pub use paper::PaperCase;
