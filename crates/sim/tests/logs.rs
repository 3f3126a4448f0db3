//! Sweeps and simulated runs written as real files and read back.

use lightpose_core::LogReader;
use lightpose_sim::{Scene, SweepKind, SweepPlan, Trajectory};
use std::io::Write;

#[test]
fn sweep_file_round_trip_and_frame_count() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sweep.jsonl");
    let plan = SweepPlan::new(SweepKind::All, 3);
    let n = plan
        .write(&Scene::default(), 9, std::fs::File::create(&path).unwrap())
        .unwrap();
    assert_eq!(n, (125 + 183) * 3);
    let mut r = LogReader::open(&path).unwrap();
    assert_eq!(r.header().extra["sweep"], "all");
    let frames: Vec<_> = r.by_ref().map(|f| f.unwrap()).collect();
    assert_eq!(frames.len() as u64, n);
    assert!(frames.iter().all(|f| f.truth.is_some()));
    assert!(frames.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    let first = frames[0].truth.unwrap().pose;
    assert_eq!((first.x, first.y, first.z), (4.5, -0.6, 0.0));
    // same seed, same bytes
    let again = dir.path().join("again.jsonl");
    plan.write(&Scene::default(), 9, std::fs::File::create(&again).unwrap())
        .unwrap();
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(&again).unwrap()
    );
}

#[test]
fn dark_sweep_has_offsets_only_and_no_truth() {
    let mut buf = Vec::new();
    SweepPlan::new(SweepKind::Dark, 50)
        .write(&Scene::default(), 1, &mut buf)
        .unwrap();
    let frames: Vec<_> = LogReader::new(&buf[..], "dark")
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(frames.len(), 50);
    let mean: f64 = frames.iter().map(|f| f.counts[12] as f64).sum::<f64>() / 50.0;
    // 0.15 V = 30.7 counts
    assert!((mean - 0.15 / 5.0 * 1023.0).abs() < 3.0, "{mean}");
    assert!(frames.iter().all(|f| f.truth.is_none()));
}

#[test]
fn simulated_log_cut_short_reads_to_the_last_whole_line() {
    let dir = tempfile::tempdir().unwrap();
    let traj = Trajectory::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/trajectories/zigzag.csv"
    )))
    .unwrap();
    let scene = Scene::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/tank.toml"
    )))
    .unwrap();
    let path = dir.path().join("z.jsonl");
    {
        let mut w =
            lightpose_core::LogWriter::create(&path, &lightpose_core::LogHeader::new(10, 5.0))
                .unwrap();
        let mut sim = lightpose_sim::Simulator::new(scene, 3);
        for (i, t) in traj.frame_times(5.0).enumerate() {
            let (p, s) = traj.sample(t);
            w.write_frame(&sim.frame(i as u64, t, &p, Some(s))).unwrap();
        }
        w.flush().unwrap();
    }
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() - 37);
    std::fs::File::create(&path)
        .unwrap()
        .write_all(&bytes)
        .unwrap();
    let mut r = LogReader::open(&path).unwrap();
    let n = r.by_ref().filter(|f| f.is_ok()).count();
    assert_eq!(n, 40);
    assert_eq!(r.truncated_at(), Some(42));
}
