//! systemd notifications (READY, STATUS line, WATCHDOG, STOPPING); no-ops
//! when not run by systemd (no NOTIFY_SOCKET).

use std::time::Duration;

pub use sd_notify::NotifyState;

pub fn notify(states: &[NotifyState]) {
    if std::env::var_os("NOTIFY_SOCKET").is_some() {
        if let Err(e) = sd_notify::notify(false, states) {
            tracing::debug!("sd_notify: {e}");
        }
    }
}

/// The watchdog timeout systemd set for this process, if any.
pub fn watchdog() -> Option<Duration> {
    let mut usec = 0u64;
    sd_notify::watchdog_enabled(false, &mut usec).then(|| Duration::from_micros(usec))
}
