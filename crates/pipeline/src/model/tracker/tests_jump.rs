//! The jump check (`Tracker::jumped`) on clean runs: the light's own range
//! is never refused by the gate, not even once, so the check never fires
//! and no pose's status changes (the replayed jumps are
//! `tests/jump.rs`).

use super::tests::tank_tracker;
use super::*;
use lightpose_core::LogReader;
use lightpose_sim::{Scene, Simulator, Trajectory};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The tank calibration's tracker over `frames`: frames whose paper range
/// went into x, and the most frames in a row it was refused.
fn paper_ranges(frames: impl IntoIterator<Item = Frame>) -> (usize, u32) {
    let (_, mut tr) = tank_tracker(TrackerConfig::default());
    let (mut read, mut refused) = (0, 0);
    for f in frames {
        tr.estimate(&f);
        if let Some(s) = tr.state_at(f.t) {
            read += usize::from(s.paper_x.is_some());
            refused = refused.max(s.paper_refused);
        }
    }
    (read, refused)
}

/// The recorded logs of tests/data that the tank calibration reads.
#[test]
fn the_regression_logs_never_refuse_the_light_s_range() {
    for name in ["dive", "zigzag", "hard", "fusion-depth", "fusion-all"] {
        let path = root().join(format!("tests/data/{name}.jsonl"));
        let mut log = LogReader::open(&path).expect("log");
        // hard.jsonl's malformed lines are skipped, as the replay skips them.
        let frames = std::iter::from_fn(|| log.next_frame()).filter_map(Result::ok);
        let (read, refused) = paper_ranges(frames);
        assert_eq!(
            refused, 0,
            "{name}: the paper range refused {refused} in a row"
        );
        // Not vacuous: the logs without an attitude reading read it.
        if !name.starts_with("fusion-all") {
            assert!(read > 0, "{name}: the paper range read on no frame");
        }
    }
}

/// A minute of coming and going in turbid water the calibration did not
/// see (tests/data/tank-murky.toml: K_D 0.19 and 0.29 against the tank's
/// 0.09, noise and scattering on), without an attitude reading, with and
/// without depth: the law and the light model are both told the wrong
/// water, and their ranges still agree within the gate.
#[test]
fn turbid_water_never_refuses_the_light_s_range() {
    let text = std::fs::read_to_string(root().join("tests/data/tank-murky.toml")).expect("scene");
    // The murky tank's attitude sensor off: the paper range is read.
    let base = &text[..text.find("[attitude]").expect("attitude table")];
    let traj = Trajectory::load(&root().join("tests/data/to-and-fro.csv")).expect("trajectory");
    for (k_d, extra, seed) in [("0.19", "", 7), ("0.19", "\n[depth]\n", 8), ("0.29", "", 9)] {
        let toml = base.replace("k_d = 0.19", &format!("k_d = {k_d}")) + extra;
        let scene = Scene::parse(&toml, "murky").expect("murky scene");
        let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
        let mut sim = Simulator::new(scene, seed);
        let frames = times
            .iter()
            .enumerate()
            .map(|(j, &t)| sim.frame_moving(j as u64, t, &traj.kinematics(t)));
        let (read, refused) = paper_ranges(frames.collect::<Vec<_>>());
        assert_eq!(refused, 0, "K_D {k_d}{extra}: refused {refused} in a row");
        assert!(read > 200, "K_D {k_d}{extra}: read on {read} of 301 frames");
    }
}
