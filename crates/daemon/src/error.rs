//! Why the daemon could not start or run, as typed errors that keep the
//! libraries' own errors as their sources; turned into one line of text
//! only where it is shown (`main.rs`, a log line) by [`report`].

use crate::config::{ConfigError, KeyAt};
use crate::outputs::udp::PublishError;
use std::error::Error;

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The calibration could not be read (the cause names the file), said
    /// at the config's `calibration` key as any refused key is.
    #[error("{at}: calibration")]
    CalibrationRead {
        at: KeyAt,
        #[source]
        source: lightpose_core::textfile::TextError,
    },
    /// The calibration is wrong, said at the config's `calibration` key
    /// (the cause names the calibration's own file and line).
    #[error("{at}: calibration")]
    Calibration {
        at: KeyAt,
        #[source]
        source: lightpose_pipeline::CalError,
    },
    /// No such estimator, or not with this calibration: at the config's
    /// `estimator` key.
    #[error("{at}: estimator")]
    Estimator {
        at: KeyAt,
        #[source]
        source: lightpose_pipeline::BuildError,
    },
    /// The backend's frames are of another ADC than the calibration's
    /// light model: said at the config's `calibration` key, the file to
    /// change (or the estimator).
    #[error("{at}: calibration {file}: backend {backend}: {msg}")]
    AdcMismatch {
        at: KeyAt,
        file: String,
        backend: &'static str,
        msg: String,
    },
    #[error("backend {kind}")]
    Backend {
        kind: &'static str,
        #[source]
        source: lightpose_hal::HalError,
    },
    /// --bench and --soak need a source that can go as fast as asked.
    #[error("backend {kind}: {mode} runs the sim or replay backend only")]
    NotFreeRunning {
        kind: &'static str,
        mode: &'static str,
    },
    #[error(transparent)]
    Publish(#[from] PublishError),
    #[error("attitude.listen {addr}")]
    AttitudeBind {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("foxglove.listen {addr}")]
    FoxgloveListen {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("web.listen {addr}")]
    WebListen {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    /// The MAVLink link could not be opened (the cause names the
    /// endpoint): a port in use, a serial device not (yet) there.
    #[error("mavlink")]
    Mavlink(#[source] lightpose_vehicle::mav::link::LinkError),
    /// The ROS 2 participant could not be made (its sockets, its thread).
    #[cfg(feature = "ros2")]
    #[error("cannot start the ROS 2 node")]
    Ros2(#[source] crate::outputs::ros2::Ros2Error),
    #[error("recording: cannot start the recorder thread")]
    Recorder(#[source] std::io::Error),
    #[error("cannot start the acquisition thread")]
    Thread(#[source] std::io::Error),
    /// `inner`, said at the config's line that asked for it (a bind, a
    /// socket, a link): `FILE:LINE: inner`.
    #[error("{at}")]
    Located {
        at: KeyAt,
        #[source]
        inner: Box<DaemonError>,
    },
}

impl DaemonError {
    /// This error said at `at`.
    pub fn at(self, at: KeyAt) -> DaemonError {
        DaemonError::Located {
            at,
            inner: Box::new(self),
        }
    }
}

impl DaemonError {
    /// Whether the configuration is what is wrong (a value, a file it
    /// names, an estimator this build lacks): the program exits 2 and
    /// systemd does not restart it (`RestartPreventExitStatus=2`), since a
    /// restart cannot help. A port that is taken or a device that is not
    /// there yet may be fine after a restart: exit 1.
    pub fn refuses_config(&self) -> bool {
        match self {
            DaemonError::Config(_)
            | DaemonError::CalibrationRead { .. }
            | DaemonError::Calibration { .. }
            | DaemonError::Estimator { .. }
            | DaemonError::AdcMismatch { .. }
            | DaemonError::NotFreeRunning { .. } => true,
            DaemonError::Backend { source, .. } => source.refuses_config(),
            DaemonError::Located { inner, .. } => inner.refuses_config(),
            DaemonError::Publish(_)
            | DaemonError::AttitudeBind { .. }
            | DaemonError::FoxgloveListen { .. }
            | DaemonError::WebListen { .. }
            | DaemonError::Mavlink(_)
            | DaemonError::Recorder(_)
            | DaemonError::Thread(_) => false,
            #[cfg(feature = "ros2")]
            DaemonError::Ros2(_) => false,
        }
    }

    /// The exit code of a failure: 2 for a refused configuration, else 1.
    pub fn exit_code(&self) -> u8 {
        if self.refuses_config() {
            2
        } else {
            1
        }
    }
}

/// `e` and its causes on one line, `: `-separated. A cause whose text its
/// parent already shows (some libraries put their source's text in their
/// own message) is left out, so nothing is said twice.
pub fn report(e: &(dyn Error + 'static)) -> String {
    let mut line = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !text.is_empty() && !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        cause = c.source();
    }
    // Libraries quote excerpts; this bounds whatever slipped through.
    lightpose_core::textfile::excerpt(&line.replace(['\n', '\r'], " "), 1000)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_are_chained_once() {
        let io = || std::io::Error::new(std::io::ErrorKind::AddrInUse, "address in use");
        let e = DaemonError::AttitudeBind {
            addr: "127.0.0.1:9".parse().unwrap(),
            source: io(),
        };
        assert_eq!(report(&e), "attitude.listen 127.0.0.1:9: address in use");
        // A library error that already says its source's text.
        let t = lightpose_core::textfile::TextError::Io {
            file: "c.toml".into(),
            source: io(),
        };
        let e = DaemonError::Config(ConfigError::Text(t));
        assert_eq!(report(&e), "c.toml: address in use");
    }
}
