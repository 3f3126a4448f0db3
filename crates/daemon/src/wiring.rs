//! Wiring: from a validated [`Config`] to a running daemon — the estimator
//! (from the calibration), the frame source (hal's one call), the inputs,
//! the outputs and the frame thread. Everything the supervisor then
//! watches is in [`Running`].

use crate::config::{machine, places, Config};
use crate::engine::{EndReason, Engine};
use crate::error::{report, DaemonError};
use crate::inputs::attitude::{self, AttitudeCell, LatestAttitude};
use crate::inputs::vehicle::VehicleReadings;
use crate::notify::{notify, NotifyState};
use crate::outputs::live::{self, hub::Hub};
use crate::outputs::mavlink::ToAutopilot;
use crate::outputs::recorder::{Epoch, RecStats, Recorder};
use crate::outputs::udp::{PoseDatagrams, Publisher};
use crate::outputs::web::{self, WebFeed};
use crate::outputs::StatusTap;
use crate::stats::Stats;
use crate::status::version_message;
use crate::vehicle::VehicleLink;
use lightpose_core::{Estimator, LogHeader};
use lightpose_hal::{FrameSource, HalError, Stop};
use lightpose_pipeline::Calibration;
use lightpose_vehicle::mav::link::LinkError;
use lightpose_vehicle::Endpoint;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

mod checks;
pub use checks::check;
use checks::demodulates;

/// Read and check the configured calibration.
fn load_calibration(cfg: &Config) -> Result<Calibration, DaemonError> {
    let text = cfg
        .calibration
        .read()
        .map_err(|source| DaemonError::CalibrationRead {
            at: cfg.calibration_at.clone(),
            source,
        })?;
    Calibration::parse(&text, &cfg.calibration.describe()).map_err(|source| {
        DaemonError::Calibration {
            at: cfg.calibration_at.clone(),
            source,
        }
    })
}

/// Load the calibration and build the configured estimator.
pub fn build_estimator(cfg: &Config) -> Result<Box<dyn Estimator>, DaemonError> {
    let cal = load_calibration(cfg)?;
    estimator_of(cfg, &cal)
}

fn estimator_of(cfg: &Config, cal: &Calibration) -> Result<Box<dyn Estimator>, DaemonError> {
    lightpose_pipeline::build_estimator(&cfg.estimator, cal).map_err(|source| {
        DaemonError::Estimator {
            at: cfg.estimator_at.clone(),
            source,
        }
    })
}

/// The configured estimator for frames of an `adc_bits` ADC (on SIGHUP;
/// a start builds it before opening the source and checks it after):
/// refused when the calibration's light model is of another ADC.
pub fn build_estimator_for(cfg: &Config, adc_bits: u8) -> Result<Box<dyn Estimator>, DaemonError> {
    estimator_and_calibration(cfg, adc_bits).map(|(est, _)| est)
}

pub(crate) fn estimator_and_calibration(
    cfg: &Config,
    adc_bits: u8,
) -> Result<(Box<dyn Estimator>, Calibration), DaemonError> {
    let cal = load_calibration(cfg)?;
    let est = estimator_of(cfg, &cal)?;
    reads_frames(cfg, est.as_ref(), &cal, adc_bits)?;
    Ok((est, cal))
}

/// Tell the vehicle readings the σ the estimator named `est` assumes for
/// a reading without a std (computed here, once: the frame thread only
/// reads it), so that a carried MAVLink reading goes on the frame with it
/// widened (`inputs::vehicle::assumed_std`).
pub(crate) fn assume_std(hub: Option<&lightpose_vehicle::Hub>, est: &str, cal: &Calibration) {
    if let Some(h) = hub {
        let s = crate::inputs::vehicle::assumed_std(est, cal.estimator.as_ref());
        h.readings.assume_std(Some(s));
    }
}

/// The estimator can read the source's frames (the light model's ADC is
/// the source's; see `lightpose_pipeline::reads_frames_of`).
fn reads_frames(
    cfg: &Config,
    est: &dyn Estimator,
    cal: &Calibration,
    adc_bits: u8,
) -> Result<(), DaemonError> {
    lightpose_pipeline::reads_frames_of(est, cal, adc_bits).map_err(|msg| {
        DaemonError::AdcMismatch {
            at: cfg.calibration_at.clone(),
            file: cfg.calibration.describe(),
            backend: cfg.backend.kind(),
            msg,
        }
    })
}

/// hal's refusal of a file the backend reads (a scene, a trajectory, a
/// replayed log) at the config's key that names it; any other as hal's.
fn backend_error(cfg: &Config, source: HalError) -> DaemonError {
    let key = match &source {
        HalError::Scene(_) => places::SCENE,
        HalError::Trajectory(_) => places::TRAJECTORY,
        HalError::Log(_) => places::LOG,
        _ => {
            return DaemonError::Backend {
                kind: cfg.backend.kind(),
                source,
            }
        }
    };
    DaemonError::Config(cfg.places.of(key).refuse(key, report(&source)))
}

/// The attitude input's bind failure, at `attitude.listen`'s line.
fn attitude_bind(cfg: &Config, addr: SocketAddr, e: std::io::Error) -> DaemonError {
    DaemonError::AttitudeBind {
        addr,
        source: machine::bind_refusal(addr, e),
    }
    .at(cfg.places.of(places::ATTITUDE_LISTEN))
}

/// The live view's failure to listen, at `foxglove.listen`'s line.
fn foxglove_bind(cfg: &Config, addr: SocketAddr, e: std::io::Error) -> DaemonError {
    DaemonError::FoxgloveListen {
        addr,
        source: machine::bind_refusal(addr, e),
    }
    .at(cfg.places.of(places::FOXGLOVE_LISTEN))
}

/// The web page, if `[web]` asks for it; a port that cannot be bound is
/// said at `web.listen`'s line.
async fn start_web(
    cfg: &Config,
    rec_stats: Option<&Arc<RecStats>>,
) -> Result<Option<web::WebParts>, DaemonError> {
    let Some(w) = &cfg.web else { return Ok(None) };
    let parts = web::start(w, recordings(cfg, rec_stats)).await;
    parts.map(Some).map_err(|e| web_bind(cfg, w.listen, e))
}

/// The web page's ends: its feed takes each frame (after the others) and
/// each STATUS.
fn plug_web(
    engine: Engine,
    web: Option<web::WebParts>,
    taps: &mut Vec<Box<dyn StatusTap>>,
) -> (Engine, Option<Arc<WebFeed>>, Option<JoinHandle<()>>) {
    let Some(w) = web else {
        return (engine, None, None);
    };
    taps.push(Box::new(w.feed.clone()));
    (
        engine.output(Box::new(w.output)),
        Some(w.feed),
        Some(w.server),
    )
}

/// The ROS 2 node, with `[ros2]`: its participant made here (a failure
/// exits before the frame thread, said at the table), its output after
/// the others, its STATUS end a tap.
#[cfg(feature = "ros2")]
fn plug_ros2(
    engine: Engine,
    cfg: &Config,
    taps: &mut Vec<Box<dyn StatusTap>>,
) -> Result<(Engine, Option<Arc<crate::outputs::ros2::Ros2Node>>), DaemonError> {
    let Some(r) = &cfg.ros2 else {
        return Ok((engine, None));
    };
    let (out, node) =
        crate::outputs::ros2::start(r, cfg.site.as_ref()).map_err(DaemonError::Ros2)?;
    taps.push(Box::new(node.clone()));
    let mut engine = engine.output(Box::new(out));
    if let (Some(cell), Some(i)) = (&node.imu, &r.imu) {
        engine = engine.input(Box::new(crate::inputs::attitude::LatestAttitude::new(
            cell.clone(),
            i.max_age,
        )));
    }
    // Depth and DVL: a hub of their own, attached with [ros2]'s ages (the
    // config allows no second depth or DVL input).
    if let Some(rd) = &node.readings {
        engine = engine.input(Box::new(VehicleReadings {
            hub: rd.hub.clone(),
            max_age: rd.max_age(),
        }));
    }
    Ok((engine, Some(node)))
}

/// The ROS 2 depth and DVL inputs' hub, if any (told the assumed σ as the
/// vehicle link's is).
#[cfg(feature = "ros2")]
pub(crate) fn ros2_hub(
    node: Option<&crate::outputs::ros2::Ros2Node>,
) -> Option<Arc<lightpose_vehicle::Hub>> {
    node?.readings.as_ref().map(|r| r.hub.clone())
}

/// The recorder as the web page sees it (its folder, its counters).
fn recordings(cfg: &Config, stats: Option<&Arc<RecStats>>) -> Option<web::Recordings> {
    let (r, s) = (cfg.recording.as_ref()?, stats?);
    Some(web::Recordings {
        dir: r.dir.clone(),
        stats: s.clone(),
    })
}

/// The web page's failure to listen, at `web.listen`'s line.
fn web_bind(cfg: &Config, addr: SocketAddr, e: std::io::Error) -> DaemonError {
    DaemonError::WebListen {
        addr,
        source: machine::bind_refusal(addr, e),
    }
    .at(cfg.places.of(places::WEB_LISTEN))
}

fn mavlink_endpoint(cfg: &Config) -> Option<&Endpoint> {
    let m = cfg.vehicle.as_ref().and_then(|v| v.mavlink.as_ref());
    m.map(|m| &m.endpoint)
}

/// A MAVLink link that could not be opened, at `mavlink.connection`'s
/// line; any other error as it is.
fn mavlink_at(cfg: &Config, e: DaemonError) -> DaemonError {
    let DaemonError::Mavlink(link) = e else {
        return e;
    };
    let listen = mavlink_endpoint(cfg).and_then(Endpoint::listen_addr);
    let link = match (link, listen) {
        (LinkError::Socket { endpoint, source }, Some(a)) => LinkError::Socket {
            endpoint,
            source: machine::bind_refusal(a, source),
        },
        (LinkError::Tcp { endpoint, source }, Some(a)) => LinkError::Tcp {
            endpoint,
            source: machine::bind_refusal(a, source),
        },
        (link, _) => link,
    };
    DaemonError::Mavlink(link).at(cfg.places.of(places::MAVLINK))
}

/// Open the configured frame source, whatever it is, through hal; its
/// waits end when `stop` is raised.
pub fn open_source(cfg: &Config, stop: &Stop) -> Result<Box<dyn FrameSource>, DaemonError> {
    lightpose_hal::open(&cfg.backend, stop).map_err(|e| backend_error(cfg, e))
}

/// A daemon whose frame thread runs, and what the supervisor needs of it.
pub struct Running {
    pub started: Instant,
    pub publisher: Arc<Publisher>,
    pub stats: Arc<Stats>,
    pub rec_stats: Option<Arc<RecStats>>,
    pub attitude: Option<Arc<AttitudeCell>>,
    /// The attitude input's socket task, aborted at stop.
    pub listener: Option<JoinHandle<()>>,
    /// Outputs that also take each STATUS (MCAP recording, live view).
    pub status_taps: Vec<Box<dyn StatusTap>>,
    /// The live view's clients (STATUS, closed at stop) and its accept
    /// task (aborted at stop).
    pub live: Option<Arc<Hub>>,
    pub live_server: Option<JoinHandle<()>>,
    /// The web page's feed (STATUS, closed at stop) and its accept task
    /// (aborted at stop).
    pub web: Option<Arc<WebFeed>>,
    pub web_server: Option<JoinHandle<()>>,
    /// The ROS 2 node's counters and STATUS end.
    #[cfg(feature = "ros2")]
    pub ros2: Option<Arc<crate::outputs::ros2::Ros2Node>>,
    /// The MAVLink and DVL tasks and their hub, stopped after the frame
    /// thread.
    pub vehicle: Option<VehicleLink>,
    pub source: String,
    /// The ADC of the source's frames (a reloaded calibration must match).
    pub adc_bits: u8,
    pub estimator: &'static str,
    /// Raised to stop the frame thread (and end its source's waits).
    pub stop: Stop,
    /// New estimators for the frame thread (calibration reloads).
    pub reload: std::sync::mpsc::Sender<Box<dyn Estimator>>,
    /// The calibration the running estimator was built from (a reload
    /// of the same is no reload).
    pub calibration: Option<Calibration>,
    /// The frame thread; taken when it is joined.
    pub frames: Option<std::thread::JoinHandle<EndReason>>,
    /// Says when the frame thread has ended by itself.
    pub done: oneshot::Receiver<EndReason>,
}

/// The recorder and the Foxglove live view `cfg` asks for, each started
/// (its file opened, its port bound) before the first frame.
async fn start_recording(
    cfg: &Config,
    header: &LogHeader,
    epoch: Epoch,
) -> Result<(Option<Recorder>, Option<live::Live>), DaemonError> {
    let recorder = match &cfg.recording {
        Some(r) => Some(Recorder::start(r, header.clone(), epoch).map_err(DaemonError::Recorder)?),
        None => None,
    };
    let live = match &cfg.foxglove {
        Some(f) => Some(
            live::start(f, header)
                .await
                .map_err(|e| foxglove_bind(cfg, f.listen, e))?,
        ),
        None => None,
    };
    Ok((recorder, live))
}

/// Build everything `cfg` asks for, send VERSION, start the frame thread
/// and tell systemd the daemon is ready.
pub async fn start(cfg: &Config, publisher: Publisher) -> Result<Running, DaemonError> {
    let started = Instant::now();
    // The calibration before any device: a refused one exits 2 (no restart).
    let cal = load_calibration(cfg)?;
    let estimator = estimator_of(cfg, &cal)?;
    let est_name = estimator.name();
    let stop = Stop::new();
    let source = open_source(cfg, &stop)?;
    let adc_bits = source.adc_bits();
    reads_frames(cfg, estimator.as_ref(), &cal, adc_bits)?;
    demodulates(cfg, source.as_ref())?;
    let source_desc = source.describe();
    let publisher = Arc::new(publisher);
    let stats = Arc::new(Stats::default());
    let (attitude, listener) = match start_attitude(cfg).await? {
        Some((cell, task)) => (Some(cell), Some(task)),
        None => (None, None),
    };
    let vehicle = start_vehicle(cfg).await?;
    assume_std(vehicle.as_ref().map(|v| &*v.hub), est_name, &cal);
    let header = log_header(cfg, source.as_ref(), &source_desc);
    // What the recording's clock record says its log time counts from.
    let epoch = Epoch::of(source.t_is_monotonic());
    let (recorder, live) = start_recording(cfg, &header, epoch).await?;
    let rec_stats = recorder.as_ref().map(|r| r.stats.clone());
    let mut status_taps: Vec<Box<dyn StatusTap>> = Vec::new();
    status_taps.extend(recorder.as_ref().map(Recorder::status_tap));

    let web_parts = start_web(cfg, rec_stats.as_ref()).await?;

    let (reload_tx, reload_rx) = std::sync::mpsc::channel::<Box<dyn Estimator>>();
    let mut engine = Engine::new(source, estimator)
        .stats(stats.clone())
        .stop(stop.clone())
        .reload(reload_rx)
        .late_tolerance(cfg.late_tolerance)
        .fallback_temp_c(cfg.fallback_temp_c)
        // The POSE first, so that it leaves as soon as it can.
        .output(Box::new(PoseDatagrams::new(publisher.clone())));
    engine = plug_vehicle(engine, cfg, vehicle.as_ref());
    if let Some(r) = recorder {
        engine = engine.output(Box::new(r));
    }
    let (live, live_server) = match live {
        Some(l) => {
            status_taps.push(Box::new(l.hub.clone()));
            engine = engine.output(Box::new(l.output));
            (Some(l.hub), Some(l.server))
        }
        None => (None, None),
    };
    let (web, web_server);
    (engine, web, web_server) = plug_web(engine, web_parts, &mut status_taps);
    #[cfg(feature = "ros2")]
    let (mut engine, ros2) = plug_ros2(engine, cfg, &mut status_taps)?;
    #[cfg(feature = "ros2")]
    assume_std(ros2_hub(ros2.as_deref()).as_deref(), est_name, &cal);
    // The ROS 2 IMU is the attitude input (the config allows one).
    #[cfg(feature = "ros2")]
    let attitude = attitude.or_else(|| ros2.as_ref().and_then(|n| n.imu.clone()));
    if let (Some(cell), Some(a)) = (&attitude, &cfg.attitude) {
        let max_age = a.max_age;
        engine = engine.input(Box::new(LatestAttitude::new(cell.clone(), max_age)));
    }

    publisher.send(&version_message(cfg, &source_desc, est_name));
    let (frames, done) = spawn_frames(engine)?;
    notify(&[NotifyState::Ready]);
    tracing::info!("running: {source_desc}; estimator {est_name}");
    Ok(Running {
        started,
        publisher,
        stats,
        rec_stats,
        attitude,
        listener,
        status_taps,
        live,
        live_server,
        web,
        web_server,
        #[cfg(feature = "ros2")]
        ros2,
        vehicle,
        source: source_desc,
        adc_bits,
        estimator: est_name,
        stop,
        reload: reload_tx,
        calibration: Some(cal),
        frames: Some(frames),
        done,
    })
}

/// The frame thread, running `engine`; the receiver says when it ended by
/// itself (dropped unsent: it panicked).
type FrameThread = (
    std::thread::JoinHandle<EndReason>,
    oneshot::Receiver<EndReason>,
);

fn spawn_frames(engine: Engine) -> Result<FrameThread, DaemonError> {
    let (done_tx, done) = oneshot::channel::<EndReason>();
    let frames = std::thread::Builder::new()
        .name("lightposed-frames".into())
        .spawn(move || {
            let r = engine.run();
            let _ = done_tx.send(r.clone());
            r
        })
        .map_err(DaemonError::Thread)?;
    Ok((frames, done))
}

/// The vehicle link's ends on the frame thread: its readings before the
/// estimator (the JSON attitude input is added after it: a frame takes the
/// first fresh reading), and, with `[mavlink]`, the pose to the autopilot
/// right after the POSE datagram.
fn plug_vehicle(mut engine: Engine, cfg: &Config, vehicle: Option<&VehicleLink>) -> Engine {
    let (Some(v), Some(vc)) = (vehicle, &cfg.vehicle) else {
        return engine;
    };
    engine = engine.input(Box::new(VehicleReadings {
        hub: v.hub.clone(),
        max_age: vc.max_age,
    }));
    if vc.mavlink.is_some() {
        engine = engine.output(Box::new(ToAutopilot::new(v.hub.clone())));
    }
    engine
}

/// The MAVLink and DVL tasks, if configured; a link that cannot be opened
/// is said at `mavlink.connection`'s line.
async fn start_vehicle(cfg: &Config) -> Result<Option<VehicleLink>, DaemonError> {
    let Some(v) = &cfg.vehicle else {
        return Ok(None);
    };
    if let Some(b) = &v.blueos {
        ask_blueos(b).await;
    }
    let link = crate::vehicle::start(v).await;
    link.map(Some).map_err(|e| mavlink_at(cfg, e))
}

/// BlueOS's autopilot manager asked for the daemon's MAVLink endpoint. A
/// manager that does not answer (BlueOS still starting, an older BlueOS)
/// fails nothing: the link opens as configured and the line says how to
/// add the endpoint by hand.
async fn ask_blueos(b: &crate::blueos::BlueosEndpoint) {
    let what = format!("{} {}:{}", b.connection_type, b.place, b.argument);
    match crate::blueos::ask(b).await {
        Ok(crate::blueos::Asked::Created) => {
            tracing::info!("BlueOS: the autopilot manager at {} added the MAVLink endpoint {what}", b.url)
        }
        Ok(crate::blueos::Asked::Present) => {
            tracing::info!("BlueOS: the autopilot manager at {} has the MAVLink endpoint {what} already", b.url)
        }
        Err(e) => tracing::warn!(
            "BlueOS: could not ask the autopilot manager at {} for the MAVLink endpoint {what}: {e}; the link opens all the same: add the endpoint in BlueOS (Autopilot Endpoints) by hand (docs/blueos.md)",
            b.url
        ),
    }
}

/// The attitude input's socket and task, if configured.
async fn start_attitude(
    cfg: &Config,
) -> Result<Option<(Arc<AttitudeCell>, JoinHandle<()>)>, DaemonError> {
    let Some(a) = &cfg.attitude else {
        return Ok(None);
    };
    let sock = tokio::net::UdpSocket::bind(a.listen)
        .await
        .map_err(|e| attitude_bind(cfg, a.listen, e))?;
    let cell = Arc::new(AttitudeCell::default());
    tracing::info!("attitude input on {}", a.listen);
    let task = tokio::spawn(attitude::listen(sock, a.clone(), cell.clone()));
    Ok(Some((cell, task)))
}

/// The header of the daemon's recordings (and of the live view's frames):
/// it names this daemon and the source, at the rate of the source's clock.
fn log_header(cfg: &Config, source: &dyn FrameSource, source_desc: &str) -> LogHeader {
    let mut h = LogHeader::new(source.adc_bits(), source.rate_hz().unwrap_or(cfg.rate_hz));
    h.extra.insert(
        "recorder".into(),
        format!("lightposed {}", env!("CARGO_PKG_VERSION")).into(),
    );
    h.extra.insert("source".into(), source_desc.into());
    if let Some(s) = source.sampling() {
        // What a replay's demodulator is set up from (FORMATS.md): the
        // recording's frames are BURSTs or demodulated frames of it.
        crate::engine::demod::header_fields(&mut h, &s);
    }
    h
}
