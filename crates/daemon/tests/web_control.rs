//! The page's control (`[web] control = true`, issue 43 item 4), over real
//! TCP: a calibration reload asked from the page reloads (STATUS counts
//! it); an uploaded configuration gets `--check-config`'s one-line
//! verdict, a bad one its `file:line: key` and one too large a 413; the
//! recording stops from the page (its file completed), the folder is
//! listed and that file downloads byte for byte while the daemon runs, a
//! name that would leave the folder is refused, and recording starts again
//! in a new file. Without
//! `control` the same requests are refused (403) and nothing happens.

mod common;
use common::run::{collect, run_until, sim_config};
use common::{calibration_copy, other_calibration, subscriber};

use lightposed::Config;
use serde_json::Value;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::{Duration, Instant};

fn http(addr: SocketAddr, request: &[u8]) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).expect("send");
    let mut all = Vec::new();
    s.read_to_end(&mut all).expect("an answer");
    let end = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a head");
    let code = String::from_utf8_lossy(&all[9..12])
        .parse()
        .expect("a code");
    (code, all[end + 4..].to_vec())
}

fn post(addr: SocketAddr, path: &str, body: &[u8]) -> (u16, Value) {
    let mut req = format!(
        "POST {path} HTTP/1.1\r\nHost: v\r\nContent-Length: {}\r\n\r\n",
        body.len()
    )
    .into_bytes();
    req.extend_from_slice(body);
    let (code, b) = http(addr, &req);
    (code, serde_json::from_slice(&b).unwrap_or(Value::Null))
}

fn get(addr: SocketAddr, path: &str) -> (u16, Vec<u8>) {
    http(
        addr,
        format!("GET {path} HTTP/1.1\r\nHost: v\r\n\r\n").as_bytes(),
    )
}

/// The latest STATUS within `d`.
fn status(sub: &UdpSocket, d: Duration) -> Value {
    collect(sub, d)
        .into_iter()
        .rev()
        .find(|v| v["class"] == "STATUS")
        .expect("STATUS")
}

fn start(
    text: &str,
    sub: &UdpSocket,
) -> (
    std::thread::JoinHandle<lightposed::Summary>,
    tokio::sync::oneshot::Sender<()>,
    SocketAddr,
) {
    let cfg = Config::parse(text, "control.toml", None).expect("valid config");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let h = run_until(cfg, async move {
        let _ = rx.await;
    });
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(10) {
        for v in collect(sub, Duration::from_millis(100)) {
            if let Some(a) = v["web"]["listen"].as_str() {
                return (h, tx, a.parse().unwrap());
            }
        }
    }
    panic!("no STATUS with web.listen");
}

#[test]
fn with_control_the_page_reloads_checks_a_config_and_downloads_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let (sub, dest) = subscriber();
    let text = sim_config(
        20.0,
        &[dest],
        "",
        &format!("[recording]\ndir = \"{}\"\nflush_s = 0.1\n[web]\nlisten = \"127.0.0.1:0\"\ncontrol = true\n", rec.display()),
    );
    let (cal, text, good) = calibration_copy(dir.path(), &text);
    let (daemon, stop, web) = start(&text, &sub);

    std::fs::write(&cal, other_calibration(&good)).unwrap();
    let (code, v) = post(web, "/v1/reload", b"");
    assert_eq!(code, 202, "{v}");
    let t0 = Instant::now();
    let mut reloads = 0;
    while reloads == 0 && t0.elapsed() < Duration::from_secs(10) {
        reloads = status(&sub, Duration::from_millis(300))["estimator"]["reloads"]
            .as_u64()
            .unwrap_or(0);
    }
    assert_eq!(reloads, 1, "the page's reload reloaded");

    let (code, v) = post(web, "/v1/check-config", text.as_bytes());
    assert_eq!((code, &v["ok"]), (200, &Value::Bool(true)), "{v}");
    let bad = text.replace("rate_hz = 20", "rate_hz = -20");
    let (code, v) = post(web, "/v1/check-config", bad.as_bytes());
    assert_eq!((code, &v["ok"]), (200, &Value::Bool(false)), "{v}");
    assert!(
        v["error"]
            .as_str()
            .unwrap()
            .starts_with("uploaded.toml:1: rate_hz:"),
        "{v}"
    );
    let (code, v) = post(web, "/v1/check-config", &vec![b'#'; 300 << 10]);
    assert_eq!(code, 413, "{v}");
    let (code, v) = post(web, "/v1/check-config", b"\xff\xfe");
    assert!(
        code == 200 && v["error"].as_str().unwrap().contains("not UTF-8"),
        "{v}"
    );

    // Recording stopped from the page: the file is completed and closed,
    // and downloads whole, byte for byte, while the daemon runs on.
    let (code, v) = post(web, "/v1/recording/stop", b"");
    assert_eq!(
        (code, &v["recording"]),
        (202, &Value::from("stopped")),
        "{v}"
    );
    let state = |sub: &UdpSocket| status(sub, Duration::from_millis(300))["recording"].clone();
    let t0 = Instant::now();
    let mut rec_status = state(&sub);
    while rec_status["state"] != "paused" && t0.elapsed() < Duration::from_secs(10) {
        rec_status = state(&sub);
    }
    assert_eq!(rec_status["state"], "paused", "{rec_status}");
    let (code, list) = get(web, "/v1/recordings");
    assert_eq!(code, 200);
    let list: Value = serde_json::from_slice(&list).unwrap();
    let files = list["files"].as_array().unwrap().len();
    let name = list["files"][0]["name"]
        .as_str()
        .expect("a recording")
        .to_string();
    let (code, body) = get(web, &format!("/v1/recordings/{name}"));
    assert_eq!(code, 200);
    let on_disk = std::fs::read(rec.join(&name)).unwrap();
    assert_eq!(body, on_disk, "{name} byte for byte");
    assert!(body.ends_with(b"\n"), "a whole JSON Lines file");
    for bad in [
        "..%2f..%2fetc%2fpasswd",
        "../cal.toml",
        ".hidden",
        "nope.jsonl",
    ] {
        let (code, _) = get(web, &format!("/v1/recordings/{bad}"));
        assert_eq!(code, 404, "{bad}");
    }
    // Started again: a new file.
    let (code, _) = post(web, "/v1/recording/start", b"");
    assert_eq!(code, 202);
    let t0 = Instant::now();
    while state(&sub)["state"] != "recording" && t0.elapsed() < Duration::from_secs(10) {}
    let (_, list) = get(web, "/v1/recordings");
    let list: Value = serde_json::from_slice(&list).unwrap();
    assert_eq!(list["files"].as_array().unwrap().len(), files + 1, "{list}");
    let s = status(&sub, Duration::from_millis(400));
    let _ = stop.send(());
    let summary = daemon.join().expect("daemon");
    assert_eq!((summary.failed, summary.lost), (0, 0));
    assert!(s["frames"].as_u64() > Some(0));
}

#[test]
fn without_control_the_page_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (sub, dest) = subscriber();
    let text = sim_config(20.0, &[dest], "", "[web]\nlisten = \"127.0.0.1:0\"\n");
    let (cal, text, good) = calibration_copy(dir.path(), &text);
    let (daemon, stop, web) = start(&text, &sub);
    std::fs::write(&cal, other_calibration(&good)).unwrap();
    let (code, v) = post(web, "/v1/reload", b"");
    assert_eq!(code, 403, "{v}");
    assert!(v["error"].as_str().unwrap().contains("read-only"), "{v}");
    assert_eq!(post(web, "/v1/check-config", b"rate_hz = 1\n").0, 403);
    assert_eq!(get(web, "/v1/recordings").0, 403);
    let s = status(&sub, Duration::from_millis(1200));
    let _ = stop.send(());
    daemon.join().expect("daemon");
    assert_eq!(
        s["estimator"]["reloads"], 0,
        "no reload: {}",
        s["estimator"]
    );
}
