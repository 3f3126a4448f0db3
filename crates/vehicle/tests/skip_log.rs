//! An `ok` pose that cannot go to the autopilot (a std missing under the
//! default `missing_std = "skip"`, a negative capture time) is said in the
//! journal, not only counted for STATUS: the first of each reason at once,
//! with the pose's seq and why, then after 1 s, 10 s, 1 min and every 10
//! min while more come; a burst of skips is one line, not one per pose.

mod common;

use common::{estimate, udpout};
use lightpose_testkit::logs::logged;
use lightpose_vehicle::{Hub, Offer};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

/// The count of skips of `reason` in STATUS.
fn skipped(hub: &Hub, reason: &str) -> u64 {
    let st = hub.mavlink.status(Instant::now());
    st.skipped
        .iter()
        .find(|(r, _)| *r == reason)
        .map_or(0, |(_, n)| *n)
}

/// Offer `e` and wait (up to 5 s) until the task has skipped it.
async fn skip_one(hub: &Hub, e: &lightpose_core::PoseEstimate, reason: &str) {
    let before = skipped(hub, reason);
    assert_eq!(hub.outbox.offer(e, 0), Offer::Queued);
    let end = Instant::now() + Duration::from_secs(5);
    while skipped(hub, reason) == before {
        assert!(Instant::now() < end, "pose {} skipped within 5 s", e.seq);
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}

#[test]
fn a_burst_of_skipped_poses_is_one_warning_per_reason() {
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = sink.local_addr().unwrap().port();
    let hub = Hub::new();
    let s = udpout(port);
    let burst = 50;
    let mut took = Duration::ZERO;
    let log = logged(|| {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
            let task = lightpose_vehicle::mav::task::run(s, hub.clone(), async {
                let _ = stopped.await;
            });
            let feed = async {
                let t0 = Instant::now();
                for k in 0..burst {
                    let mut e = estimate(7 + k, 1.0 + k as f64 * 0.1);
                    e.std.yaw = None;
                    skip_one(&hub, &e, "no_std").await;
                }
                took = t0.elapsed();
                skip_one(&hub, &estimate(500, -2.0), "bad_time").await;
                let _ = stop.send(());
            };
            tokio::join!(task, feed);
        });
    });
    assert_eq!(skipped(&hub, "no_std"), burst);
    let warns: Vec<&str> = log.lines().filter(|l| l.contains(" WARN ")).collect();
    let no_std: Vec<&&str> = warns
        .iter()
        .filter(|l| l.contains("reason=\"no_std\""))
        .collect();
    // One line for the burst (one more per whole second it took, on a
    // machine slow enough to stretch it), and at stop the skips after
    // its last line: the lines add up to the burst.
    let (at_stop, no_std): (Vec<&&str>, Vec<&&str>) =
        no_std.into_iter().partition(|l| l.contains(": at stop: "));
    let most = 1 + took.as_secs() as usize;
    assert!(
        (1..=most).contains(&no_std.len()),
        "{} no_std lines for {burst} skips in {took:?}:\n{log}",
        no_std.len()
    );
    let number_after = |l: &str, key: &str| -> u64 {
        let at = l.find(key).unwrap_or_else(|| panic!("{key} in {l}")) + key.len();
        let digits = l[at..].split(|c: char| !c.is_ascii_digit()).next();
        digits.unwrap().parse().unwrap()
    };
    // The count in all of the last line: the skips its lines told.
    let mut told = number_after(no_std[no_std.len() - 1], " count=");
    assert!(at_stop.len() <= 1, "{log}");
    for l in &at_stop {
        assert!(
            l.contains("VISION_POSITION_ESTIMATE skips (no_std): at stop: ")
                && l.contains(&format!("({burst} in all)")),
            "{l}"
        );
        told += number_after(l, "since_last_line=");
    }
    assert_eq!(told, burst, "{log}");
    let first = no_std[0];
    assert!(
        first.contains("VISION_POSITION_ESTIMATE not sent for pose 7:")
            && first.contains("no std for yaw")
            && first.contains("missing_std"),
        "{first}"
    );
    let bad_time: Vec<&&str> = warns
        .iter()
        .filter(|l| l.contains("reason=\"bad_time\""))
        .collect();
    assert_eq!(bad_time.len(), 1, "{log}");
    assert!(
        bad_time[0].contains("pose 500") && bad_time[0].contains("capture time -2 s"),
        "{}",
        bad_time[0]
    );
}
