//! The BlueOS extension (issue 43, item 3): the image's labels as BlueOS
//! reads them (each JSON label parsed, `permissions` as Docker's create
//! body with host networking and the boards' buses), the extensions
//! repository's metadata.json, the shipped config/examples/blueos.toml;
//! and `[mavlink] blueos_endpoint = true` asking a stand-in for BlueOS's
//! autopilot manager for the daemon's MAVLink endpoint (what was posted is
//! recorded and checked), then sending its heartbeats there.

mod common;
use common::run::{run_until, sim_config};
use common::{root, subscriber};

use lightposed::Config;
use serde_json::Value;
use std::collections::BTreeMap;
use std::net::UdpSocket;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The Dockerfile's LABELs, continuation lines joined, quotes taken off.
fn labels(text: &str) -> BTreeMap<String, String> {
    let joined = text.replace("\\\n", "");
    let mut out = BTreeMap::new();
    for line in joined.lines() {
        let Some(rest) = line.trim().strip_prefix("LABEL ") else {
            continue;
        };
        let (key, value) = rest.split_once('=').expect("LABEL key=value");
        let v = value.trim();
        let v = v
            .strip_prefix('\'')
            .and_then(|v| v.strip_suffix('\''))
            .or_else(|| v.strip_prefix('"').and_then(|v| v.strip_suffix('"')))
            .expect("a quoted label value");
        out.insert(key.trim().to_string(), v.to_string());
    }
    out
}

#[test]
fn the_image_s_labels_and_the_repository_s_metadata_parse() {
    let text = std::fs::read_to_string(root().join("config/blueos/Dockerfile")).unwrap();
    assert!(
        text.contains("FROM --platform=$BUILDPLATFORM"),
        "multi-stage, the binary picked per platform"
    );
    for p in ["linux/amd64", "linux/arm64", "linux/arm/v7"] {
        assert!(text.contains(p), "{p}");
    }
    let l = labels(&text);
    assert_eq!(l["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(l["type"], "device-integration");
    let json = |k: &str| -> Value {
        serde_json::from_str(&l[k])
            .unwrap_or_else(|e| panic!("LABEL {k} is not JSON: {e}: {}", l[k]))
    };
    let perm = json("permissions");
    let host = &perm["HostConfig"];
    assert_eq!(host["NetworkMode"], "host", "{perm}");
    let devices: Vec<&str> = host["Devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| {
            assert_eq!(d["PathOnHost"], d["PathInContainer"]);
            assert_eq!(d["CgroupPermissions"], "rwm");
            d["PathOnHost"].as_str().unwrap()
        })
        .collect();
    for d in ["/dev/spidev0.0", "/dev/i2c-1"] {
        assert!(devices.contains(&d), "{d} in {devices:?}");
    }
    assert!(
        host["Binds"][0]
            .as_str()
            .unwrap()
            .ends_with(":/etc/lightpose"),
        "{perm}"
    );
    assert!(perm["ExposedPorts"]["17160/tcp"].is_object(), "{perm}");
    assert!(json("authors")
        .as_array()
        .is_some_and(|a| !a.is_empty() && a[0]["name"].is_string()));
    assert!(json("company")["name"].is_string());
    assert!(json("links")["website"]
        .as_str()
        .unwrap()
        .starts_with("https://"));
    assert!(json("tags")
        .as_array()
        .is_some_and(|t| t.iter().all(Value::is_string)));
    assert!(l["readme"].starts_with("https://") && l["readme"].contains("{tag}"));
    assert!(l["requirements"].starts_with("core >= "));

    let meta: Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("config/blueos/metadata.json")).unwrap(),
    )
    .expect("metadata.json is JSON");
    for k in ["name", "website", "docker", "description"] {
        assert!(
            meta[k].as_str().is_some_and(|s| !s.is_empty()),
            "metadata.json {k}"
        );
    }
    // The image the metadata names is the one tools/blueos-image.sh tags.
    let script = std::fs::read_to_string(root().join("tools/blueos-image.sh")).unwrap();
    assert!(
        script.contains(meta["docker"].as_str().unwrap()),
        "blueos-image.sh tags {}",
        meta["docker"]
    );

    // The example the extension starts with serves the page where the
    // image exposes it.
    let ex =
        Config::load(&root().join("config/examples/blueos.toml")).expect("blueos.toml validates");
    assert_eq!(ex.web.expect("[web]").listen.port(), 17160);
}

/// What the stand-in manager was asked: (method, path, body).
type Asked = Arc<Mutex<Vec<(String, String, String)>>>;

/// A stand-in for BlueOS's autopilot manager: no endpoints at first, and
/// every request recorded.
async fn manager(listener: tokio::net::TcpListener, asked: Asked) {
    loop {
        let Ok((mut s, _)) = listener.accept().await else {
            return;
        };
        let mut all = Vec::new();
        let mut buf = [0u8; 4096];
        let (head, body) = loop {
            let n = s.read(&mut buf).await.unwrap_or(0);
            if n == 0 {
                return;
            }
            all.extend_from_slice(&buf[..n]);
            let Some(end) = all.windows(4).position(|w| w == b"\r\n\r\n") else {
                continue;
            };
            let head = String::from_utf8_lossy(&all[..end]).to_string();
            let len = head
                .lines()
                .find_map(|l| l.strip_prefix("Content-Length: "))
                .map_or(0, |n| n.trim().parse::<usize>().unwrap());
            if all.len() >= end + 4 + len {
                break (
                    head,
                    String::from_utf8_lossy(&all[end + 4..end + 4 + len]).to_string(),
                );
            }
        };
        let mut line = head.lines().next().unwrap().split(' ');
        let (method, path) = (
            line.next().unwrap().to_string(),
            line.next().unwrap().to_string(),
        );
        let answer: &[u8] = if method == "GET" {
            b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n[]"
        } else {
            b"HTTP/1.1 201 Created\r\nContent-Type: application/json\r\nContent-Length: 4\r\n\r\nnull"
        };
        asked.lock().unwrap().push((method, path, body));
        let _ = s.write_all(answer).await;
    }
}

#[test]
fn blueos_endpoint_asks_the_autopilot_manager_and_the_link_goes_there() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let asked: Asked = Arc::default();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let at = listener.local_addr().unwrap();
    rt.spawn(manager(listener, asked.clone()));
    // Where BlueOS's router would listen (the "UDP Server" endpoint).
    let router = UdpSocket::bind("127.0.0.1:0").unwrap();
    router
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let port = router.local_addr().unwrap().port();

    let (_sub, dest) = subscriber();
    let extra = format!(
        "[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 3.0\n[mavlink]\nconnection = \"udpout:127.0.0.1:{port}\"\nblueos_endpoint = true\nblueos_url = \"http://{at}/ardupilot-manager\"\n"
    );
    let cfg =
        Config::parse(&sim_config(10.0, &[dest], "", &extra), "blueos.toml", None).expect("valid");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let daemon = run_until(cfg, async move {
        let _ = rx.await;
    });
    // The daemon's heartbeat reaches the router's port: MAVLink 2 frames.
    let mut buf = [0u8; 512];
    let t0 = Instant::now();
    let mut heard = false;
    while !heard && t0.elapsed() < Duration::from_secs(10) {
        heard = router.recv(&mut buf).is_ok_and(|n| n > 0 && buf[0] == 0xFD);
    }
    let _ = tx.send(());
    daemon.join().expect("daemon");
    assert!(heard, "no MAVLink frame at the endpoint asked for");

    let asked = asked.lock().unwrap().clone();
    assert_eq!(asked.len(), 2, "{asked:?}");
    assert_eq!(
        (asked[0].0.as_str(), asked[0].1.as_str()),
        ("GET", "/ardupilot-manager/v1.0/endpoints/")
    );
    assert_eq!(
        (asked[1].0.as_str(), asked[1].1.as_str()),
        ("POST", "/ardupilot-manager/v1.0/endpoints/")
    );
    let posted: Value = serde_json::from_str(&asked[1].2).expect("JSON posted");
    let e = &posted[0];
    assert_eq!(posted.as_array().map(Vec::len), Some(1), "{posted}");
    assert_eq!(
        e["connection_type"], "udpin",
        "a UDP Server for our udpout: {e}"
    );
    assert_eq!(e["place"], "127.0.0.1");
    assert_eq!(e["argument"], port);
    assert_eq!(
        (e["name"].as_str(), e["owner"].as_str()),
        (Some("lightpose"), Some("lightpose"))
    );
    assert_eq!(
        (e["enabled"].as_bool(), e["persistent"].as_bool()),
        (Some(true), Some(true))
    );
}

#[test]
fn blueos_endpoint_is_refused_for_a_link_the_router_cannot_serve() {
    let (_sub, dest) = subscriber();
    let extra = "[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 3.0\n[mavlink]\nconnection = \"serial:/dev/ttyACM0:115200\"\nblueos_endpoint = true\n";
    let text = sim_config(10.0, &[dest], "", extra);
    let e = Config::parse(&text, "b.toml", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("mavlink.blueos_endpoint: needs a UDP connection"),
        "{e}"
    );
    let bad = text
        .replace("serial:/dev/ttyACM0:115200", "udpout:127.0.0.1:14660")
        .replace("blueos_endpoint = true", "blueos_endpoint = \"yes\"");
    let e = Config::parse(&bad, "b.toml", None).unwrap_err().to_string();
    assert!(
        e.contains("mavlink.blueos_endpoint: want true or false"),
        "{e}"
    );
}
