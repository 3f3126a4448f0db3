//! The vehicle link's async side: one [`Hub`] shared by the MAVLink task,
//! the DVL client and the frame thread (whose ends are
//! [`crate::inputs::vehicle`] and [`crate::outputs::mavlink`]).
//!
//! The MAVLink link is opened here, before the daemon reports ready, so
//! that a port that is taken or a serial device that is not there fails
//! the start (exit 1: it may be fine after a restart); once running, the
//! task reopens a failed link with a back-off. The DVL is only connected
//! to, with its own back-off: it may boot after the daemon, and its
//! absence is counted in STATUS rather than fatal.

use crate::config::VehicleConfig;
use crate::error::DaemonError;
use lightpose_vehicle::{dvl, mav, Hub, Link};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// The running link tasks and their hub.
pub struct VehicleLink {
    pub hub: Arc<Hub>,
    /// The MAVLink socket's local address (UDP), for logs and tests.
    pub mavlink_local: Option<SocketAddr>,
    /// Dropping or sending one ends its task (its shutdown future).
    stops: Vec<oneshot::Sender<()>>,
    tasks: Vec<JoinHandle<()>>,
}

/// How long a stop waits for the tasks (they end at their next await).
const STOP_BOUND: Duration = Duration::from_secs(1);

/// A shutdown future for a task, and the sender that resolves it (also
/// when dropped, so a start that fails later leaves no task behind).
fn shutdown_pair() -> (oneshot::Sender<()>, impl std::future::Future<Output = ()>) {
    let (tx, rx) = oneshot::channel::<()>();
    (tx, async move {
        let _ = rx.await;
    })
}

/// Open the MAVLink link and start the tasks `cfg` asks for on the
/// current tokio runtime.
pub async fn start(cfg: &VehicleConfig) -> Result<VehicleLink, DaemonError> {
    let hub = Hub::new();
    let mut link = VehicleLink {
        hub: hub.clone(),
        mavlink_local: None,
        stops: Vec::new(),
        tasks: Vec::new(),
    };
    if let Some(m) = &cfg.mavlink {
        let opened = Link::open(&m.endpoint)
            .await
            .map_err(DaemonError::Mavlink)?;
        link.mavlink_local = opened.local_addr();
        tracing::info!(
            "mavlink: component {}/{} on {}",
            m.system_id,
            m.component_id,
            m.endpoint
        );
        let (tx, shutdown) = shutdown_pair();
        let task = mav::task::run_with(m.clone(), hub.clone(), Some(opened), shutdown);
        link.stops.push(tx);
        link.tasks.push(tokio::spawn(task));
    }
    if let Some(d) = &cfg.dvl {
        tracing::info!("dvl: reading {}", d.address);
        let (tx, shutdown) = shutdown_pair();
        link.stops.push(tx);
        link.tasks.push(tokio::spawn(dvl::client::run(
            d.clone(),
            hub.clone(),
            shutdown,
        )));
    }
    Ok(link)
}

impl VehicleLink {
    /// End the tasks (after the frame thread, so that its last poses go
    /// out); a task that does not end within a second is aborted.
    pub async fn stop(mut self) {
        for s in self.stops.drain(..) {
            let _ = s.send(());
        }
        for t in self.tasks.drain(..) {
            let abort = t.abort_handle();
            if tokio::time::timeout(STOP_BOUND, t).await.is_err() {
                abort.abort();
            }
        }
    }
}
