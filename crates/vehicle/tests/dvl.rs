//! A stand-in Water Linked DVL: a TCP server in the test speaking the
//! vendor's JSON (one report per line). Good reports become readings;
//! garbage lines, `velocity_valid: false`, water-track reports, a server
//! that closes, falls silent or goes away and comes back are counted and
//! survived; a reading that stops coming goes stale and is not attached.

mod common;

use common::{spawn_dvl, wait_until};
use lightpose_core::{Frame, NDET};
use lightpose_vehicle::dvl::DvlRefusal;
use lightpose_vehicle::{DvlSettings, Hub, MaxAge};
use std::io::Write;
use std::net::{TcpListener, TcpStream};
use std::time::{Duration, Instant};

/// A report sent 50 ms after its time of validity.
fn report(vx: f64, vy: f64, vz: f64, valid: bool) -> String {
    lightpose_testkit::dvl::report([vx, vy, vz], valid, 50_000)
}

fn accept(l: &TcpListener) -> TcpStream {
    l.set_nonblocking(false).unwrap();
    let (s, _) = l.accept().expect("the client connects");
    s
}

fn settings(port: u16) -> DvlSettings {
    let mut s = DvlSettings::new(format!("127.0.0.1:{port}"));
    s.reconnect_first = Duration::from_millis(50);
    s.reconnect_max = Duration::from_millis(200);
    s.silence = Duration::from_millis(400);
    s
}

fn velocity_is(hub: &Hub, v: [f64; 3]) -> bool {
    hub.readings
        .velocity(Instant::now(), Duration::from_secs(60))
        .is_some_and(|r| r.v.0 == v)
}

#[test]
fn the_dvl_client_reads_reports_and_survives_what_a_real_one_does() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let hub = Hub::new();
    let _client = spawn_dvl(settings(port), hub.clone());
    let c = &hub.dvl;

    // 1. Good reports, and every kind of line that is not one.
    let mut s = accept(&listener);
    s.write_all(report(0.3, -0.05, 0.01, true).as_bytes())
        .unwrap();
    s.write_all(b"this is not json\n\n").unwrap();
    s.write_all(report(9.0, 9.0, 9.0, false).as_bytes())
        .unwrap();
    s.write_all(
        report(0.3, 0.0, 0.0, true)
            .replace("\"velocity\"", "\"velocity_water\"")
            .as_bytes(),
    )
    .unwrap();
    s.write_all(report(60.0, 0.0, 0.0, true).as_bytes())
        .unwrap();
    s.write_all(b"{\"type\":\"position_local\",\"x\":1.0,\"y\":2.0,\"z\":0.5,\"std\":0.1,\"roll\":0,\"pitch\":0,\"yaw\":0,\"status\":0,\"ts\":1.0,\"format\":\"json_v3.1\"}\n").unwrap();
    // A report split across two writes.
    let r = report(0.25, 0.02, -0.01, true);
    s.write_all(&r.as_bytes()[..50]).unwrap();
    s.flush().unwrap();
    std::thread::sleep(Duration::from_millis(30));
    s.write_all(&r.as_bytes()[50..]).unwrap();
    assert!(
        wait_until(Duration::from_secs(5), || velocity_is(
            &hub,
            [0.25, 0.02, -0.01]
        )),
        "{:?}",
        c.status()
    );
    assert_eq!(c.reports(), 2);
    assert_eq!(c.refused(DvlRefusal::Garbage), 1);
    assert_eq!(c.refused(DvlRefusal::Invalid), 1);
    assert_eq!(c.refused(DvlRefusal::WaterTrack), 1);
    assert_eq!(c.refused(DvlRefusal::OutOfRange), 1);
    assert_eq!(c.status().other, 1);
    let std = hub
        .readings
        .velocity(Instant::now(), Duration::from_secs(60))
        .unwrap()
        .std
        .unwrap();
    assert!(
        (std.0[0] - 0.01).abs() < 1e-12
            && (std.0[1] - 0.02).abs() < 1e-12
            && (std.0[2] - 0.03).abs() < 1e-12
    );

    // 2. The DVL closes the connection: counted, and the client is back.
    drop(s);
    let mut s = accept(&listener);
    assert!(wait_until(Duration::from_secs(5), || c.drops() == 1
        && c.connects() == 2));
    s.write_all(report(0.1, 0.0, 0.0, true).as_bytes()).unwrap();
    assert!(wait_until(Duration::from_secs(5), || velocity_is(
        &hub,
        [0.1, 0.0, 0.0]
    )));

    // 3. It falls silent: given up after the silence limit, reconnected.
    let _silent = s;
    let s3 = accept(&listener);
    assert!(wait_until(Duration::from_secs(5), || c.status().silences
        == 1
        && c.connects() == 3));

    // 4. It goes away altogether (unplugged): connections refused, counted;
    // meanwhile the last reading goes stale and is not attached.
    drop(s3);
    drop(listener);
    assert!(wait_until(Duration::from_secs(5), || c
        .status()
        .connect_failures
        >= 2));
    let mut f = Frame::new(0, 0.0, 10, [0; NDET]);
    let ages = MaxAge {
        velocity: Duration::from_millis(100),
        ..MaxAge::default()
    };
    let a = hub.readings.attach(&mut f, Instant::now(), &ages);
    assert!(!a.velocity && f.velocity.is_none());
    assert!(hub.readings.status(Instant::now()).velocity.stale >= 1);

    // 5. It comes back on the same port: the client finds it again.
    let listener = TcpListener::bind(("127.0.0.1", port)).expect("the port again");
    let mut s = accept(&listener);
    s.write_all(report(-0.2, 0.1, 0.0, true).as_bytes())
        .unwrap();
    assert!(wait_until(Duration::from_secs(5), || velocity_is(
        &hub,
        [-0.2, 0.1, 0.0]
    )));
    let st = c.status();
    assert_eq!(st.connects, 4, "{st:?}");
    assert!(st.drops >= 3, "{st:?}");
    assert!(st.last_error.is_some());
}

/// Network audit: an overlong line was refused only at its newline, so a
/// peer sending one endless line kept the connection with nothing
/// refused. Past 64 KiB without a newline the connection is dropped,
/// counted `garbage`, with `last_error` saying so, and connected again.
#[test]
fn a_peer_sending_an_endless_line_is_dropped_and_counted() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let hub = Hub::new();
    let mut set = settings(port);
    set.silence = Duration::from_secs(10); // not what ends it here
    let _client = spawn_dvl(set, hub.clone());
    let c = &hub.dvl;
    let mut s = accept(&listener);
    // The client stops reading at 64 KiB: later writes may fail.
    let _ = s.write_all(&vec![b'x'; 200 * 1024]);
    assert!(
        wait_until(Duration::from_secs(3), || c.drops() == 1),
        "{:?}",
        c.status()
    );
    let st = c.status();
    assert_eq!(c.refused(DvlRefusal::Garbage), 1, "{st:?}");
    assert_eq!(st.silences, 0, "{st:?}");
    assert!(
        st.last_error
            .as_deref()
            .is_some_and(|e| e.contains("64 KiB")),
        "{st:?}"
    );
    let _again = accept(&listener);
    assert!(wait_until(Duration::from_secs(3), || c.connects() == 2));
}

/// Network audit: any byte reset the silence timer, so a peer trickling a
/// byte every 2 s kept the connection (and a stale `last_error`). Only a
/// DVL message counts: reports every 100 ms keep it well past the 0.5 s
/// silence, a byte every 100 ms does not.
#[test]
fn a_peer_trickling_bytes_is_dropped_as_silent() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let hub = Hub::new();
    let mut set = settings(port);
    set.silence = Duration::from_millis(500);
    let _client = spawn_dvl(set, hub.clone());
    let c = &hub.dvl;
    let mut s = accept(&listener);
    // A healthy DVL at 10 Hz for 1.2 s: kept.
    for i in 0..12 {
        s.write_all(report(0.01 * i as f64, 0.0, 0.0, true).as_bytes())
            .unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    let st = c.status();
    assert_eq!((st.drops, st.silences, st.reports), (0, 0, 12), "{st:?}");
    // Then a space every 100 ms: no message, dropped as silent.
    let t0 = Instant::now();
    while c.status().silences == 0 && t0.elapsed() < Duration::from_secs(3) {
        let _ = s.write_all(b" ");
        std::thread::sleep(Duration::from_millis(100));
    }
    let st = c.status();
    assert_eq!((st.drops, st.silences), (1, 1), "{st:?}");
    assert!(
        st.last_error
            .as_deref()
            .is_some_and(|e| e.contains("silent")),
        "{st:?}"
    );
    assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
}
