//! `lightposed --bench` on a source that samples faster than its frames
//! (a v3 scene: a docking station's beacons at the scene's sample_hz): the
//! frame thread's three parts timed one by one on the source's own
//! bursts — the take (the simulator making a burst; on a vehicle the ADC
//! read), the demodulation and the estimator — so that the daemon's share
//! of a core at the scene's frame rate can be split into what a vehicle
//! pays and what only the simulation does (issue 41: a station at 20 Hz
//! with the demodulation on, under 25 % of one core).

use crate::config::Config;
use crate::engine::demod::{demodulator, Demod};
use crate::wiring::{build_estimator, open_source};
use crate::DaemonError;
use lightpose_core::{StationMode, Status};
use lightpose_hal::{SourceError, Stop, Take};

/// Frames taken before timing (the beacons locked, the track started),
/// and timed: two passes of a 10 s approach at 20 Hz.
const WARMUP: usize = 40;
const FRAMES: usize = 400;

/// The configured source's bursts through the frame thread's parts; CPU
/// seconds per frame of each, over [`FRAMES`] frames after [`WARMUP`].
#[derive(Debug, Clone, PartialEq)]
pub struct SourceRow {
    pub sample_hz: f64,
    pub rate_hz: f64,
    pub beacons: usize,
    pub frames: u64,
    pub source_s: f64,
    pub demod_s: f64,
    pub estimator_s: f64,
    /// Timed frames whose pose was `ok`, and those with three beacons or
    /// more seen: the estimator was tracking, not failing cheaply.
    pub ok: u64,
    pub six_dof: u64,
}

impl SourceRow {
    /// What a vehicle's frame thread pays at rate_hz beyond reading its
    /// ADC: the demodulation and the estimator.
    pub fn core_share(&self) -> f64 {
        (self.demod_s + self.estimator_s) * self.rate_hz
    }

    /// The same with the simulator's making of each burst.
    pub fn core_share_with_source(&self) -> f64 {
        (self.source_s + self.demod_s + self.estimator_s) * self.rate_hz
    }
}

impl std::fmt::Display for SourceRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "the source's own bursts ({} beacons at {:.0} Hz, {:.0} Hz frames; CPU time per frame, after {WARMUP}):",
            self.beacons, self.sample_hz, self.rate_hz
        )?;
        writeln!(
            f,
            "    frames  ok  six_dof  source µs  demod µs  estimator µs  % of one core (demod + estimator)  with the source"
        )?;
        write!(
            f,
            "    {:>6}  {:>3}  {:>7}  {:>9.0}  {:>8.0}  {:>12.0}  {:>33.2}  {:>15.2}",
            self.frames,
            self.ok,
            self.six_dof,
            self.source_s * 1e6,
            self.demod_s * 1e6,
            self.estimator_s * 1e6,
            self.core_share() * 100.0,
            self.core_share_with_source() * 100.0
        )
    }
}

/// The calling thread's CPU seconds (user + system).
fn thread_cpu() -> f64 {
    use nix::sys::resource::{getrusage, UsageWho};
    match getrusage(UsageWho::RUSAGE_THREAD) {
        Ok(u) => {
            let tv = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
            tv(u.user_time()) + tv(u.system_time())
        }
        Err(_) => f64::NAN,
    }
}

/// `None` when the configured source gives frames, not bursts (the
/// demodulation table's synthetic bursts cover it). Its frame rate is the
/// source's own: a burst's samples are the scene's.
pub fn source_bench(cfg: &Config) -> Result<Option<SourceRow>, DaemonError> {
    let mut cfg = cfg.clone();
    cfg.backend = cfg
        .backend
        .free_running(None)
        .ok_or(DaemonError::NotFreeRunning {
            kind: cfg.backend.kind(),
            mode: "--bench",
        })?;
    let mut source = open_source(&cfg, &Stop::new())?;
    let Some(sampling) = source.sampling() else {
        return Ok(None);
    };
    let rate_hz = source.rate_hz().unwrap_or(cfg.rate_hz);
    let Ok(dm) = demodulator(&sampling, rate_hz) else {
        // A start refuses such a source at --check-config: nothing to time.
        return Ok(None);
    };
    let mut d = Demod::new(dm);
    let mut estimator = build_estimator(&cfg)?;
    let mut row = SourceRow {
        sample_hz: sampling.sample_hz,
        rate_hz,
        beacons: sampling.beacons.len(),
        frames: 0,
        source_s: 0.0,
        demod_s: 0.0,
        estimator_s: 0.0,
        ok: 0,
        six_dof: 0,
    };
    let mut taken = 0;
    // Failures are retried, as the engine does, but not forever.
    for _ in 0..(WARMUP + FRAMES) * 2 {
        if taken == WARMUP + FRAMES {
            break;
        }
        let timed = taken >= WARMUP;
        let c0 = thread_cpu();
        d.taking();
        let take = source.next_take(&mut d.burst);
        let c1 = thread_cpu();
        let frame = match take {
            Ok(Take::Frame(f)) => Ok(f),
            Ok(Take::Burst) => d.frame(),
            Err(SourceError::Ended) => break,
            Err(e) => Err(e),
        };
        let c2 = thread_cpu();
        let frame = match frame {
            Ok(f) => f,
            Err(e) => {
                tracing::warn!("source bench: {e}");
                continue;
            }
        };
        let est = std::hint::black_box(estimator.estimate(&frame));
        let c3 = thread_cpu();
        taken += 1;
        if timed {
            row.frames += 1;
            row.source_s += c1 - c0;
            row.demod_s += c2 - c1;
            row.estimator_s += c3 - c2;
            row.ok += u64::from(est.status == Status::Ok);
            row.six_dof += u64::from(est.station.mode() == StationMode::SixDof);
        }
    }
    let n = row.frames.max(1) as f64;
    row.source_s /= n;
    row.demod_s /= n;
    row.estimator_s /= n;
    Ok(Some(row))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example(name: &str) -> Config {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/examples")
            .join(name);
        Config::load(&p).unwrap_or_else(|e| panic!("{name}: {e}"))
    }

    /// The station's example: its own bursts timed part by part, the
    /// tracker on every beacon's image tracking (not failing cheaply).
    #[test]
    fn a_station_s_bursts_are_timed_part_by_part() {
        let row = source_bench(&example("dock.toml"))
            .expect("the bench runs")
            .expect("a source of bursts");
        assert_eq!((row.beacons, row.frames), (4, FRAMES as u64));
        assert_eq!((row.sample_hz, row.rate_hz), (8000.0, 20.0));
        for (what, s) in [
            ("source", row.source_s),
            ("demod", row.demod_s),
            ("estimator", row.estimator_s),
        ] {
            assert!(s > 0.0 && s.is_finite(), "{what}: {s}");
        }
        // The looping 8.6 → 5 m approach: far out a dim beacon drops.
        assert!(row.ok * 10 >= row.frames * 8, "{row:?}");
        assert!(row.six_dof * 10 >= row.frames * 7, "{row:?}");
        let shown = row.to_string();
        assert!(
            shown.contains("4 beacons at 8000 Hz, 20 Hz frames"),
            "{shown}"
        );
    }

    /// A source of frames of counts has no bursts of its own.
    #[test]
    fn a_source_of_frames_gives_no_row() {
        assert_eq!(source_bench(&example("sim.toml")).expect("runs"), None);
    }
}
