//! The autopilot's MAVLink 2 link (ArduSub, PX4): frames found and checked
//! (`scan`), the autopilot's messages turned into readings (`inbound`), the
//! poses turned into messages (`outbound`), the transports (`link`), what
//! happened (`counters`), signatures made and checked (`signing`), and the
//! task that runs it all (`task`).

pub mod counters;
pub mod inbound;
pub mod link;
pub mod outbound;
pub mod scan;
mod sender;
pub mod signing;
mod skips;
pub mod task;
