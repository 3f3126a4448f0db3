//! The frame thread hands frames to the MCAP recorder, to the live view
//! (with a client subscribed to every channel), to the web page's feed
//! (with a browser's feed open) and to the ROS 2 node (its DDS
//! participant on loopback) without allocating: a
//! counting allocator, counting on the frame thread only (the recorder
//! and encoder threads allocate per chunk and per message, off the hot
//! path), shows that the frame thread's allocations do not grow with the
//! number of frames. Beside it, on real sockets: the UDP publisher
//! meeting a destination where nobody listens, and the live view's hub
//! framing messages for several subscribed clients, allocate nothing per
//! datagram or message once warm.

use futures_util::{SinkExt, StreamExt};
use lightpose_hal::Stop;
use lightpose_testkit::alloc::Counting;
use lightposed::config::Config;
use lightposed::engine::Engine;
use lightposed::outputs::live;
use lightposed::outputs::recorder::{Epoch, Recorder};
use lightposed::outputs::udp::PoseDatagrams;
use lightposed::outputs::web;
use lightposed::Publisher;
use std::net::UdpSocket;
use std::path::Path;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message as Ws;

// Counted per thread (`A.this_thread`): the tests of this file run side by side.
#[global_allocator]
static A: Counting = Counting::new();

fn config(sink: &UdpSocket, rec: &Path) -> Config {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = format!(
        "rate_hz = 50.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{}\"]\n[recording]\ndir = \"{}\"\nformat = \"mcap\"\nflush_s = 0.05\n[foxglove]\nlisten = \"127.0.0.1:{}\"\n[web]\nlisten = \"127.0.0.1:0\"\n[ros2]\nnetworks = [\"127.0.0.1\"]\n",
        root.join("config/calibration/tank.toml").display(),
        root.join("config/scenes/tank-ahrs.toml").display(),
        root.join("config/trajectories/zigzag.csv").display(),
        sink.local_addr().expect("addr"),
        rec.display(),
        // Port 0 is refused by the config: a port free a moment ago.
        std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("probe port")
            .port()
    );
    Config::parse(&text, "noalloc.toml", None).expect("valid")
}

/// A client subscribed to every channel, reading all it gets.
async fn reader(addr: std::net::SocketAddr) {
    let mut req = format!("ws://{addr}").into_client_request().unwrap();
    req.headers_mut()
        .insert("sec-websocket-protocol", "foxglove.sdk.v1".parse().unwrap());
    let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let (mut ws, _) = tokio_tungstenite::client_async(req, tcp).await.unwrap();
    let subs: Vec<_> = (1..=7)
        .map(|i| serde_json::json!({"id": i, "channelId": i}))
        .collect();
    let msg = serde_json::json!({"op": "subscribe", "subscriptions": subs});
    ws.send(Ws::text(msg.to_string())).await.unwrap();
    while let Some(Ok(_)) = ws.next().await {}
}

/// A browser's live feed, read to its end.
async fn feed_reader(addr: std::net::SocketAddr) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(b"GET /v1/events HTTP/1.1\r\nHost: v\r\n\r\n")
        .await
        .unwrap();
    let mut buf = vec![0u8; 65536];
    while let Ok(n) = s.read(&mut buf).await {
        if n == 0 {
            break;
        }
    }
}

/// Allocations on the frame thread over `frames` frames.
fn allocations(frames: u64, rt: &tokio::runtime::Runtime) -> u64 {
    let sink = UdpSocket::bind("127.0.0.1:0").expect("sink");
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = config(&sink, dir.path());
    let source = lightposed::open_source(&cfg, &Stop::new()).expect("source");
    let header = lightpose_core::LogHeader::new(10, 50.0);
    let fx = cfg.foxglove.as_ref().expect("foxglove");
    let live = rt.block_on(live::start(fx, &header)).expect("live view");
    rt.spawn(reader(live.hub.listen));
    let page = rt
        .block_on(web::start(cfg.web.as_ref().expect("web"), None))
        .expect("web page");
    rt.spawn(feed_reader(page.feed.listen));
    let t0 = Instant::now();
    while !live.hub.wanted() && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(live.hub.wanted(), "the client subscribed");
    let rec_cfg = cfg.recording.as_ref().expect("recording");
    let epoch = Epoch::of(source.t_is_monotonic());
    let recorder = Recorder::start(rec_cfg, header, epoch).expect("recorder");
    let rec_stats = recorder.stats.clone();
    let publisher = Arc::new(Publisher::open(&cfg.outputs).expect("publisher"));
    let (ros2, node) = lightposed::outputs::ros2::start(cfg.ros2.as_ref().expect("ros2"), None)
        .expect("ros2 node");
    let engine = Engine::new(
        source,
        lightposed::build_estimator(&cfg).expect("estimator"),
    )
    .period(Some(Duration::from_millis(20)))
    .max_frames(frames)
    .output(Box::new(PoseDatagrams::new(publisher)))
    .output(Box::new(recorder))
    .output(Box::new(live.output))
    .output(Box::new(page.output))
    .output(Box::new(ros2));
    let (_, n) = A.this_thread(|| engine.run());
    live.server.abort();
    live.hub.close();
    page.feed.close();
    let handed = page.feed.handed.load(Relaxed) + page.feed.handoff_dropped.load(Relaxed);
    assert_eq!(handed, frames, "every frame offered to the page's feed");
    let r = &node.stats;
    let to_ros2 = r.handed.load(Relaxed) + r.handoff_dropped.load(Relaxed);
    assert_eq!(to_ros2, frames, "every frame offered to the ROS 2 node");
    // The node's thread publishes what it was handed, off the frame thread.
    let t0 = Instant::now();
    while r.published.load(Relaxed) + r.not_ok.load(Relaxed) < r.handed.load(Relaxed)
        && t0.elapsed() < Duration::from_secs(10)
    {
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(
        r.published.load(Relaxed) > 0,
        "ok poses published: {}",
        node.report()
    );
    assert!(
        page.feed.events.load(Relaxed) >= 1,
        "the page's feed ran: {}",
        page.feed.report()
    );
    assert_eq!(
        rec_stats.frames.load(Relaxed),
        frames,
        "every frame recorded"
    );
    n
}

#[test]
fn handing_frames_to_the_recorder_the_live_view_and_the_page_does_not_allocate() {
    // The counter counts this thread's allocations (else the test would
    // prove nothing).
    let (v, n) = A.this_thread(|| std::hint::black_box(Vec::<u8>::with_capacity(64)));
    drop(v);
    assert_eq!(n, 1);
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let few = allocations(50, &rt);
    let many = allocations(400, &rt);
    eprintln!("frame thread: {few} allocations for 50 frames, {many} for 400");
    assert!(
        many <= few + 2,
        "{few} allocations for 50 frames, {many} for 400"
    );
}

/// A destination where nobody listens refuses about every other datagram
/// (ECONNREFUSED): each refusal is counted and kept as the last error
/// without formatting it again (it was formatted twice per refusal).
#[test]
fn refused_datagrams_do_not_allocate() {
    let dir = tempfile::tempdir().expect("tempdir");
    let gone = UdpSocket::bind("127.0.0.1:0").expect("sink");
    let cfg = config(&gone, dir.path());
    drop(gone); // nobody listens there now
    let publisher = Publisher::open(&cfg.outputs).expect("publisher");
    let send = |n: u32| {
        for _ in 0..n {
            publisher.send(br#"{"class":"POSE"}"#);
            std::thread::sleep(Duration::from_micros(300));
        }
    };
    let errors = || publisher.destinations()[0].stats.errors.load(Relaxed);
    let ((), few) = A.this_thread(|| send(50));
    let e0 = errors();
    let ((), many) = A.this_thread(|| send(500));
    let refused = errors() - e0;
    eprintln!("refused sends: {few} allocations for 50 sends, {many} for 500 ({refused} refused)");
    assert!(refused >= 100, "{refused} of 500 sends refused");
    assert!(many <= 2, "{many} allocations for {refused} refused sends");
}

/// Three clients subscribed to every channel over real sockets: framing a
/// message for each of them does not allocate once warm (it was one
/// allocation per message per client).
#[test]
fn framing_for_subscribed_clients_does_not_allocate_per_message() {
    use lightpose_logs::{Channel, Message};
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let sink = UdpSocket::bind("127.0.0.1:0").expect("sink");
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = config(&sink, dir.path());
    let header = lightpose_core::LogHeader::new(10, 50.0);
    let fx = cfg.foxglove.as_ref().expect("foxglove");
    let live = rt.block_on(live::start(fx, &header)).expect("live view");
    for _ in 0..3 {
        rt.spawn(reader(live.hub.listen));
    }
    let subscribed = || {
        let r = live.hub.report();
        let list = r["client_list"].as_array().cloned().unwrap_or_default();
        list.len() == 3 && list.iter().all(|c| c["subscriptions"] == 7)
    };
    let t0 = Instant::now();
    while !subscribed() && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(subscribed(), "three clients subscribed to every channel");
    let data = [b'7'; 300];
    let publish = |n: u32| {
        for i in 0..n {
            live.hub.publish(&Message {
                channel: Channel::ALL[i as usize % 7],
                sequence: i,
                log_time: u64::from(i),
                data: &data,
            });
            if i % 16 == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    };
    publish(500); // warm: blocks, the clients' queues
    let ((), few) = A.this_thread(|| publish(200));
    let ((), many) = A.this_thread(|| publish(2000));
    // `sent` counts what a client has shown it read (it answered a ping
    // sent after it), a second or so behind what it was written.
    let t0 = Instant::now();
    while live.hub.report()["sent"].as_u64() <= Some(3000) && t0.elapsed() < Duration::from_secs(10)
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    let r = live.hub.report();
    live.server.abort();
    live.hub.close();
    eprintln!("hub: {few} allocations for 200 messages to 3 clients, {many} for 2000; {r}");
    assert!(r["sent"].as_u64() > Some(3000), "{r}");
    // Framed messages share 64 KiB blocks; one is taken back once its
    // clients have written every message in it. A client that lags (its
    // task starved on a loaded host) holds its blocks, and the next is then
    // new: at most one allocation per block filled (about 30 here, 8–11
    // seen under load), never one per message (6000 here).
    let blocks = (2000 * 3 * (13 + data.len() as u64)).div_ceil(64 << 10);
    assert!(
        many <= few + blocks,
        "{few} allocations for 200 messages, {many} for 2000 ({blocks} blocks filled)"
    );
}
