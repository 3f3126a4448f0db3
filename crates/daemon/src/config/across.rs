//! Checks across tables, once each has validated its own: two inputs on
//! one UDP port (each alone binds, but a start binds both, and the second
//! would fail as "in use"), and a destination that is one of the daemon's
//! own inputs (its POSE datagrams would come back as refused readings).
//! And one warning: an autopilot fed from a source that runs faster than
//! time.

use super::places::{self, Places};
use super::{AttitudeInput, ConfigError, Outputs, VehicleConfig};
use lightpose_hal::{Pace, ValidBackend};
use lightpose_vehicle::Endpoint;
use std::net::SocketAddr;

/// A UDP address the daemon listens on: its key, the address, and the
/// value as the file says it.
type Listener = (&'static str, SocketAddr, String);

fn udp_listeners(
    attitude: Option<&AttitudeInput>,
    vehicle: Option<&VehicleConfig>,
) -> Vec<Listener> {
    let mut out = Vec::new();
    if let Some(a) = attitude {
        out.push((places::ATTITUDE_LISTEN, a.listen, a.listen.to_string()));
    }
    let mavlink = vehicle
        .and_then(|v| v.mavlink.as_ref())
        .map(|m| &m.endpoint);
    if let Some(ep @ Endpoint::UdpIn(a)) = mavlink {
        out.push((places::MAVLINK, *a, ep.to_string()));
    }
    out
}

pub(super) fn validate(
    outputs: &Outputs,
    attitude: Option<&AttitudeInput>,
    vehicle: Option<&VehicleConfig>,
    at: &Places,
) -> Result<(), ConfigError> {
    let listeners = udp_listeners(attitude, vehicle);
    for (i, (key, a, this)) in listeners.iter().enumerate() {
        if let Some((other, _, that)) = listeners[..i].iter().find(|(_, b, _)| overlap(*a, *b)) {
            return Err(at.of(key).refuse(
                key,
                format!(
                    "{this} is the UDP port of {other} {that} ({}) again: a start would bind one and fail on the other; give each input its own port",
                    at.of(other)
                ),
            ));
        }
    }
    for (i, &d) in outputs.destinations.iter().enumerate() {
        if let Some((key, _, that)) = listeners.iter().find(|(_, l, _)| sends_to(d, *l)) {
            let here = places::destination(i);
            return Err(at.of(&here).refuse(
                "outputs.destinations",
                format!(
                    "{d} is the daemon's own input {key} {that} ({}): its own datagrams would come back to it as input",
                    at.of(key)
                ),
            ));
        }
    }
    Ok(())
}

/// A simulator or replay at `pace = "fast"` with `[mavlink]`: the
/// autopilot would get poses whose `usec` (the frame's `t`) runs many times
/// faster than its own clock, which its time-alignment takes for a lagging
/// source, and live readings of the autopilot's (attitude, depth) put on
/// frames from another time. Allowed (a bench with a simulated autopilot
/// may want it), said once at start.
pub(super) fn fast_source_to_autopilot(
    backend: &ValidBackend,
    vehicle: Option<&VehicleConfig>,
) -> Option<String> {
    let pace = match backend {
        ValidBackend::Sim(p) => p.pace,
        ValidBackend::Replay(p) => p.pace,
        _ => return None,
    };
    let mavlink = vehicle.and_then(|v| v.mavlink.as_ref())?;
    (pace == Pace::Fast).then(|| {
        format!(
            "backend {} at pace \"fast\" with [mavlink] {}: the autopilot gets poses faster than real time (usec runs ahead of its clock) and its live attitude and depth go on frames from another time; use pace = \"realtime\" to feed an autopilot",
            backend.kind(),
            mavlink.endpoint
        )
    })
}

/// Whether `x`, bound, takes `y`'s place: the unspecified address takes
/// every address of its family, `[::]` IPv4's too (Linux binds it dual
/// stack unless told otherwise).
fn covers(x: SocketAddr, y: SocketAddr) -> bool {
    x.ip().is_unspecified() && (x.is_ipv6() || y.ip().to_canonical().is_ipv4())
}

/// Two UDP sockets that could not both be bound (neither sets
/// SO_REUSEADDR).
fn overlap(a: SocketAddr, b: SocketAddr) -> bool {
    a.port() == b.port()
        && (a.ip().to_canonical() == b.ip().to_canonical() || covers(a, b) || covers(b, a))
}

/// Whether datagrams sent to `dest` arrive at a socket bound to `listen`
/// as far as the file tells: the same address, or a loopback one when it
/// listens on every address.
fn sends_to(dest: SocketAddr, listen: SocketAddr) -> bool {
    dest.port() == listen.port()
        && (dest.ip().to_canonical() == listen.ip().to_canonical()
            || (covers(listen, dest) && dest.ip().to_canonical().is_loopback()))
}

#[cfg(test)]
mod tests {
    use super::{overlap, sends_to};
    use std::net::SocketAddr;

    fn a(s: &str) -> SocketAddr {
        s.parse().expect("address")
    }

    #[test]
    fn overlap_follows_the_kernels_rules() {
        assert!(overlap(a("127.0.0.1:5"), a("127.0.0.1:5")));
        assert!(overlap(a("0.0.0.0:5"), a("127.0.0.1:5")));
        assert!(overlap(a("127.0.0.1:5"), a("[::]:5")));
        assert!(overlap(a("[::ffff:127.0.0.1]:5"), a("127.0.0.1:5")));
        assert!(!overlap(a("0.0.0.0:5"), a("[::1]:5")));
        assert!(!overlap(a("127.0.0.1:5"), a("127.0.0.2:5")));
        assert!(!overlap(a("127.0.0.1:5"), a("127.0.0.1:6")));
        assert!(sends_to(a("127.0.0.1:5"), a("0.0.0.0:5")));
        assert!(!sends_to(a("10.0.0.1:5"), a("0.0.0.0:5")));
        assert!(!sends_to(a("127.0.0.1:5"), a("127.0.0.1:6")));
    }
}
