//! The frame thread's side of the vehicle link, `Readings::attach` and
//! `PoseOutbox::offer`, must neither allocate nor lock: a counting global
//! allocator, counting only on the frame thread, sees no allocation over
//! thousands of frames while the MAVLink task takes the poses and sends
//! them on another thread. And the MAVLink task itself, sending to a
//! `udpout` peer that is down, allocates nothing per pose for the error
//! each one draws.

mod common;

use common::{estimate, spawn_mavlink, udpout, wait_until};
use lightpose_core::{Angle, AttitudeReading, DepthReading, Frame, VelocityReading, NDET};
use lightpose_testkit::alloc::Counting;
use lightpose_vehicle::{Hub, MaxAge, Offer};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

#[global_allocator]
static A: Counting = Counting::new();

#[test]
fn attach_and_offer_do_not_allocate() {
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = sink.local_addr().unwrap().port();
    let hub = Hub::new();
    let _running = spawn_mavlink(udpout(port), hub.clone());
    let now = Instant::now();
    hub.readings.store_attitude(
        now,
        &AttitudeReading::new(Angle::from_deg(2.0), Angle::from_deg(-3.0)),
    );
    hub.readings.store_depth(now, &DepthReading::new(0.4));
    hub.readings.store_temperature(now, 14.0);
    hub.readings
        .store_velocity(now, &VelocityReading::new(0.3, 0.0, 0.0));
    let ages = MaxAge {
        attitude: Duration::from_secs(3600),
        depth: Duration::from_secs(3600),
        temperature: Duration::from_secs(3600),
        velocity: Duration::from_secs(3600),
    };
    let frame = |k: u64| {
        let mut f = Frame::new(k, k as f64 * 0.01, 10, [0; NDET]);
        let a = hub.readings.attach(&mut f, Instant::now(), &ages);
        assert!(a.attitude && a.depth && a.temperature && a.velocity);
        assert_eq!(hub.outbox.offer(&estimate(k, f.t), 0), Offer::Queued);
    };
    for k in 0..200 {
        frame(k);
    }
    // Counted on this thread, the frame thread, only.
    let ((), allocs) = A.this_thread(|| {
        let mut sent = hub.mavlink.sent(0);
        for k in 200..10_200 {
            frame(k);
            if k % 1000 == 999 {
                // Wait for the task to send this pose, so that the two sides
                // do run together while the frame thread is counted: a burst
                // alone ends in milliseconds, and on a loaded machine the task
                // may not run in them at all (the test failed so, once in
                // some hundred runs). Polling an atomic and sleeping do not
                // allocate; the pose is 10 s of capture time past the last,
                // so no rate limit holds it back.
                let more = wait_until(Duration::from_secs(5), || hub.mavlink.sent(0) > sent);
                assert!(more, "pose {k} sent within 5 s");
                sent = hub.mavlink.sent(0);
            } else if k % 100 == 0 {
                std::thread::yield_now();
            }
        }
    });
    assert_eq!(allocs, 0, "allocations on the frame thread");
    // Ten poses went out while it was counted.
    assert!(hub.mavlink.sent(0) >= 10);
}

/// Audit: every failed UDP receive or send was formatted into STATUS's
/// `last_error`, and a `udpout` peer that is down (a closed port) answers
/// about every pose with an ICMP "port unreachable", which the socket's
/// next receive or send reports as ECONNREFUSED: an allocation per pose.
/// The task runs here on a thread of its own, counted once it is warm.
#[test]
fn a_peer_that_is_down_costs_the_task_no_allocation() {
    let port = {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        s.local_addr().unwrap().port()
    }; // closed again: nobody listens there
    let hub = Hub::new();
    let s = udpout(port);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let h = hub.clone();
    let task = std::thread::spawn(move || {
        A.watch_this_thread();
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        rt.block_on(lightpose_vehicle::mav::task::run(s, h, async {
            let _ = stopped.await;
        }));
    });
    let errors = || {
        let st = hub.mavlink.status(Instant::now());
        (
            st.send_errors + st.recv_errors,
            hub.mavlink.sent(0) + st.send_errors,
        )
    };
    // One pose at a time, each waited for until the task has tried it.
    let pose = |k: u64| {
        let tried = errors().1;
        assert_eq!(hub.outbox.offer(&estimate(k, k as f64), 0), Offer::Queued);
        let went = wait_until(Duration::from_secs(5), || errors().1 > tried);
        assert!(went, "pose {k} tried within 5 s");
    };
    for k in 0..20 {
        pose(k);
    }
    let (before, _) = errors();
    assert!(before > 0, "a closed port refuses: {before} errors");
    // Counted on the task's thread only.
    let ((), task_allocs) = A.watched(|| {
        for k in 20..320 {
            pose(k);
        }
        // The last pose's refusal, if it comes on the receive side.
        std::thread::sleep(Duration::from_millis(20));
    });
    let (after, _) = errors();
    let _ = stop.send(());
    task.join().expect("task thread ends without panic");
    assert!(
        after - before >= 100,
        "{} refusals over 300 poses",
        after - before
    );
    assert_eq!(task_allocs, 0, "allocations on the task thread");
    let st = hub.mavlink.status(Instant::now());
    let last = st.last_error.unwrap_or_default();
    assert!(last.contains("Connection refused"), "{last}");
}
