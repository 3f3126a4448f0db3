//! `convert_ros2` of a lightpose MCAP recording: its STATUS messages
//! become `/diagnostics`, stamped on the poses' wall clock (a STATUS at
//! log time t′ is the last pose's wall time + (t′ − t)), each at the level
//! of the latest pose's status; the poses that are not `ok` are counted,
//! not written.

mod common;

use common::record;
use lightpose_logs::ros2msg::{DiagnosticArray, DIAG_WARN};
use lightpose_logs::{convert_ros2, Ros2BagOptions};

#[test]
fn a_recording_s_status_becomes_diagnostics_on_the_wall_clock() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, bag) = (dir.path().join("rec.mcap"), dir.path().join("bag.mcap"));
    // 30 frames at 5 Hz, a STATUS after frames 9, 19 and 29, each pose
    // stamped 1.7e9 + t on the wall clock.
    std::fs::write(&rec, record(30, 4096)).unwrap();
    let s = convert_ros2(&rec, &bag, None, &Ros2BagOptions::default(), |e| {
        panic!("{e}")
    })
    .unwrap();
    assert_eq!((s.frames, s.poses, s.diagnostics), (30, 30, 3), "{s:?}");
    // common::pose gives σ of x and yaw only: nothing complete to publish.
    assert_eq!((s.written, s.not_ok), (0, 30));

    let bytes = std::fs::read(&bag).unwrap();
    let mut got = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.topic, "/diagnostics");
        assert_eq!(m.data[..4], [0, 1, 0, 0]);
        let d: DiagnosticArray =
            cdr_encoding::from_bytes::<DiagnosticArray, byteorder::LittleEndian>(&m.data[4..])
                .unwrap()
                .0;
        let ns = d.header.stamp.sec as u64 * 1_000_000_000 + d.header.stamp.nanosec as u64;
        assert_eq!(m.log_time, ns);
        let st = &d.status[0];
        assert_eq!(st.level, DIAG_WARN, "{st:?}");
        let seq = st.values.iter().find(|kv| kv.key == "seq").unwrap();
        got.push((ns, st.message.clone(), seq.value.clone()));
    }
    // Frames 9, 19, 29 at t = seq·0.2 s; each of their poses no_light.
    let want: Vec<(u64, String, String)> = [(9u64, "0"), (19, "1"), (29, "2")]
        .iter()
        .map(|&(f, k)| {
            let wall = 1.7e9 + f as f64 * 0.2;
            (
                (wall * 1e9).round() as u64,
                format!("no_light (frame {f})"),
                k.to_string(),
            )
        })
        .collect();
    for (g, w) in got.iter().zip(&want) {
        assert!(g.0.abs_diff(w.0) <= 1_000, "{got:?}");
        assert_eq!((&g.1, &g.2), (&w.1, &w.2));
    }
    assert_eq!(got.len(), 3);
}
