//! Wiring: from a validated [`Config`] to a running daemon — the estimator
//! (from the calibration), the frame source (hal's one call), the inputs,
//! the outputs and the frame thread. Everything the supervisor then
//! watches is in [`Running`].

use crate::config::Config;
use crate::engine::{EndReason, Engine};
use crate::error::DaemonError;
use crate::inputs::attitude::{self, AttitudeCell, LatestAttitude};
use crate::inputs::vehicle::VehicleReadings;
use crate::notify::{notify, NotifyState};
use crate::outputs::live::{self, hub::Hub};
use crate::outputs::mavlink::ToAutopilot;
use crate::outputs::recorder::{RecStats, Recorder};
use crate::outputs::udp::{PoseDatagrams, Publisher};
use crate::outputs::StatusTap;
use crate::stats::Stats;
use crate::status::version_message;
use crate::vehicle::VehicleLink;
use lightpose_core::{Estimator, LogHeader};
use lightpose_hal::{FrameSource, Stop};
use lightpose_pipeline::Calibration;
use std::sync::Arc;
use std::time::Instant;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// Read and check the configured calibration.
fn load_calibration(cfg: &Config) -> Result<Calibration, DaemonError> {
    let text = cfg
        .calibration
        .read()
        .map_err(|source| DaemonError::CalibrationRead {
            at: cfg.calibration_at.clone(),
            source,
        })?;
    Ok(Calibration::parse(&text, &cfg.calibration.describe())?)
}

/// Load the calibration and build the configured estimator (at start and
/// on SIGHUP).
pub fn build_estimator(cfg: &Config) -> Result<Box<dyn Estimator>, DaemonError> {
    let cal = load_calibration(cfg)?;
    lightpose_pipeline::build_estimator(&cfg.estimator, &cal).map_err(|source| {
        DaemonError::Estimator {
            at: cfg.estimator_at.clone(),
            source,
        }
    })
}

/// The estimator can read the source's frames (the light model's ADC is
/// the source's; see `lightpose_pipeline::reads_frames_of`).
fn reads_frames(cfg: &Config, est: &dyn Estimator, adc_bits: u8) -> Result<(), DaemonError> {
    let cal = load_calibration(cfg)?;
    lightpose_pipeline::reads_frames_of(est, &cal, adc_bits).map_err(|msg| {
        DaemonError::AdcMismatch {
            backend: cfg.backend.kind(),
            msg,
        }
    })
}

/// Check everything a start would read, without starting: the calibration
/// (read, parsed, checked), the estimator built from it by name, and what
/// the backend reads (scene, trajectory, a log's header; hal opens no
/// device). `--check-config` runs this; a start fails on the same things
/// with the same errors.
pub fn check(cfg: &Config) -> Result<(), DaemonError> {
    build_estimator(cfg)?;
    lightpose_hal::check(&cfg.backend).map_err(|source| DaemonError::Backend {
        kind: cfg.backend.kind(),
        source,
    })
}

/// Open the configured frame source, whatever it is, through hal; its
/// waits end when `stop` is raised.
pub fn open_source(cfg: &Config, stop: &Stop) -> Result<Box<dyn FrameSource>, DaemonError> {
    lightpose_hal::open(&cfg.backend, stop).map_err(|source| DaemonError::Backend {
        kind: cfg.backend.kind(),
        source,
    })
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
    /// The MAVLink and DVL tasks and their hub, stopped after the frame
    /// thread.
    pub vehicle: Option<VehicleLink>,
    pub source: String,
    pub estimator: &'static str,
    /// Raised to stop the frame thread (and end its source's waits).
    pub stop: Stop,
    /// New estimators for the frame thread (calibration reloads).
    pub reload: std::sync::mpsc::Sender<Box<dyn Estimator>>,
    /// The frame thread; taken when it is joined.
    pub frames: Option<std::thread::JoinHandle<EndReason>>,
    /// Says when the frame thread has ended by itself.
    pub done: oneshot::Receiver<EndReason>,
}

/// Build everything `cfg` asks for, send VERSION, start the frame thread
/// and tell systemd the daemon is ready.
pub async fn start(cfg: &Config, publisher: Publisher) -> Result<Running, DaemonError> {
    let started = Instant::now();
    let estimator = build_estimator(cfg)?;
    let est_name = estimator.name();
    let stop = Stop::new();
    let source = open_source(cfg, &stop)?;
    reads_frames(cfg, estimator.as_ref(), source.adc_bits())?;
    let source_desc = source.describe();
    let publisher = Arc::new(publisher);
    let stats = Arc::new(Stats::default());
    let (attitude, listener) = match start_attitude(cfg).await? {
        Some((cell, task)) => (Some(cell), Some(task)),
        None => (None, None),
    };
    let vehicle = match &cfg.vehicle {
        Some(v) => Some(crate::vehicle::start(v).await?),
        None => None,
    };
    let header = log_header(cfg, source.as_ref(), &source_desc);
    let recorder = match &cfg.recording {
        Some(r) => Some(Recorder::start(r, header.clone()).map_err(DaemonError::Recorder)?),
        None => None,
    };
    let rec_stats = recorder.as_ref().map(|r| r.stats.clone());
    let mut status_taps: Vec<Box<dyn StatusTap>> = Vec::new();
    status_taps.extend(recorder.as_ref().map(Recorder::status_tap));
    let live =
        match &cfg.foxglove {
            Some(f) => Some(live::start(f, &header).await.map_err(|source| {
                DaemonError::FoxgloveListen {
                    addr: f.listen,
                    source,
                }
            })?),
            None => None,
        };

    let (reload_tx, reload_rx) = std::sync::mpsc::channel::<Box<dyn Estimator>>();
    let mut engine = Engine::new(source, estimator)
        .stats(stats.clone())
        .stop(stop.clone())
        .reload(reload_rx)
        .late_tolerance(cfg.late_tolerance)
        .fallback_temp_c(cfg.fallback_temp_c)
        .epoch(started)
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
    if let (Some(cell), Some(a)) = (&attitude, &cfg.attitude) {
        let max_age = a.max_age;
        engine = engine.input(Box::new(LatestAttitude {
            cell: cell.clone(),
            max_age,
        }));
    }

    publisher.send(&version_message(cfg, &source_desc, est_name));
    let (done_tx, done) = oneshot::channel::<EndReason>();
    let frames = std::thread::Builder::new()
        .name("lightposed-frames".into())
        .spawn(move || {
            let r = engine.run();
            let _ = done_tx.send(r.clone());
            r
        })
        .map_err(DaemonError::Thread)?;
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
        vehicle,
        source: source_desc,
        estimator: est_name,
        stop,
        reload: reload_tx,
        frames: Some(frames),
        done,
    })
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

/// The attitude input's socket and task, if configured.
async fn start_attitude(
    cfg: &Config,
) -> Result<Option<(Arc<AttitudeCell>, JoinHandle<()>)>, DaemonError> {
    let Some(a) = &cfg.attitude else {
        return Ok(None);
    };
    let sock = tokio::net::UdpSocket::bind(a.listen)
        .await
        .map_err(|source| DaemonError::AttitudeBind {
            addr: a.listen,
            source,
        })?;
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
    h
}
