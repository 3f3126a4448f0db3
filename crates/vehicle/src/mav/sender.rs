//! The MAVLink task's sending side: each new pose of the outbox into
//! VISION_POSITION_ESTIMATE (and VISION_SPEED_ESTIMATE), rate-limited on
//! capture time, framed and signed, its skips and send errors counted and
//! logged by the rule for repeated lines.

use super::counters::{LastError, NetOp};
use super::link::{Link, Sent};
use super::outbound::{vision_position, vision_speed, Encoder, Skip};
use super::scan::Framing;
use super::skips::SkipLog;
use super::task::MavlinkSettings;
use crate::Hub;
use lightpose_core::ratelog::RateLog;
use mavlink::dialects::ardupilotmega::MavMessage;
use std::io;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

/// The sending side: the encoder with its sequence numbers, the rate
/// limit's memory, the outbox version last taken and the skips' log.
pub(super) struct Sender {
    pub(super) enc: Encoder,
    pub(super) seen: u64,
    pub(super) last_pos_t: Option<f64>,
    pub(super) last_sent: Option<Instant>,
    pub(super) pos_skips: SkipLog,
    pub(super) speed_skips: SkipLog,
    /// UDP send errors (an autopilot gone: ICMP port unreachable), by the
    /// rule for repeated lines; before, counted in STATUS alone.
    pub(super) send_log: RateLog,
}

impl Sender {
    pub(super) fn new(s: &MavlinkSettings) -> Self {
        Sender {
            enc: Encoder::new(s.system_id, s.component_id).signed(s.signing.clone()),
            seen: 0,
            last_pos_t: None,
            last_sent: None,
            pos_skips: SkipLog::new(false),
            speed_skips: SkipLog::new(true),
            send_log: RateLog::new(),
        }
    }

    /// Within the position rate limit of the last pose sent? (Capture
    /// time, so that a replay at any pace decimates alike; a step back in
    /// time starts over.)
    fn decimated(&self, t: f64, rate_hz: Option<f64>) -> bool {
        match (rate_hz, self.last_pos_t) {
            (Some(r), Some(last)) if t >= last => t - last < (1.0 - 1e-6) / r,
            _ => false,
        }
    }

    pub(super) async fn poses(
        &mut self,
        link: &mut Link,
        s: &MavlinkSettings,
        hub: &Hub,
    ) -> io::Result<()> {
        let c = &hub.mavlink;
        let Some(o) = hub.outbox.take_new(&mut self.seen) else {
            return Ok(());
        };
        if self.decimated(o.t, s.output.position_rate_hz) {
            c.skipped[Skip::Decimated.index()].fetch_add(1, Relaxed);
            return Ok(());
        }
        let msg = match vision_position(&o, &s.site, &s.output).and_then(|v| v.message()) {
            Ok(m) => m,
            Err(k) => {
                let n = c.skipped[k.index()].fetch_add(1, Relaxed) + 1;
                self.pos_skips.note(&o, k, n);
                return Ok(());
            }
        };
        // Only a pose that went out takes the rate limit's slot: one not
        // sent (no peer yet, a UDP error) must not decimate the next.
        if self.send(link, hub, &msg, 0).await? {
            self.last_pos_t = Some(o.t);
            self.last_sent = Some(Instant::now());
        }
        if s.output.speed && o.surge.is_some() {
            match vision_speed(&o, &s.site, &s.output).and_then(|v| v.message()) {
                Ok(m) => {
                    self.send(link, hub, &m, 1).await?;
                }
                Err(k) => {
                    let n = c.speed_skipped[k.index()].fetch_add(1, Relaxed) + 1;
                    self.speed_skips.note(&o, k, n);
                }
            }
        }
        Ok(())
    }

    /// Send one message: whether it went out. An error is returned only
    /// when the link is lost (serial); a UDP send error is counted.
    pub(super) async fn send(
        &mut self,
        link: &mut Link,
        hub: &Hub,
        msg: &MavMessage,
        kind: usize,
    ) -> io::Result<bool> {
        let c = &hub.mavlink;
        let framing = link.framing();
        // Nowhere to send (udpin before the autopilot spoke): nothing is
        // framed, so no sequence number or signing timestamp is spent on
        // it (a timestamp moved by unsent frames could leave an autopilot
        // whose clock is behind ours refused before it ever heard us).
        if !link.has_peer() {
            c.no_peer.fetch_add(1, Relaxed);
            return Ok(false);
        }
        match link.send(self.enc.encode(msg)).await {
            Ok(Sent::Yes) => {
                c.sent[kind].fetch_add(1, Relaxed);
                Ok(true)
            }
            Ok(Sent::NoPeer) => {
                c.no_peer.fetch_add(1, Relaxed);
                Ok(false)
            }
            Err(e) if framing == Framing::Stream => Err(e),
            Err(e) => {
                let n = c.send_errors.fetch_add(1, Relaxed) + 1;
                c.set_error(LastError::net(NetOp::Send, &e));
                if let Some(k) = self.send_log.tick(Instant::now()) {
                    tracing::warn!(
                        send_errors = n,
                        since_last_line = k,
                        "mavlink: send failed: {e}"
                    );
                }
                Ok(false)
            }
        }
    }
}
