//! The web page in a real browser (issue 43's "done when"): Debian's
//! headless Chromium, driven by npm's playwright-core (tools/browserenv.sh
//! installs both, or fails with one line: never a skip), opens the page
//! through a reverse proxy that serves it under a path prefix as BlueOS
//! does, sees the heatmap drawn, the pose change at least 5 times a
//! second and status `ok` with no script error; the daemon is then
//! restarted on the same port with the mock backend's faults, and the
//! page reconnects by itself and says what is wrong. Screenshots are
//! saved to target/web-shots/ (docs/blueos.md shows them).

mod common;
use common::run::{collect, run_until, sim_config};
use common::{free_tcp_port, root, subscriber};

use lightposed::Config;
use serde_json::Value;
use std::io::{BufRead, BufReader, Write};
use std::net::SocketAddr;
use std::process::{Command, Stdio};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// BlueOS's prefix for an extension's page.
const PREFIX: &str = "/extensionv2/lightpose";

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

/// A reverse proxy as BlueOS's: `PREFIX/x` to the daemon's `/x`, a 502
/// while the daemon is down; everything else 404.
async fn proxy(listener: tokio::net::TcpListener, upstream: SocketAddr) {
    loop {
        let Ok((mut client, _)) = listener.accept().await else {
            return;
        };
        tokio::spawn(async move {
            let mut head = Vec::new();
            let mut buf = [0u8; 4096];
            while !head.windows(4).any(|w| w == b"\r\n\r\n") {
                match client.read(&mut buf).await {
                    Ok(0) | Err(_) => return,
                    Ok(n) => head.extend_from_slice(&buf[..n]),
                }
            }
            let text = String::from_utf8_lossy(&head).to_string();
            let mut parts = text.splitn(3, ' ');
            let (method, target, rest) = (
                parts.next().unwrap_or(""),
                parts.next().unwrap_or(""),
                parts.next().unwrap_or(""),
            );
            let Some(inner) = target.strip_prefix(PREFIX) else {
                let _ = client
                    .write_all(
                        b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
                    )
                    .await;
                return;
            };
            let inner = if inner.is_empty() { "/" } else { inner };
            let Ok(mut up) = tokio::net::TcpStream::connect(upstream).await else {
                let _ = client.write_all(b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\nConnection: close\r\n\r\n").await;
                return;
            };
            let rewritten = format!("{method} {inner} {rest}");
            if up.write_all(rewritten.as_bytes()).await.is_err() {
                return;
            }
            let _ = tokio::io::copy_bidirectional(&mut client, &mut up).await;
        });
    }
}

/// The daemon's default run (config/lightposed.toml: the simulated tank
/// with its attitude sensor, the tracker) at 20 Hz, to `dest`, with `web`.
fn default_simulation(dest: SocketAddr, web: &str) -> String {
    let text = std::fs::read_to_string(root().join("config/lightposed.toml")).unwrap();
    let text = text
        .replacen("rate_hz = 5.0", "rate_hz = 20.0", 1)
        .replace("127.0.0.1:17150", &dest.to_string());
    assert!(text.contains("rate_hz = 20.0") && text.contains(&dest.to_string()));
    format!("{text}\n{web}")
}

/// The first STATUS that says the page is served.
fn wait_web(sub: &std::net::UdpSocket) {
    for _ in 0..100 {
        if collect(sub, Duration::from_millis(100))
            .iter()
            .any(|v| v["web"]["listen"].is_string())
        {
            return;
        }
    }
    panic!("no STATUS with web.listen within 10 s");
}

#[test]
fn chromium_sees_the_page_live_under_a_prefix_and_through_a_restart_with_faults() {
    let out = Command::new(root().join("tools/browserenv.sh"))
        .output()
        .expect("tools/browserenv.sh runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr).trim()
    );
    let modules = String::from_utf8_lossy(&out.stdout).trim().to_string();

    let port = free_tcp_port();
    let (sub, dest) = subscriber();
    let web = format!("[web]\nlisten = \"127.0.0.1:{port}\"\n");
    let (daemon, stop) = start(&default_simulation(dest, &web));
    wait_web(&sub);

    let rt = tokio::runtime::Runtime::new().unwrap();
    let upstream: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let proxy_addr = listener.local_addr().unwrap();
    rt.spawn(proxy(listener, upstream));

    let shots = root().join("target/web-shots");
    std::fs::create_dir_all(&shots).unwrap();
    let url = format!("http://{proxy_addr}{PREFIX}/");
    let mut node = Command::new("node")
        .arg(root().join("crates/daemon/tests/web_browser.mjs"))
        .args([&modules, &url, &shots.display().to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("node runs");
    let mut lines = BufReader::new(node.stdout.take().unwrap()).lines();
    let first = lines.next().and_then(Result::ok).unwrap_or_default();
    if first != "RESTART" {
        let mut err = String::new();
        let _ = std::io::Read::read_to_string(&mut node.stderr.take().unwrap(), &mut err);
        panic!("the browser's first phase failed: {first} {err}");
    }

    // The daemon stops and comes back on the same port, now the mock
    // backend with its faults: every channel dark, a bus error every 10th frame.
    let _ = stop.send(());
    daemon.join().expect("daemon");
    let stuck: Vec<String> = (0..25)
        .map(|k| format!("{{ r = {}, c = {}, value = 0 }}", k / 5, k % 5))
        .collect();
    let faulty = sim_config(20.0, &[dest], "", &web)
        .replacen("kind = \"sim\"", "kind = \"mock\"", 1)
        .replacen(
            "[outputs]",
            &format!(
                "faults = {{ bus_error_every = 10, stuck = [{}] }}\n[outputs]",
                stuck.join(", ")
            ),
            1,
        );
    let (daemon, stop) = start(&faulty);
    node.stdin
        .as_mut()
        .unwrap()
        .write_all(b"RESTARTED\n")
        .unwrap();
    let result = lines.next().and_then(Result::ok).unwrap_or_default();
    let status = node.wait().expect("node ends");
    let _ = stop.send(());
    daemon.join().expect("daemon");
    let mut err = String::new();
    let _ = std::io::Read::read_to_string(&mut node.stderr.take().unwrap(), &mut err);
    assert!(
        status.success(),
        "the browser's second phase failed: {result} {err}"
    );

    let r: Value = serde_json::from_str(&result).expect("one JSON object");
    assert_eq!(r["scriptErrors"], serde_json::json!([]), "{r}");
    assert_eq!(r["pageErrors"], serde_json::json!([]), "{r}");
    assert_eq!(r["consoleErrors"], serde_json::json!([]), "{r}");
    assert!(r["rate"].as_f64() >= Some(5.0), "live events a second: {r}");
    assert!(r["distinctX"].as_u64() >= Some(5), "the pose changed: {r}");
    assert!(r["heatmap"]["drawn"].as_u64() >= Some(10), "{r}");
    assert!(
        r["heatmap"]["colours"].as_u64() >= Some(3),
        "a heatmap, not a blank: {r}"
    );
    assert!(r["trackPoints"].as_u64() >= Some(10), "{r}");
    assert_eq!(r["status"], "ok");
    assert!(
        r["estimatorTable"].as_str().unwrap().contains("tracker"),
        "{r}"
    );
    // Every request went under the prefix: the page's paths are relative.
    for u in r["requests"].as_array().unwrap() {
        assert!(
            u.as_str()
                .unwrap()
                .starts_with(&format!("http://{proxy_addr}{PREFIX}/")),
            "{u}"
        );
    }
    assert!(r["connects"].as_u64() >= Some(2), "reconnected: {r}");
    assert_eq!(r["faultStatus"], "no_light", "{r}");
    let why = r["why"].as_str().unwrap();
    assert!(why.contains("no_light: Too little light"), "{why}");
    assert!(why.contains("faults injected by the mock backend"), "{why}");
}
