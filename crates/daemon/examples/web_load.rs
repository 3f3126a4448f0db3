//! The web page's load bench (issue 43): what 200 page clients reading the
//! live feed, plus one client that asks for the feed and never reads, cost
//! the frame thread. The daemon runs in-process on the simulated tank at
//! `RATE` Hz, paced, for `SECONDS` without clients and then as long with
//! them; each phase's row is the POSE rate and the frame-to-output
//! latency p99 (from the last STATUS of the phase: its `recent` window),
//! frames late or failed, and the process's RSS at its end. Prints a
//! Markdown table (docs/blueos.md has the figures). Not a test: figures
//! depend on the machine.
//!
//!   cargo run --release -p lightposed --example web_load [CLIENTS] [SECONDS]

use lightposed::{Config, Publisher};
use serde_json::Value;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const RATE: f64 = 50.0;

fn rss_kib() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// Every STATUS and the POSE count that reach `sub` within `d`.
fn listen(sub: &UdpSocket, d: Duration) -> (Vec<Value>, u64) {
    let (mut status, mut poses) = (Vec::new(), 0);
    let mut buf = vec![0u8; 65536];
    let end = Instant::now() + d;
    while Instant::now() < end {
        let Ok(n) = sub.recv(&mut buf) else { continue };
        let Ok(v) = serde_json::from_slice::<Value>(&buf[..n]) else {
            continue;
        };
        match v["class"].as_str() {
            Some("POSE") => poses += 1,
            Some("STATUS") => status.push(v),
            _ => {}
        }
    }
    (status, poses)
}

async fn reader(addr: SocketAddr) -> u64 {
    let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else {
        return 0;
    };
    if s.write_all(b"GET /v1/events HTTP/1.1\r\nHost: v\r\n\r\n")
        .await
        .is_err()
    {
        return 0;
    }
    let mut buf = vec![0u8; 16384];
    let mut got = 0u64;
    while let Ok(n) = s.read(&mut buf).await {
        if n == 0 {
            break;
        }
        got += n as u64;
    }
    got
}

fn row(name: &str, sub: &UdpSocket, secs: u64) -> String {
    let (status, poses) = listen(sub, Duration::from_secs(secs));
    let last = status.last().cloned().unwrap_or(Value::Null);
    let p99 = last["latency"]["recent"]["p99"]
        .as_f64()
        .unwrap_or(f64::NAN)
        * 1e6;
    let web = &last["web"];
    format!(
        "| {name} | {:.1} | {:.0} | {} / {} | {} | {} | {:.1} |",
        poses as f64 / secs as f64,
        p99,
        last["late"],
        last["failed"],
        web["live_clients"],
        web["refused"],
        rss_kib() as f64 / 1024.0
    )
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let clients: usize = args.next().map_or(Ok(200), |a| a.parse())?;
    let secs: u64 = args.next().map_or(Ok(10), |a| a.parse())?;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let sub = UdpSocket::bind("127.0.0.1:0")?;
    sub.set_read_timeout(Some(Duration::from_millis(50)))?;
    let text = format!(
        "rate_hz = {RATE}\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\n[outputs]\ndestinations = [\"{}\"]\nstatus_interval_s = 1.0\n[web]\nlisten = \"127.0.0.1:0\"\nmax_clients = 256\nmax_clients_per_addr = 256\n",
        root.join("config/calibration/tank.toml").display(),
        root.join("config/scenes/tank-ahrs.toml").display(),
        root.join("config/trajectories/zigzag.csv").display(),
        sub.local_addr()?
    );
    let cfg = Config::parse(&text, "web_load.toml", None)?;
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let daemon = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()?;
        rt.block_on(async move {
            let p = Publisher::open(&cfg.outputs)?;
            lightposed::run(cfg, p, async move {
                let _ = stop_rx.await;
            })
            .await
            .map_err(anyhow::Error::from)
        })
    });
    // The page's address, from STATUS.
    let web: SocketAddr = loop {
        let (status, _) = listen(&sub, Duration::from_millis(200));
        if let Some(a) = status.iter().find_map(|v| v["web"]["listen"].as_str()) {
            break a.parse()?;
        }
    };
    println!("{RATE} Hz frames, {secs} s a phase, {clients} clients reading the feed and one that never reads\n");
    println!("| clients | POSE/s | latency p99 (µs) | late / failed | live feeds | refused | RSS (MiB) |");
    println!("|---|---|---|---|---|---|---|");
    let _ = listen(&sub, Duration::from_secs(2)); // warm
    println!("{}", row("none", &sub, secs));
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    let readers: Vec<_> = (0..clients).map(|_| rt.spawn(reader(web))).collect();
    // The client that never reads: its receive buffer small, so that the
    // server's writes to it block.
    let stuck = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None)?;
    stuck.set_recv_buffer_size(4096)?;
    stuck.connect(&web.into())?;
    let mut stuck: std::net::TcpStream = stuck.into();
    std::io::Write::write_all(&mut stuck, b"GET /v1/events HTTP/1.1\r\nHost: v\r\n\r\n")?;
    let _ = listen(&sub, Duration::from_secs(2)); // all connected
    println!("{}", row(&format!("{clients} + 1 stuck"), &sub, secs));
    let _ = stop_tx.send(());
    let summary = daemon
        .join()
        .map_err(|_| anyhow::anyhow!("daemon thread panicked"))??;
    let bytes: u64 = rt.block_on(async {
        let mut n = 0;
        for r in readers {
            n += r.await.unwrap_or(0);
        }
        n
    });
    println!(
        "\n{} frames, {} late, {} failed; the readers got {:.1} MB",
        summary.frames,
        summary.late,
        summary.failed,
        bytes as f64 / 1e6
    );
    Ok(())
}
