//! Optional attitude input: the vehicle's AHRS sends
//! `{"class":"ATTITUDE","t":..,"pitch":..,"yaw":..}` over UDP; yaw is the
//! compass heading, referred here to the beam frame with the beacon's axis
//! heading so that each frame carries pitch and yaw in B (MODEL.md), which is
//! what lets an estimator tell y from yaw and z from pitch.

use super::Input;
use crate::config::AttitudeInput;
use lightpose_core::{Angle, AttitudeReading, Frame};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The latest reading, written by the listener and read once per frame.
#[derive(Default)]
pub struct AttitudeCell {
    latest: Mutex<Option<(Instant, AttitudeReading)>>,
    pub received: AtomicU64,
    pub rejected: AtomicU64,
}

impl AttitudeCell {
    pub fn store(&self, at: Instant, r: AttitudeReading) {
        if let Ok(mut g) = self.latest.lock() {
            *g = Some((at, r));
        }
        self.received.fetch_add(1, Relaxed);
    }

    /// The latest reading if it is younger than `max_age` at `now`.
    #[inline]
    pub fn fresh(&self, now: Instant, max_age: Duration) -> Option<AttitudeReading> {
        let g = self.latest.lock().ok()?;
        let (at, r) = (*g)?;
        (now.saturating_duration_since(at) <= max_age).then_some(r)
    }

    /// Age of the latest reading, for STATUS.
    pub fn age(&self, now: Instant) -> Option<Duration> {
        let g = self.latest.lock().ok()?;
        g.map(|(at, _)| now.saturating_duration_since(at))
    }
}

/// The engine's end of the cell: the latest reading, attached to a frame
/// that has none when it is younger than `max_age`.
pub struct LatestAttitude {
    pub cell: std::sync::Arc<AttitudeCell>,
    pub max_age: Duration,
}

impl Input for LatestAttitude {
    #[inline]
    fn attach(&mut self, frame: &mut Frame, now: Instant) {
        // Frames with their own reading (a replayed log) keep it; those
        // that carry one are counted by the engine (STATUS frames_with).
        if frame.attitude.is_none() {
            frame.attitude = self.cell.fresh(now, self.max_age);
        }
    }
}

/// Wrap degrees into (−180, 180].
pub fn wrap180(deg: f64) -> f64 {
    let r = deg.rem_euclid(360.0);
    if r > 180.0 {
        r - 360.0
    } else {
        r
    }
}

/// Parse one ATTITUDE datagram into a reading in B.
///
/// A vehicle that faces the beacon (yaw 0 in B) heads opposite to the
/// beacon's axis, and a turn to starboard raises both the compass heading
/// and yaw in B: ψ_B = heading − (axis heading + 180°).
pub fn parse(datagram: &[u8], beacon_axis_heading_deg: f64) -> Result<AttitudeReading, String> {
    #[derive(serde::Deserialize)]
    struct Msg {
        class: String,
        pitch: f64,
        yaw: f64,
    }
    let m: Msg =
        serde_json::from_slice(datagram).map_err(|e| format!("not an ATTITUDE message: {e}"))?;
    if m.class != "ATTITUDE" {
        return Err(format!("class \"{}\" is not ATTITUDE", m.class));
    }
    if !m.pitch.is_finite() || !m.yaw.is_finite() || m.pitch.abs() > 90.0 {
        return Err(format!("pitch {} / yaw {} out of range", m.pitch, m.yaw));
    }
    Ok(AttitudeReading {
        pitch: Angle::from_deg(m.pitch),
        yaw: Angle::from_deg(wrap180(m.yaw - beacon_axis_heading_deg - 180.0)),
        std: None,
    })
}

/// Receive ATTITUDE datagrams until the task is dropped.
pub async fn listen(
    sock: tokio::net::UdpSocket,
    cfg: AttitudeInput,
    cell: std::sync::Arc<AttitudeCell>,
) {
    let mut buf = [0u8; 2048];
    loop {
        let (n, from) = match sock.recv_from(&mut buf).await {
            Ok(x) => x,
            Err(e) => {
                tracing::warn!("attitude: receive failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        match parse(&buf[..n], cfg.beacon_axis_heading_deg) {
            Ok(r) => cell.store(Instant::now(), r),
            Err(e) => {
                let k = cell.rejected.fetch_add(1, Relaxed) + 1;
                if k == 1 || k.is_multiple_of(100) {
                    tracing::warn!(from = %from, rejected = k, "attitude: {e}");
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heading_is_referred_to_the_beam() {
        // Beam points north (0°): facing the beacon is heading 180° = yaw 0.
        let r = parse(
            br#"{"class":"ATTITUDE","t":1.0,"pitch":5.0,"yaw":180.0}"#,
            0.0,
        )
        .unwrap();
        assert!(r.yaw.deg().abs() < 1e-9);
        assert!((r.pitch.deg() - 5.0).abs() < 1e-9);
        // Heading 190° is 10° to starboard of facing the beacon.
        let r = parse(br#"{"class":"ATTITUDE","t":1.0,"pitch":0,"yaw":190}"#, 0.0).unwrap();
        assert!((r.yaw.deg() - 10.0).abs() < 1e-9);
        // Beam points east (90°): facing it is heading 270°; 265° is −5°.
        let r = parse(br#"{"class":"ATTITUDE","t":0,"pitch":0,"yaw":265}"#, 90.0).unwrap();
        assert!((r.yaw.deg() + 5.0).abs() < 1e-9);
    }

    #[test]
    fn bad_datagrams_are_refused_with_reason() {
        assert!(parse(b"garbage", 0.0)
            .unwrap_err()
            .contains("not an ATTITUDE"));
        assert!(parse(br#"{"class":"POSE","pitch":0,"yaw":0}"#, 0.0)
            .unwrap_err()
            .contains("POSE"));
        assert!(parse(br#"{"class":"ATTITUDE","pitch":100,"yaw":0}"#, 0.0).is_err());
    }

    #[test]
    fn stale_readings_are_not_fresh() {
        let c = AttitudeCell::default();
        let t0 = Instant::now();
        assert!(c.fresh(t0, Duration::from_secs(1)).is_none());
        c.store(
            t0,
            AttitudeReading {
                pitch: Angle::ZERO,
                yaw: Angle::ZERO,
                std: None,
            },
        );
        assert!(c
            .fresh(t0 + Duration::from_millis(100), Duration::from_millis(500))
            .is_some());
        assert!(c
            .fresh(t0 + Duration::from_secs(1), Duration::from_millis(500))
            .is_none());
        assert_eq!(wrap180(190.0), -170.0);
        assert_eq!(wrap180(-180.0), 180.0);
    }
}
