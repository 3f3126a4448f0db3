//! The frame thread hands frames to the MCAP recorder and to the live view
//! (with a client subscribed to every channel) without allocating: a
//! counting allocator, counting on the frame thread only (the recorder
//! and encoder threads allocate per chunk and per message, off the hot
//! path), shows that the frame thread's allocations do not grow with the
//! number of frames.

use futures_util::{SinkExt, StreamExt};
use lightpose_hal::Stop;
use lightposed::config::Config;
use lightposed::engine::Engine;
use lightposed::outputs::live;
use lightposed::outputs::recorder::Recorder;
use lightposed::outputs::udp::PoseDatagrams;
use lightposed::Publisher;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::net::UdpSocket;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message as Ws;

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);
thread_local! {
    static COUNT_HERE: Cell<bool> = const { Cell::new(false) };
}

fn counting() -> bool {
    COUNT_HERE.try_with(Cell::get).unwrap_or(false)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if counting() {
            ALLOCS.fetch_add(1, Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if counting() {
            ALLOCS.fetch_add(1, Relaxed);
        }
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

fn config(sink: &UdpSocket, rec: &Path) -> Config {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = format!(
        "rate_hz = 50.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{}\"]\n[recording]\ndir = \"{}\"\nformat = \"mcap\"\nflush_s = 0.05\n[foxglove]\nlisten = \"127.0.0.1:{}\"\n",
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
    let t0 = Instant::now();
    while !live.hub.wanted() && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(live.hub.wanted(), "the client subscribed");
    let rec_cfg = cfg.recording.as_ref().expect("recording");
    let recorder = Recorder::start(rec_cfg, header).expect("recorder");
    let rec_stats = recorder.stats.clone();
    let publisher = Arc::new(Publisher::open(&cfg.outputs).expect("publisher"));
    let engine = Engine::new(
        source,
        lightposed::build_estimator(&cfg).expect("estimator"),
    )
    .period(Some(Duration::from_millis(20)))
    .max_frames(frames)
    .output(Box::new(PoseDatagrams::new(publisher)))
    .output(Box::new(recorder))
    .output(Box::new(live.output));
    ALLOCS.store(0, Relaxed);
    COUNT_HERE.with(|c| c.set(true));
    engine.run();
    COUNT_HERE.with(|c| c.set(false));
    let n = ALLOCS.load(Relaxed);
    live.server.abort();
    live.hub.close();
    assert_eq!(
        rec_stats.frames.load(Relaxed),
        frames,
        "every frame recorded"
    );
    n
}

#[test]
fn handing_frames_to_the_recorder_and_the_live_view_does_not_allocate() {
    // The counter counts this thread's allocations (else the test would
    // prove nothing).
    COUNT_HERE.with(|c| c.set(true));
    let v = std::hint::black_box(Vec::<u8>::with_capacity(64));
    COUNT_HERE.with(|c| c.set(false));
    drop(v);
    assert_eq!(ALLOCS.swap(0, Relaxed), 1);
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let few = allocations(50, &rt);
    let many = allocations(400, &rt);
    eprintln!("frame thread: {few} allocations for 50 frames, {many} for 400");
    assert!(
        many <= few + 2,
        "{few} allocations for 50 frames, {many} for 400"
    );
}
