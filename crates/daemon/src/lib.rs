//! lightposed as a library: [`run`] takes a validated [`Config`], the
//! publishing sockets and a shutdown future, so that tests can run a whole
//! daemon in-process on port-0 sockets and stop it when they like (the
//! mini-redis layout); the binary only parses arguments, loads the config
//! and maps errors to an exit code.
//!
//! - [`config`]: the file, validated per table into [`Config`];
//! - [`wiring`]: from a config to a running daemon (estimator, source,
//!   inputs, outputs, the frame thread);
//! - [`engine`]: the per-frame path on its own thread;
//! - [`inputs`]: readings that ride with frames (attitude, the vehicle's);
//! - [`outputs`]: where each frame and estimate go (UDP, recording, the
//!   autopilot);
//! - [`vehicle`]: the MAVLink and DVL tasks and their shared hub;
//!   [`blueos`]: BlueOS's autopilot manager asked for their endpoint;
//! - [`supervisor`]: signals, reloads, STATUS and the watchdog;
//! - [`status`], [`stats`], [`notify`]: STATUS/VERSION, the counters
//!   behind them, systemd;
//! - [`error`]: [`DaemonError`] and the one-line [`error::report`];
//! - [`bench`]: `--bench` and `--soak`.

pub mod bench;
pub mod bench_source;
pub mod blueos;
pub mod config;
pub mod engine;
pub mod error;
pub mod inputs;
pub mod notify;
pub mod outputs;
pub mod reload;
pub mod stats;
pub mod status;
pub mod supervisor;
pub mod vehicle;
pub mod wiring;

pub use config::{Config, ConfigError};
pub use error::DaemonError;
pub use outputs::udp::Publisher;
pub use status::PROTO;
pub use wiring::{build_estimator, open_source};

use std::future::Future;

/// What a run did, for the caller's last log line and for tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Summary {
    pub frames: u64,
    pub late: u64,
    pub failed: u64,
    pub lost: u64,
    pub recorded: u64,
    pub source_ended: bool,
}

/// Run the daemon until `shutdown` completes or the source ends.
pub async fn run(
    cfg: Config,
    publisher: Publisher,
    shutdown: impl Future<Output = ()>,
) -> Result<Summary, DaemonError> {
    let (_tx, rx) = tokio::sync::mpsc::channel(1);
    run_with_reload(cfg, publisher, shutdown, rx).await
}

/// As [`run`], and each message on `reload` reloads the calibration
/// (SIGHUP in the binary). A calibration that fails to load is reported and
/// the running one is kept.
pub async fn run_with_reload(
    cfg: Config,
    publisher: Publisher,
    shutdown: impl Future<Output = ()>,
    reload: tokio::sync::mpsc::Receiver<()>,
) -> Result<Summary, DaemonError> {
    let running = wiring::start(&cfg, publisher).await?;
    Ok(supervisor::supervise(&cfg, running, shutdown, reload).await)
}
