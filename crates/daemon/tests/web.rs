//! The web page and API (`[web]`, issue 43), over real TCP on loopback:
//! the page and its files answer with relative paths only; the BlueOS
//! contract and the REST answers match config/blueos/openapi.json (checked
//! by Python's jsonschema, an independent implementation); the live feed
//! gives at least 5 events a second; the server's limits hold (a head too
//! large, a connection over the cap, a client that never reads beside one
//! that does); and without `[web]` the daemon listens on no TCP port.

mod common;
use common::run::{collect, run_until, sim_config, spawn_daemon};
use common::{root, subscriber};
use lightpose_testkit::python::{python, run_python};

use lightposed::Config;
use serde_json::Value;
use std::ffi::OsStr;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::{Duration, Instant};

/// A daemon in-process on its own thread, stopped when `stop` is sent.
fn start(
    text: &str,
) -> (
    std::thread::JoinHandle<lightposed::Summary>,
    tokio::sync::oneshot::Sender<()>,
) {
    let cfg = Config::parse(text, "web.toml", None).expect("valid config");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let h = run_until(cfg, async move {
        let _ = rx.await;
    });
    (h, tx)
}

/// The page's address, from STATUS (`web.listen`, port 0 resolved).
fn web_addr(sub: &UdpSocket) -> SocketAddr {
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(10) {
        for v in collect(sub, Duration::from_millis(100)) {
            if let Some(a) = v["web"]["listen"].as_str() {
                return a.parse().expect("listen is an address");
            }
        }
    }
    panic!("no STATUS with web.listen within 10 s");
}

/// One request, its answer: status code, head, body.
fn http(addr: SocketAddr, request: &str) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request.as_bytes()).expect("send");
    let mut all = Vec::new();
    s.read_to_end(&mut all).expect("an answer, then the close");
    let end = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a head");
    let head = String::from_utf8_lossy(&all[..end]).to_string();
    let code = head[9..12].parse().expect("a status code");
    (code, head, all[end + 4..].to_vec())
}

fn get(addr: SocketAddr, path: &str) -> (u16, String, Vec<u8>) {
    http(
        addr,
        &format!("GET {path} HTTP/1.1\r\nHost: vehicle\r\n\r\n"),
    )
}

fn web_config(dest: SocketAddr, web_extra: &str) -> String {
    sim_config(
        20.0,
        &[dest],
        "",
        &format!("[web]\nlisten = \"127.0.0.1:0\"\n{web_extra}\n"),
    )
}

#[test]
fn the_page_and_the_api_answer_as_the_openapi_file_says() {
    let py = python();
    let (sub, dest) = subscriber();
    let (daemon, stop) = start(&web_config(dest, ""));
    let web = web_addr(&sub);

    let (code, head, page) = get(web, "/");
    assert_eq!(code, 200, "{head}");
    assert!(head.contains("Content-Type: text/html"), "{head}");
    let page = String::from_utf8(page).expect("UTF-8 page");
    // BlueOS serves the page under a prefix: no reference may start at
    // the root, and nothing comes from another host.
    for bad in ["src=\"/", "href=\"/", "http://", "https://"] {
        assert!(!page.contains(bad), "the page holds {bad:?}");
    }
    for file in ["app.js", "style.css", "icon.svg"] {
        assert!(
            page.contains(&format!("\"{file}\"")),
            "the page names {file}"
        );
        let (code, head, body) = get(web, &format!("/{file}"));
        assert_eq!(code, 200, "{file}: {head}");
        assert!(!body.is_empty());
    }
    let (_, _, js) = get(web, "/app.js");
    let js = String::from_utf8(js).unwrap();
    assert!(
        js.contains("new EventSource(\"v1/events\")"),
        "relative feed"
    );
    assert!(!js.contains("fetch(\"/") && !js.contains("EventSource(\"/"));

    let (code, _, body) = get(web, "/register_service");
    assert_eq!(code, 200);
    let reg: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(reg["works_in_relative_paths"], true);
    assert_eq!(reg["version"], env!("CARGO_PKG_VERSION"));

    // Read-only: anything but GET/HEAD is refused, in one line of JSON.
    let (code, _, body) = http(
        web,
        "POST /v1/pose HTTP/1.1\r\nHost: v\r\nContent-Length: 0\r\n\r\n",
    );
    assert_eq!(code, 405);
    let e: Value = serde_json::from_slice(&body).unwrap();
    assert!(e["error"].as_str().unwrap().contains("read-only"), "{e}");
    let (code, head, body) = http(web, "HEAD /v1/status HTTP/1.1\r\nHost: v\r\n\r\n");
    assert_eq!(code, 200, "{head}");
    assert!(body.is_empty());

    let spec = root().join("config/blueos/openapi.json");
    let (_, _, served) = get(web, "/v1/openapi.json");
    assert_eq!(
        served,
        std::fs::read(&spec).unwrap(),
        "the file served is the file checked"
    );
    let base = format!("http://{web}");
    let out = run_python(
        &py,
        &root().join("crates/daemon/tests/web_openapi.py"),
        &[spec.as_os_str(), OsStr::new(&base)],
    );
    let got: Value = serde_json::from_str(&out).expect("one JSON object");
    let checked: Vec<&str> = got["checked"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(
        checked,
        ["/register_service", "/v1/status", "/v1/pose", "404", "live"]
    );

    // The pose served is a POSE the daemon sent.
    let (_, _, pose) = get(web, "/v1/pose");
    let pose: Value = serde_json::from_slice(&pose).unwrap();
    assert_eq!(pose["class"], "POSE");
    assert!(pose["seq"].as_u64() > Some(0), "{pose}");
    let _ = stop.send(());
    daemon.join().expect("daemon");
}

/// The feed's events for `d`: (live events, status events, the last live
/// event), read as a browser reads them.
fn read_feed(web: SocketAddr, d: Duration) -> (usize, usize, Value) {
    let mut s = TcpStream::connect(web).unwrap();
    s.write_all(b"GET /v1/events HTTP/1.1\r\nHost: v\r\n\r\n")
        .unwrap();
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut text = Vec::new();
    let end = Instant::now() + d;
    let mut buf = [0u8; 65536];
    while Instant::now() < end {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => text.extend_from_slice(&buf[..n]),
            Err(_) => {}
        }
    }
    let text = String::from_utf8_lossy(&text).to_string();
    assert!(
        text.starts_with("HTTP/1.1 200 OK\r\nContent-Type: text/event-stream"),
        "{}",
        &text[..text.len().min(300)]
    );
    let (mut live, mut status, mut last) = (0, 0, Value::Null);
    let mut name = "";
    for line in text.lines() {
        if let Some(n) = line.strip_prefix("event: ") {
            name = n;
        } else if let Some(data) = line.strip_prefix("data: ") {
            let v: Value = serde_json::from_str(data).expect("each event is one JSON object");
            match name {
                "live" => {
                    live += 1;
                    last = v;
                }
                "status" => status += 1,
                other => panic!("unknown event {other}"),
            }
        }
    }
    (live, status, last)
}

#[test]
fn the_feed_gives_five_events_a_second_and_a_client_that_never_reads_costs_nothing() {
    let (sub, dest) = subscriber();
    let text = sim_config(
        100.0,
        &[dest],
        "pace = \"fast\"",
        "[web]\nlisten = \"127.0.0.1:0\"\nmax_clients = 4\nmax_clients_per_addr = 4\n",
    );
    let (daemon, stop) = start(&text);
    let web = web_addr(&sub);

    // A client that asks for the feed and never reads, its receive
    // buffer made small so that it fills.
    let stuck = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    stuck.set_recv_buffer_size(4096).unwrap();
    stuck.connect(&web.into()).unwrap();
    let mut stuck: TcpStream = stuck.into();
    stuck
        .write_all(b"GET /v1/events HTTP/1.1\r\nHost: v\r\n\r\n")
        .unwrap();

    let (live, status, last) = read_feed(web, Duration::from_secs(2));
    assert!(live >= 10, "{live} live events in 2 s");
    assert!(
        status >= 2,
        "{status} STATUS events in 2 s (one each 0.2 s)"
    );
    assert_eq!(last["frame"]["counts"].as_array().unwrap().len(), 25);
    assert_eq!(last["pose"]["class"], "POSE");

    // The cap: 4 places; the stuck client holds one, three more are
    // taken and held (a head never finished), the fifth is turned away.
    let held: Vec<TcpStream> = (0..3).map(|_| TcpStream::connect(web).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(200));
    let (code, head, body) = get(web, "/v1/status");
    assert_eq!(code, 503, "{head}");
    assert!(head.contains("Retry-After"), "{head}");
    assert!(String::from_utf8_lossy(&body).contains("too many connections"));
    drop(held);
    std::thread::sleep(Duration::from_millis(200));

    // A head over 8 KiB: refused, counted.
    let big = format!("GET / HTTP/1.1\r\nX-Pad: {}\r\n\r\n", "a".repeat(9000));
    let (code, _, _) = http(web, &big);
    assert_eq!(code, 431);
    let (code, _, _) = http(web, "BREW /pot HTCPCP/1.0\r\n\r\n");
    assert_eq!(code, 400);

    let status = collect(&sub, Duration::from_millis(400))
        .into_iter()
        .rev()
        .find(|v| v["class"] == "STATUS")
        .expect("STATUS");
    let _ = stop.send(());
    let summary = daemon.join().expect("daemon");
    drop(stuck);
    let w = &status["web"];
    assert!(w["refused"].as_u64() >= Some(1), "{w}");
    assert!(w["bad_requests"].as_u64() >= Some(2), "{w}");
    assert!(w["events"].as_u64() >= Some(10), "{w}");
    // The frame thread ran free all along: thousands of frames, none
    // failed or lost, whatever the page's clients did.
    assert!(summary.frames > 2000, "{summary:?}");
    assert_eq!((summary.failed, summary.lost), (0, 0));
}

/// The inodes of the TCP sockets `pid` listens on (/proc: its fds'
/// `socket:[inode]` against the LISTEN lines of its network namespace).
fn listening_tcp(pid: u32) -> Vec<u64> {
    let mut mine = std::collections::HashSet::new();
    for e in std::fs::read_dir(format!("/proc/{pid}/fd")).expect("/proc/PID/fd") {
        let Ok(link) = std::fs::read_link(e.unwrap().path()) else {
            continue;
        };
        let l = link.to_string_lossy().to_string();
        if let Some(i) = l.strip_prefix("socket:[").and_then(|s| s.strip_suffix(']')) {
            mine.insert(i.parse::<u64>().unwrap());
        }
    }
    let mut out = Vec::new();
    for table in ["tcp", "tcp6"] {
        let text = std::fs::read_to_string(format!("/proc/{pid}/net/{table}")).unwrap_or_default();
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            // st 0A is LISTEN; the inode is the tenth field.
            if f.len() > 9 && f[3] == "0A" {
                let inode: u64 = f[9].parse().unwrap();
                if mine.contains(&inode) {
                    out.push(inode);
                }
            }
        }
    }
    out
}

#[test]
fn without_a_web_table_the_daemon_listens_on_no_tcp_port() {
    let dir = tempfile::tempdir().unwrap();
    let (sub, dest) = subscriber();
    let off = sim_config(20.0, &[dest], "", "");
    let (mut child, _) = spawn_daemon(dir.path(), &off, &sub);
    let none = listening_tcp(child.id());
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(none, Vec::<u64>::new(), "TCP ports open without [web]");

    // The same look finds the page's port when it is on: the check sees.
    // (The first daemon's datagrams drained: spawn_daemon waits for POSE.)
    let _ = collect(&sub, Duration::from_millis(300));
    let on = web_config(dest, "");
    let (mut child, _) = spawn_daemon(dir.path(), &on, &sub);
    let mut one = listening_tcp(child.id());
    let t0 = Instant::now();
    while one.is_empty() && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(50));
        one = listening_tcp(child.id());
    }
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(one.len(), 1, "the page's one port");
}
