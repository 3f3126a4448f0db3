//! What a start verifies before it opens any device, and `--check-config`
//! verifies alone: the calibration and the estimator, the ADC they read,
//! what MAVLink asks, the demodulator's settings, the recording directory
//! and every address the daemon binds or sends to.

use super::{
    attitude_bind, backend_error, estimator_of, foxglove_bind, load_calibration, mavlink_at,
    mavlink_endpoint, open_source, reads_frames, web_bind,
};
use crate::config::{machine, places, Config};
use crate::error::DaemonError;
use crate::outputs::udp::PublishError;
use lightpose_core::Estimator;
use lightpose_demod::ConfigError;
use lightpose_hal::{FrameSource, Sampling, Stop, ValidBackend};
use lightpose_vehicle::mav::link::LinkError;
use lightpose_vehicle::{Endpoint, MissingStd};

/// Check everything a start would read, without starting: the calibration
/// (read, parsed, checked), the estimator built from it by name, what the
/// backend reads (scene, trajectory, a log's header; hal opens no
/// device), the recording directory (a file is none; nothing is created)
/// and every address the daemon binds (bound and let go; the multicast
/// interface set on a throwaway socket), and that the estimator reads the
/// backend's ADC as a start checks it. `--check-config` runs this, and so
/// does the binary before a start: a start fails on the same things with
/// the same errors. Each names the config's `FILE:LINE`.
pub fn check(cfg: &Config) -> Result<(), DaemonError> {
    let cal = load_calibration(cfg)?;
    let est = estimator_of(cfg, &cal)?;
    reads_frames(cfg, est.as_ref(), &cal, checked_adc_bits(cfg)?)?;
    sends_what_mavlink_asks(cfg, est.as_ref())?;
    if let Some(r) = &cfg.recording {
        machine::recording_dir(&r.dir, &cfg.places.of(places::RECORDING_DIR))?;
    }
    check_binds(cfg)
}

/// With `[mavlink]` and `missing_std = "skip"` (the default) only a pose
/// with a std of each field is sent: an estimator that never gives them
/// would send the autopilot nothing, each pose counted `no_std`, while
/// everything else looked well. Refused at the estimator's line.
fn sends_what_mavlink_asks(cfg: &Config, est: &dyn Estimator) -> Result<(), DaemonError> {
    let Some(m) = cfg.vehicle.as_ref().and_then(|v| v.mavlink.as_ref()) else {
        return Ok(());
    };
    if est.std_with_every_ok_pose() || m.output.missing_std != MissingStd::Skip {
        return Ok(());
    }
    let msg = format!(
        "estimator {:?} gives no std with its poses, so [mavlink] would never send \
         VISION_POSITION_ESTIMATE (missing_std = \"skip\"): use estimator = \"auto\" or \
         \"tracker\" with a calibration that has a [physical] light model, or set \
         [mavlink] missing_std = \"assume\"",
        est.name()
    );
    Err(DaemonError::Config(
        cfg.estimator_at.refuse("estimator", msg),
    ))
}

/// The ADC of the frames the backend would give, without a device: a
/// log's header or the simulator's scene from the source opened (as
/// `lightpose_hal::check` opens it: nothing but files), a board's from its
/// validated kind, after hal's check of it.
fn checked_adc_bits(cfg: &Config) -> Result<u8, DaemonError> {
    match &cfg.backend {
        ValidBackend::Sim(_) | ValidBackend::Replay(_) => {
            let source = open_source(cfg, &Stop::new())?;
            demodulates(cfg, source.as_ref())?;
            Ok(source.adc_bits())
        }
        ValidBackend::Spi { common, .. }
        | ValidBackend::Ads1115 { common, .. }
        | ValidBackend::Ads7828 { common, .. }
        | ValidBackend::Serial { common, .. } => {
            lightpose_hal::check(&cfg.backend).map_err(|e| backend_error(cfg, e))?;
            // The sampling the opened bank would report (`sampling()`):
            // its demodulator is checked here as a start checks it, not
            // first met when the daemon starts.
            let rate = common.rate_hz.unwrap_or(cfg.rate_hz);
            sampling_demodulates(cfg, common.sampling().as_ref(), rate)?;
            Ok(common.bits)
        }
    }
}

/// Spec v3: a source that gives bursts can be demodulated (its beacons'
/// frequencies fit its sampling by MODEL.md's rules, its channels' skew
/// fits a frame), refused at the key that names what it samples: the
/// scene, the replayed log, the board's `sample_hz`.
pub(super) fn demodulates(cfg: &Config, source: &dyn FrameSource) -> Result<(), DaemonError> {
    let rate = source.rate_hz().unwrap_or(cfg.rate_hz);
    sampling_demodulates(cfg, source.sampling().as_ref(), rate)
}

/// [`demodulates`] of a sampling at frames of `rate` Hz: a board's from
/// its validated config (no device opened), a source's as it reports it.
/// A board's refusal is said at the key it is about: a beacon's at
/// `beacons`, the channels' skew at `channel_skew_s` where the config gives
/// it (a serial board), the rest at `sample_hz`.
fn sampling_demodulates(
    cfg: &Config,
    sampling: Option<&Sampling>,
    rate: f64,
) -> Result<(), DaemonError> {
    let Some(s) = sampling else {
        return Ok(());
    };
    let Err(e) = crate::engine::demod::demodulator(s, rate) else {
        return Ok(());
    };
    let key = match (&cfg.backend, &e) {
        (ValidBackend::Sim(_), _) => places::SCENE,
        (ValidBackend::Replay(_), _) => places::LOG,
        (ValidBackend::Serial { .. }, ConfigError::Skew { .. }) => "backend.channel_skew_s",
        (
            _,
            ConfigError::Skew { .. } | ConfigError::NotPositive { .. } | ConfigError::Range { .. },
        ) => "backend.sample_hz",
        _ => "backend.beacons",
    };
    let msg = format!(
        "the demodulator cannot take this sampling ({} Hz, {} samples a frame at {rate} Hz): {e}",
        s.sample_hz, s.samples_per_frame
    );
    Err(DaemonError::Config(cfg.places.of(key).refuse(key, msg)))
}

/// Bind what a start binds, each held until the last is done (as a start
/// holds them all), then let go. A port in use fails as at a start (exit
/// 1: it may be free later), and while the daemon runs, its own ports are
/// in use: the message asks whether it is.
fn check_binds(cfg: &Config) -> Result<(), DaemonError> {
    check_sending(cfg)?;
    let mut udp = Vec::new();
    if let Some(a) = &cfg.attitude {
        udp.push(machine::try_udp(a.listen).map_err(|e| attitude_bind(cfg, a.listen, e))?);
    }
    if let Some(ep @ Endpoint::UdpIn(a)) = mavlink_endpoint(cfg) {
        let bound = machine::try_udp(*a).map_err(|source| LinkError::Socket {
            endpoint: ep.to_string(),
            source,
        });
        udp.push(bound.map_err(|e| mavlink_at(cfg, DaemonError::Mavlink(e)))?);
    }
    let tcp = match &cfg.foxglove {
        Some(f) => Some(machine::try_tcp(f.listen).map_err(|e| foxglove_bind(cfg, f.listen, e))?),
        None => None,
    };
    let web_tcp = match &cfg.web {
        Some(w) => Some(machine::try_tcp(w.listen).map_err(|e| web_bind(cfg, w.listen, e))?),
        None => None,
    };
    let mav_tcp = match mavlink_endpoint(cfg) {
        Some(ep @ Endpoint::TcpIn(a)) => {
            let bound = machine::try_tcp(*a).map_err(|source| LinkError::Tcp {
                endpoint: ep.to_string(),
                source,
            });
            Some(bound.map_err(|e| mavlink_at(cfg, DaemonError::Mavlink(e)))?)
        }
        _ => None,
    };
    drop((udp, tcp, web_tcp, mav_tcp));
    Ok(())
}

/// The sockets the publisher opens: one of each destination's family
/// (IPv6 may be off on this machine), and the multicast interface, which
/// must be an address of this machine.
fn check_sending(cfg: &Config) -> Result<(), DaemonError> {
    let o = &cfg.outputs;
    let unicast = o.destinations.iter().enumerate();
    let dests = unicast.map(|(i, d)| (places::destination(i), *d));
    let group = o
        .multicast
        .as_ref()
        .map(|m| (places::MULTICAST_GROUP.to_string(), m.group));
    let (mut v4, mut v6) = (false, false);
    for (key, addr) in dests.chain(group) {
        let seen = if addr.is_ipv4() { &mut v4 } else { &mut v6 };
        if std::mem::replace(seen, true) {
            continue;
        }
        machine::try_sender(addr).map_err(|source| {
            DaemonError::Publish(PublishError::Socket { addr, source }).at(cfg.places.of(&key))
        })?;
    }
    let interface = o.multicast.as_ref().map(|m| m.interface);
    if let Some(ip) = interface.filter(|i| !i.is_unspecified()) {
        machine::try_multicast_interface(ip).map_err(|e| {
            DaemonError::Publish(PublishError::Multicast {
                what: "interface",
                source: machine::interface_refusal(ip, e),
            })
            .at(cfg.places.of(places::MULTICAST_INTERFACE))
        })?;
    }
    Ok(())
}
