//! Talking to the rest of the vehicle: the autopilot over MAVLink 2 (its
//! attitude, depth and water temperature in, the pose out) and a Water
//! Linked DVL over TCP (its velocity in).
//!
//! It exists so that the daemon's two sides can share the vehicle without
//! waiting on each other: the I/O tasks run on tokio and leave their
//! readings in a [`Hub`]; the frame thread takes the fresh ones with
//! [`Readings::attach`] and hands each pose back with
//! [`PoseOutbox::offer`], neither of which allocates or blocks.
//!
//! ```text
//! tokio:  mav::task::run(settings, hub, shutdown)   dvl::client::run(settings, hub, shutdown)
//!             │ ATTITUDE, GLOBAL_POSITION_INT,             │ velocity reports
//!             │ SCALED_PRESSURE2                           │
//!             ▼                                            ▼
//!         hub.readings ── attach(&mut frame, capture) ─▶ frame thread ── estimate
//!         hub.outbox   ◀─── offer(&estimate, epoch) ────┘
//!             │ VISION_POSITION_ESTIMATE, VISION_SPEED_ESTIMATE, HEARTBEAT
//! ```
//!
//! The geometry between the beam frame B and the autopilot's NED frame is
//! in [`ned`] and [`covariance`]; FORMATS.md ("Vehicle integration") is
//! the contract and docs/vehicle.md the description of what is built.

pub mod backoff;
pub mod config;
pub mod covariance;
pub mod dvl;
pub mod latest;
pub mod mav;
pub mod ned;
pub mod readings;
pub mod stale;
pub mod standin;

pub use config::{ConfigError, DvlTable, MavlinkTable, SiteTable};
pub use dvl::client::DvlSettings;
pub use mav::link::{Endpoint, Link};
pub use mav::outbound::{MissingStd, Offer, OutputConfig, PoseOutbox, RestartCounter};
pub use mav::task::MavlinkSettings;
pub use ned::{NedPose, NedVec, Site};
pub use readings::{AssumedStd, Attached, AttitudeRates, MaxAge, Readings};

use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

/// What the I/O tasks and the frame thread share.
#[derive(Default)]
pub struct Hub {
    pub readings: Readings,
    pub outbox: PoseOutbox,
    pub mavlink: mav::counters::MavCounters,
    pub dvl: dvl::DvlCounters,
}

/// Everything about the vehicle link for the daemon's STATUS.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VehicleStatus {
    pub readings: readings::ReadingsStatus,
    pub outbox: mav::outbound::OutboxStatus,
    pub mavlink: mav::counters::MavlinkStatus,
    pub dvl: dvl::DvlStatus,
}

impl Hub {
    pub fn new() -> Arc<Hub> {
        Arc::new(Hub::default())
    }

    /// A snapshot for STATUS (allocates; not for the frame thread).
    pub fn status(&self, now: Instant) -> VehicleStatus {
        VehicleStatus {
            readings: self.readings.status(now),
            outbox: self.outbox.status(),
            mavlink: self.mavlink.status(now),
            dvl: self.dvl.status(),
        }
    }
}

/// Counts per name, serialized as a JSON object (`{"bad_crc": 3}`) rather
/// than a list of pairs: what a reader of STATUS looks a reason up by.
pub(crate) fn counts_as_map<S: serde::Serializer>(
    v: &[(&'static str, u64)],
    s: S,
) -> Result<S::Ok, S::Error> {
    s.collect_map(v.iter().map(|(k, n)| (*k, *n)))
}

/// An error and its causes on one line.
pub(crate) fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cause = c.source();
    }
    s
}
