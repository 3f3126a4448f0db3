//! The STATUS and VERSION messages (docs/daemon.md lists their fields): the
//! daemon's counters, read without stopping the frame thread, as JSON.

use crate::config::Config;
use crate::inputs::attitude::{AttitudeCell, Reason};
use crate::outputs::live::hub::Hub;
use crate::outputs::recorder::RecStats;
use crate::outputs::udp::Publisher;
use crate::stats::{Histogram, Stats, TempSource};
use lightpose_core::{ReadingUse, Refusal, Status, CHECKED, COLS, NDET, READINGS};
use lightpose_hal::SourceHealth;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::Instant;

/// Version of the message set (POSE, STATUS, VERSION) on the wire.
pub const PROTO: u32 = 1;

pub(crate) fn unix_now() -> f64 {
    crate::outputs::recorder::unix_now()
}

fn opt(v: Option<f64>) -> Value {
    v.and_then(lightpose_core::finite)
        .map_or(Value::Null, Into::into)
}

/// The VERSION banner sent once at start.
pub fn version_message(cfg: &Config, source: &str, estimator: &str) -> Vec<u8> {
    let v = json!({
        "class": "VERSION",
        "seq": 0,
        "t": unix_now(),
        "name": "lightposed",
        "release": env!("CARGO_PKG_VERSION"),
        "proto": PROTO,
        "backend": cfg.backend.kind(),
        "source": source,
        "estimator": estimator,
        "calibration": cfg.calibration.describe(),
        "rate_hz": cfg.rate_hz,
    });
    serde_json::to_vec(&v).unwrap_or_default()
}

/// What a STATUS is made from.
pub struct StatusCtx<'a> {
    pub cfg: &'a Config,
    pub stats: &'a Stats,
    pub rec: Option<&'a RecStats>,
    pub att: Option<&'a AttitudeCell>,
    /// The live view, if on.
    pub live: Option<&'a Hub>,
    /// The web page's feed, if on.
    pub web: Option<&'a crate::outputs::web::WebFeed>,
    /// The ROS 2 node, if `[ros2]` is on.
    #[cfg(feature = "ros2")]
    pub ros2: Option<&'a crate::outputs::ros2::Ros2Node>,
    /// The vehicle link's hub, if `[mavlink]` or `[dvl]` is on.
    pub vehicle: Option<&'a lightpose_vehicle::Hub>,
    pub publisher: &'a Publisher,
    pub source: &'a str,
    pub estimator: &'a str,
    pub started: Instant,
}

/// STATUS number `seq`, with `fps` measured since the last one.
pub fn status_message(c: &StatusCtx, seq: u64, fps: f64) -> Value {
    let s = c.stats;
    let health = s.source_health.lock().ok().and_then(|h| h.clone());
    json!({
        "class": "STATUS",
        "seq": seq,
        "t": unix_now(),
        "uptime": c.started.elapsed().as_secs_f64(),
        "backend": backend(c, health.as_ref()),
        "frames": s.frames.load(Relaxed),
        "late": s.late.load(Relaxed),
        "failed": s.failed.load(Relaxed),
        "lost": s.lost.load(Relaxed),
        "last_seq": s.last_seq.load(Relaxed),
        "fps": fps,
        "latency": latency(&s.latency),
        "estimator": estimator(c),
        "temperature": temperature(c, health.as_ref()),
        "recording": recording(c.rec),
        "attitude": attitude(c),
        "readings": readings(s),
        "channels": channels(s),
        "outputs": outputs(c.publisher),
        "foxglove": c.live.map_or_else(|| json!({"enabled": false}), Hub::report),
        "web": c.web.map_or_else(|| json!({"enabled": false}), crate::outputs::web::WebFeed::report),
        "vehicle": vehicle(c),
        "demodulator": demodulator(s),
        "station": station(s),
        "ros2": ros2(c),
    })
}

/// The ROS 2 node's counters; `enabled: false` without `[ros2]` (or a
/// build without the feature).
fn ros2(c: &StatusCtx) -> Value {
    #[cfg(feature = "ros2")]
    if let Some(r) = c.ros2 {
        return r.report();
    }
    let _ = c;
    json!({"enabled": false})
}

/// Spec v3: a docking station's beacons as the last estimate saw them,
/// each with its SNR (√(Σ a²/σ²) over its image), and the estimates by
/// mode; `enabled: false` for one beacon.
fn station(s: &Stats) -> Value {
    let st = &s.station;
    let size = usize::from(st.size.load(Relaxed));
    if size == 0 {
        return json!({"enabled": false});
    }
    let names = st.names.lock().ok().and_then(|n| *n);
    let seen = st.seen_now.load(Relaxed);
    let beacons: Vec<Value> = (0..size.min(lightpose_core::MAX_BEACONS))
        .map(|b| {
            let snr2 = f64::from_bits(st.snr2_bits[b].load(Relaxed));
            json!({
                "id": names.and_then(|n| n.beacons.get(b)).map_or_else(|| format!("#{b}"), |i| i.clone()),
                "seen": seen & (1 << b) != 0,
                "snr": snr2.max(0.0).sqrt(),
            })
        })
        .collect();
    let m = |i: usize| st.by_mode[i].load(Relaxed);
    json!({
        "enabled": true,
        "name": names.map(|n| n.name.clone()),
        "seen": (seen as u32).count_ones(),
        "beacons": beacons,
        "estimates": {"six_dof": m(0), "roll_observable": m(1), "one_beacon": m(2), "dark": m(3)},
    })
}

/// Spec v3: the demodulator's state (each beacon locked or not, its
/// clock's offset in ppm, the clipped samples); `enabled: false` for a
/// source of one sample a frame.
fn demodulator(s: &Stats) -> Value {
    let d = s.demod.lock().ok().and_then(|g| g.clone());
    let Some(d) = d else {
        return json!({"enabled": false});
    };
    let beacons: Vec<Value> = d
        .beacons
        .iter()
        .map(|b| {
            json!({
                "id": b.id,
                "mod_hz": b.mod_hz,
                "locked": b.locked,
                "detected": b.detected,
                "freq_hz": b.freq_hz,
                "offset_ppm": b.offset_ppm(),
                "detection": b.detection,
            })
        })
        .collect();
    json!({
        "enabled": true,
        "sample_hz": d.sample_hz,
        "samples_per_frame": d.samples_per_frame,
        "channel_skew_s": d.channel_skew_s,
        "frames": d.frames,
        "refused": d.refused,
        "clipped_total": d.clipped_total,
        "clipped_last": d.clipped_last,
        "beacons": beacons,
    })
}

/// Latency over the whole run, and over the last minute (`recent`: the
/// whole run's quantiles hide a slowdown that began after days).
fn latency(h: &Histogram) -> Value {
    let r = h.recent();
    json!({
        "p50": opt(h.quantile(0.5)),
        "p99": opt(h.quantile(0.99)),
        "max": opt(h.max()),
        "recent": {
            "p50": opt(r.p50),
            "p99": opt(r.p99),
            "max": opt(r.max),
            "count": r.count,
            "window_s": r.window_s,
        },
    })
}

/// The vehicle link: lightpose-vehicle's `VehicleStatus` (readings
/// attached and stale, the outbox, the MAVLink and DVL counters) with what
/// is configured.
fn vehicle(c: &StatusCtx) -> Value {
    let (Some(hub), Some(cfg)) = (c.vehicle, &c.cfg.vehicle) else {
        return json!({"enabled": false});
    };
    let mut v = serde_json::to_value(hub.status(Instant::now())).unwrap_or(Value::Null);
    if let Value::Object(m) = &mut v {
        m.insert("enabled".into(), true.into());
        let conn = cfg.mavlink.as_ref().map(|m| m.endpoint.to_string());
        m.insert("connection".into(), conn.into());
        let dvl = cfg.dvl.as_ref().map(|d| d.address.clone());
        m.insert("dvl_address".into(), dvl.into());
    }
    v
}

fn backend(c: &StatusCtx, health: Option<&SourceHealth>) -> Value {
    let s = c.stats;
    json!({
        "kind": c.cfg.backend.kind(),
        "source": c.source,
        "state": s.state().as_str(),
        "last_error": s.last_error.lock().ok().and_then(|g| g.clone()),
        "health": health.map(|h| json!({
            "bad_lines": h.bad_lines,
            "wrong_board_lines": h.wrong_board_lines,
            "superseded_lines": h.superseded_lines,
            "last_bad_line": h.last_bad_line,
            "reopens": h.reopens,
            "injected_faults": h.injected_faults,
            "skipped_frames": h.skipped_frames,
            "time_jumps": h.time_jumps,
            "glitches": h.glitches,
            "other_lines": h.other_lines,
            "bad_readings": h.bad_readings,
            "last_bad_reading": h.last_bad_reading,
        })),
    })
}

fn estimator(c: &StatusCtx) -> Value {
    let s = c.stats;
    let last_status = Status::ALL
        .get(s.last_status.load(Relaxed) as usize)
        .map_or("none", |st| st.as_str());
    let counts: serde_json::Map<String, Value> = Status::ALL
        .iter()
        .zip(&s.by_status)
        .map(|(st, n)| (st.as_str().to_string(), n.load(Relaxed).into()))
        .collect();
    json!({
        "name": c.estimator,
        "status": last_status,
        "counts": counts,
        "calibration": c.cfg.calibration.describe(),
        "reloads": s.calibration_reloads.load(Relaxed),
        "water_k_d": opt(s.water_k_d()),
        "depth_offset": s.depth_offset().map(|(m, sd)| json!({"m": m, "std": sd})),
        "pitch_offset": s.pitch_offset_deg().map(|(d, sd)| json!({"deg": d, "std": sd})),
    })
}

fn temperature(c: &StatusCtx, health: Option<&SourceHealth>) -> Value {
    let (temp, tsrc) = c.stats.temp();
    let sensor = health.and_then(|h| h.temp.as_ref());
    // hal stamps its own fallback on the frame when its sensor fails, so
    // `source` alone would say "frame" during a sensor outage: `fallback`
    // and `error` say plainly whether the value in use is a stand-in and why.
    let sensor_fallback = sensor.is_some_and(|t| t.fallback_active);
    let mut v = json!({
        "c": opt(temp),
        "source": tsrc.as_str(),
        "fallback_c": opt(c.cfg.fallback_temp_c),
        "fallback": sensor_fallback || tsrc == TempSource::Fallback,
        "error": if sensor_fallback { sensor.and_then(|t| t.last_error.clone()) } else { None },
    });
    if let Some(t) = sensor {
        v["sensor"] = json!({
            "kind": t.source,
            "fallback_active": t.fallback_active,
            "fallbacks": t.fallbacks,
            "last_error": t.last_error,
        });
    }
    v
}

fn recording(rec: Option<&RecStats>) -> Value {
    match rec {
        None => json!({"state": "off"}),
        Some(r) => json!({
            "state": r.state().as_str(),
            "format": r.format.as_str(),
            "synced": r.synced.load(Relaxed),
            "file": r.current.lock().ok().and_then(|g| g.clone()),
            "frames": r.frames.load(Relaxed),
            "failed": r.failed.load(Relaxed),
            "dropped": r.dropped.load(Relaxed),
            "skipped": r.skipped.load(Relaxed),
            "status_dropped": r.status_dropped.load(Relaxed),
            "outages": r.outages.load(Relaxed),
            "retries": r.retries.load(Relaxed),
            "pruned": r.pruned.load(Relaxed),
            "files": r.files.load(Relaxed),
            "bytes": r.bytes.load(Relaxed),
            "error": r.error.lock().ok().and_then(|g| g.clone()),
        }),
    }
}

/// The channels the estimator leaves out as stuck (a photodiode or ADC
/// input at full scale or zero that its neighbours' light rules out):
/// those left out of the last frame, and frames per channel so far, each
/// as `[row, col]`.
fn channels(s: &Stats) -> Value {
    let now = s.excluded_now.load(Relaxed);
    let rc = |k: usize| json!([k / COLS, k % COLS]);
    let excluded_now: Vec<Value> = (0..NDET).filter(|k| now & (1 << k) != 0).map(rc).collect();
    let frames: Vec<Value> = s
        .excluded
        .iter()
        .enumerate()
        .filter_map(|(k, n)| {
            let n = n.load(Relaxed);
            (n > 0).then(|| json!({"channel": rc(k), "frames": n}))
        })
        .collect();
    json!({"excluded_now": excluded_now, "excluded_frames": frames})
}

/// Per own-sensor reading, frames per outcome of the estimator's verdict:
/// `used`, `ignored` (this estimator does not use it), `refused` by reason
/// (`not_finite`, `bad_std`, `implausible`, `gate`, `light`: the DVL
/// check), and the checks against the light (`check`: the reading check
/// per component, and `dvl`, the DVL checks' last changes of range (the
/// light's and the DVL's), the DVL track's turn, and their verdict); the
/// light still
/// updated the pose on a frame whose reading was refused.
fn readings(s: &Stats) -> Value {
    let mut v = serde_json::Map::new();
    let now = s.disagreeing_now.load(Relaxed);
    let known = s.agreement_known.load(Relaxed);
    let mut check: serde_json::Map<String, Value> = CHECKED
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let bits = s.agreement_bits[i].load(Relaxed);
            let mean = (known & (1 << i) != 0).then(|| f64::from_bits(bits));
            let c = json!({
                "mean": mean,
                "disagreeing": now & (1 << i) != 0,
                "frames": s.disagreed[i].load(Relaxed),
            });
            (name.to_string(), c)
        })
        .collect();
    let f64_if = |k: &AtomicBool, bits: &AtomicU64| {
        k.load(Relaxed).then(|| f64::from_bits(bits.load(Relaxed)))
    };
    let change = s.dvl_change_known.load(Relaxed).then(|| {
        let [l, d] = &s.dvl_change_bits;
        json!({"light": f64::from_bits(l.load(Relaxed)), "dvl": f64::from_bits(d.load(Relaxed))})
    });
    check.insert(
        "dvl".to_string(),
        json!({
            "range_change_m": change,
            "turned_deg": f64_if(&s.dvl_turned_known, &s.dvl_turned_bits),
            "refused": s.dvl_refused_now.load(Relaxed),
        }),
    );
    v.insert("check".to_string(), Value::Object(check));
    for (name, counts) in READINGS.iter().zip(&s.readings) {
        let n = |u: ReadingUse| counts[u.index()].load(Relaxed);
        let refused: serde_json::Map<String, Value> = Refusal::ALL
            .iter()
            .map(|r| (r.as_str().to_string(), json!(n(ReadingUse::Refused(*r)))))
            .collect();
        v.insert(
            name.to_string(),
            json!({
                "used": n(ReadingUse::Used),
                "ignored": n(ReadingUse::Ignored),
                "refused": refused,
            }),
        );
    }
    Value::Object(v)
}

/// The frames' attitude and the UDP JSON input's counters. `enabled`
/// says whether the frames have an attitude at all, from anywhere (the
/// input, the autopilot, or the backend's own: a simulated AHRS, a
/// replayed log's): an audit read `false` beside a scene's AHRS in use.
/// `input` says whether the UDP JSON input is configured.
fn attitude(c: &StatusCtx) -> Value {
    let frames_with = c.stats.frames_with_attitude.load(Relaxed);
    match c.att {
        None => json!({"enabled": frames_with > 0, "input": false, "frames_with": frames_with}),
        Some(a) => json!({
            "enabled": true,
            "input": true,
            "received": a.received.load(Relaxed),
            "rejected": a.rejected.load(Relaxed),
            "rejected_by": Reason::ALL
                .iter()
                .map(|r| (r.as_str().to_string(), a.rejected_by[*r as usize].load(Relaxed).into()))
                .collect::<serde_json::Map<String, Value>>(),
            "age": a.age(Instant::now()).map(|d| d.as_secs_f64()),
            "repeated": a.repeated.load(Relaxed),
            "attached": a.attached.load(Relaxed),
            "stale": a.status(Instant::now()).stale,
            "superseded": a.superseded.load(Relaxed),
            "frames_with": frames_with,
        }),
    }
}

fn outputs(publisher: &Publisher) -> Value {
    publisher
        .destinations()
        .iter()
        .map(|d| {
            json!({
                "addr": d.addr.to_string(),
                "multicast": d.multicast,
                "sent": d.stats.sent.load(Relaxed),
                "errors": d.stats.errors.load(Relaxed),
                "last_error": d.stats.last_error.lock().ok().and_then(|g| g.clone()),
            })
        })
        .collect()
}
