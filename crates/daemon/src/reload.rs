//! Calibration reloads (SIGHUP), off the async thread and never more than
//! one at a time. The supervisor's thread also sends STATUS, pings the
//! watchdog and handles SIGTERM: a reload read there (a calibration that
//! is a FIFO, a slow network mount) had stopped all three. And a reload
//! restarts the track, so a storm of SIGHUPs must not become a storm of
//! reloads: those that come while one runs, or within [`MIN_INTERVAL`] of
//! the last, make one more reload after it; a calibration that parses to
//! the one running is left running (the track is kept); and the SIGHUP
//! lines follow core's rule for repeated lines.

use crate::config::Config;
use crate::error::report;
use crate::wiring::Running;
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_core::Estimator;
use lightpose_pipeline::Calibration;
use std::sync::mpsc::Sender;
use std::sync::Arc;
use tokio::sync::oneshot;
use tokio::time::{Duration, Instant};

/// A reload still reading after this is told.
const SLOW: Duration = Duration::from_secs(5);

/// Reloads start at least this far apart.
pub const MIN_INTERVAL: Duration = Duration::from_secs(1);

/// What one reload needs, moved to its thread and back.
struct Job {
    cfg: Config,
    adc_bits: u8,
    /// The vehicle link's hub and the ROS 2 inputs' (each told the σ).
    hubs: Vec<Arc<lightpose_vehicle::Hub>>,
    tx: Sender<Box<dyn Estimator>>,
    /// The calibration the running estimator was built from.
    running: Option<Calibration>,
}

/// What a reload did.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// A new estimator went to the frame thread.
    Replaced,
    /// The calibration is the running one's: nothing replaced.
    Unchanged,
    /// Refused, and why; the running calibration is kept.
    Refused(String),
}

impl Job {
    /// Read and build (blocking), hand a new estimator to the frame thread.
    /// Said by the supervisor ([`Reloads::finished`]).
    fn run(&mut self) -> Outcome {
        let (est, cal) = match crate::wiring::estimator_and_calibration(&self.cfg, self.adc_bits) {
            Ok(x) => x,
            Err(why) => return Outcome::Refused(report(&why)),
        };
        if self.running.as_ref() == Some(&cal) {
            return Outcome::Unchanged;
        }
        // Told before the frame thread takes the estimator: a frame between
        // gets the new σ.
        for h in &self.hubs {
            crate::wiring::assume_std(Some(h), est.name(), &cal);
        }
        let _ = self.tx.send(est);
        self.running = Some(cal);
        Outcome::Replaced
    }
}

fn hubs(d: &Running) -> Vec<Arc<lightpose_vehicle::Hub>> {
    let mut v: Vec<_> = d.vehicle.iter().map(|v| v.hub.clone()).collect();
    #[cfg(feature = "ros2")]
    v.extend(crate::wiring::ros2_hub(d.ros2.as_deref()));
    v
}

/// The supervisor's end: SIGHUPs in, at most one reload running.
pub struct Reloads {
    /// The job, home while no reload runs.
    job: Option<Job>,
    /// The running reload's thread gives the job back with its outcome.
    running: Option<oneshot::Receiver<(Job, Outcome)>>,
    /// A SIGHUP not acted on yet.
    asked: bool,
    next_at: Instant,
    /// When the running reload began, and whether its slowness was told.
    began: Option<(std::time::Instant, bool)>,
    /// The calibration's name, for the lines.
    file: String,
    log: RateLog,
    /// Outcomes by the rule for repeated lines: loaded, unchanged,
    /// refused (a storm is a reload a second, still 60 lines a minute).
    said: [RateLog; 3],
}

impl Reloads {
    pub fn new(cfg: &Config, d: &Running) -> Self {
        Reloads {
            job: Some(Job {
                cfg: cfg.clone(),
                adc_bits: d.adc_bits,
                hubs: hubs(d),
                tx: d.reload.clone(),
                running: d.calibration.clone(),
            }),
            running: None,
            asked: false,
            next_at: Instant::now(),
            began: None,
            file: cfg.calibration.describe(),
            log: RateLog::new(),
            said: [RateLog::new(); 3],
        }
    }

    /// A SIGHUP: a reload now, or once the running one is done and
    /// [`MIN_INTERVAL`] has passed.
    pub fn ask(&mut self) {
        if let Some(k) = self.log.tick(std::time::Instant::now()) {
            tracing::info!(
                sighups_since_last_line = k,
                "SIGHUP: reloading the calibration (SIGHUPs while a reload runs, or within {} s of the last, make one more after it)",
                MIN_INTERVAL.as_secs_f64()
            );
        }
        self.asked = true;
        self.start();
    }

    /// When the supervisor should call [`Reloads::poll`] again: the next
    /// moment a reload asked for may start (`None`: nothing waits on time).
    pub fn wake_at(&self) -> Option<Instant> {
        (self.asked && self.running.is_none()).then_some(self.next_at)
    }

    /// Wait for the running reload's end (pending forever when none runs).
    pub async fn finished(&mut self) {
        match self.running.as_mut() {
            Some(rx) => {
                let got = rx.await;
                self.running = None;
                match got {
                    Ok((job, outcome)) => {
                        self.job = Some(job);
                        self.began = None;
                        self.say(&outcome);
                    }
                    // The thread died (a panic in a build): no more reloads.
                    Err(_) => tracing::error!("calibration reload thread ended without a word: reloads are off until a restart"),
                }
            }
            None => std::future::pending().await,
        }
    }

    /// Start the reload asked for, if it may start now.
    pub fn start(&mut self) {
        let now = Instant::now();
        if !self.asked || self.running.is_some() || now < self.next_at {
            return;
        }
        let Some(mut job) = self.job.take() else {
            return;
        };
        self.asked = false;
        self.next_at = now + MIN_INTERVAL;
        let (tx, rx) = oneshot::channel();
        // A thread of its own, not tokio's blocking pool: a read that never
        // returns must not hold the runtime's shutdown at exit.
        let spawned = std::thread::Builder::new()
            .name("reload".into())
            .spawn(move || {
                let outcome = job.run();
                let _ = tx.send((job, outcome));
            });
        match spawned {
            Ok(_) => {
                self.running = Some(rx);
                self.began = Some((std::time::Instant::now(), false));
            }
            Err(e) => tracing::error!("calibration reload: cannot start its thread: {e}"),
        }
    }

    /// One reload's outcome, by the rule for repeated lines of its kind.
    fn say(&mut self, outcome: &Outcome) {
        let file = &self.file;
        let i = match outcome {
            Outcome::Replaced => 0,
            Outcome::Unchanged => 1,
            Outcome::Refused(_) => 2,
        };
        let Some(k) = self.said[i].tick(std::time::Instant::now()) else {
            return;
        };
        match outcome {
            Outcome::Replaced => tracing::info!(
                reloads_since_last_line = k,
                "calibration {file} loaded: its estimator replaces the running one"
            ),
            Outcome::Unchanged => tracing::info!(
                reloads_since_last_line = k,
                "calibration {file} unchanged: the running estimator and its track are kept"
            ),
            Outcome::Refused(why) => tracing::error!(
                reloads_since_last_line = k,
                "reload of calibration {file} refused, keeping the running calibration: {why}"
            ),
        }
    }

    /// A reload still reading after [`SLOW`] (a FIFO whose writer never
    /// writes, a hung network mount): told once, since the SIGHUPs after
    /// it wait for it.
    pub fn check_slow(&mut self) {
        if let Some((at, told @ false)) = &mut self.began {
            let took = at.elapsed();
            if took >= SLOW {
                *told = true;
                tracing::warn!(
                    "calibration reload still reading {} after {:.0} s (a FIFO no one writes? a hung mount?): the running calibration stays, and SIGHUPs wait for this reload",
                    self.file,
                    took.as_secs_f64()
                );
            }
        }
    }

    /// The closing line of SIGHUPs not told yet: once they stopped
    /// (`Close::Over`, at each STATUS), or at stop (`Close::AtStop`).
    pub fn close(&mut self, when: Close) {
        let now = std::time::Instant::now();
        for (log, what) in self.said.iter_mut().zip(["loaded", "unchanged", "refused"]) {
            if let Some(k) = log.close(now, when) {
                tracing::info!(
                    reloads_since_last_line = k,
                    "calibration reloads {what}: {when}: {k} more since the last line"
                );
            }
        }
        if let Some(k) = self.log.close(now, when) {
            tracing::info!(
                sighups_since_last_line = k,
                "SIGHUP: {when}: {k} more since the last line"
            );
        }
    }
}
