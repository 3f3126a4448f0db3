//! The `lightposed` binary, kept thin: parse arguments, load and validate
//! the config, set up logging and signals, call `lightposed::run`, and map
//! the outcome to an exit code (0 clean, 1 runtime failure, 2 refused
//! config — at `--check-config` and at a start alike, so that systemd's
//! `RestartPreventExitStatus=2` does not restart what cannot start; a
//! frame thread that panicked is a runtime failure, 1, which systemd's
//! `Restart=on-failure` restarts). A failure is said once: on stderr before
//! logging is set up, as one log line after.

use anyhow::Context;
use clap::Parser;
use lightposed::config::LogFormat;
use lightposed::engine::EndReason;
use lightposed::error::report;
use lightposed::{Config, DaemonError, Publisher};
use nix::sys::signal::{SigSet, Signal};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tracing_appender::non_blocking::{ErrorCounter, NonBlockingBuilder, WorkerGuard};

#[derive(Parser)]
#[command(
    name = "lightposed",
    version,
    about = "Pose of an underwater vehicle from a 5×5 photodiode dome, published over UDP"
)]
struct Args {
    /// Config file (TOML). Without it: the embedded simulated tank,
    /// publishing to 127.0.0.1:17150.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Validate a config file and everything it names that a start would
    /// read (calibration, estimator, scene, trajectory, log header, the
    /// recording dir) or bind (every listen address, briefly; no device is
    /// opened) and exit (0 valid, 2 refused, 1 an address this machine
    /// cannot bind now).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["config", "bench", "soak"])]
    check_config: Option<PathBuf>,
    /// Run the simulator backend as fast as it goes and print throughput,
    /// latency, CPU and memory.
    #[arg(long, conflicts_with = "soak")]
    bench: bool,
    /// Soak: an hour of simulated 1 kHz frames (3.6 M) through the whole
    /// path as fast as it goes, recording on (rotated, old files deleted);
    /// prints frames/s, latency of the first and last 10 %, and memory.
    #[arg(long)]
    soak: bool,
    /// Frames for --bench (default 100000) or --soak (default 3600000); at
    /// least 1.
    #[arg(long)]
    frames: Option<u64>,
}

fn load(path: Option<&PathBuf>) -> Result<Config, lightposed::ConfigError> {
    match path {
        Some(p) => Config::load(p),
        None => Config::embedded_default(),
    }
}

impl Logging {
    /// Flush what is queued, for at most [`FLUSH_WAIT`]. The guard's drop
    /// waits 100 ms for room in a full queue and then prints to stdout,
    /// which under systemd is the same stalled journal stream: it could
    /// block the exit until the watchdog aborts the daemon. So it is
    /// dropped on a thread of its own, and not waited for past the limit.
    fn finish(self) {
        let Logging { flush: guard, .. } = self;
        let (done, flushed) = std::sync::mpsc::channel();
        let spawned = std::thread::Builder::new()
            .name("lightposed-flush".into())
            .spawn(move || {
                drop(guard);
                let _ = done.send(());
            });
        if spawned.is_ok() {
            let _ = flushed.recv_timeout(FLUSH_WAIT);
        }
    }
}

/// The longest the exit waits for queued log lines to reach a stalled
/// stderr: the writer's own ~1 s, and a margin.
const FLUSH_WAIT: Duration = Duration::from_millis(1500);

/// Log lines that may wait for the writer thread: far more than the daemon
/// says in a burst (its repeated warnings are thinned), and the queue's
/// slots are allocated up front (~32 bytes each).
const LOG_QUEUE: usize = 8192;

/// Logging set up; the writer thread flushes what is queued when this is
/// dropped (at the end of `main`), waiting at most ~1 s for a stalled
/// stderr.
struct Logging {
    flush: WorkerGuard,
    lost: LostWatch,
}

/// Log lines go to stderr from a thread of their own: a journald that
/// stalls (its socket buffer full) must not block the frame thread until
/// the watchdog kills the daemon. While the queue is full, lines are
/// dropped and counted ([`LostWatch`]).
fn init_logging(cfg: &Config) -> Logging {
    // The DDS stack logs each discovery event at info: its own warnings
    // only, unless RUST_LOG says otherwise.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new(format!(
            "{},rustdds=warn,ros2_client=warn",
            cfg.logging.level
        ))
    });
    // Under systemd the journal stamps and colours lines itself.
    let journald = std::env::var_os("JOURNAL_STREAM").is_some();
    let (writer, flush) = NonBlockingBuilder::default()
        .lossy(true)
        .buffered_lines_limit(LOG_QUEUE)
        .thread_name("lightposed-log")
        .finish(std::io::stderr());
    let lost = LostWatch {
        counter: writer.error_counter(),
        state: Arc::default(),
    };
    let b = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(writer)
        .with_ansi(colour(journald, std::io::stderr().is_terminal()));
    match (cfg.logging.format, journald) {
        (LogFormat::Json, _) => b.json().init(),
        (LogFormat::Plain, true) => b.without_time().with_target(false).init(),
        (LogFormat::Plain, false) => b.with_target(false).init(),
    }
    Logging { flush, lost }
}

/// Log lines lost to a stalled stderr, said once per stall: when the
/// count has stopped growing (said while stderr is stalled, it would be
/// lost too), and at exit.
#[derive(Default)]
struct LostLines {
    said: usize,
    seen: usize,
}

impl LostLines {
    /// How often the count is looked at.
    const EVERY: Duration = Duration::from_secs(5);

    /// The count `n` now: the lines to report, if it is time to.
    fn note(&mut self, n: usize, at_exit: bool) -> Option<usize> {
        let settled = at_exit || n == self.seen;
        self.seen = n;
        if n <= self.said || !settled {
            return None;
        }
        let lost = n - self.said;
        self.said = n;
        Some(lost)
    }
}

/// The count of lines the writer dropped, and what was said of it.
#[derive(Clone)]
struct LostWatch {
    counter: ErrorCounter,
    state: Arc<Mutex<LostLines>>,
}

impl LostWatch {
    fn report(&self, at_exit: bool) {
        let n = self.counter.dropped_lines();
        let Some(lost) = self.state.lock().ok().and_then(|mut s| s.note(n, at_exit)) else {
            return;
        };
        tracing::warn!(lost, total = n, "stderr was stalled: log lines lost");
    }

    /// Look every [`LostLines::EVERY`] until the runtime ends.
    async fn watch(self) {
        let mut every = tokio::time::interval(LostLines::EVERY);
        loop {
            every.tick().await;
            self.report(false);
        }
    }
}

/// Colour only for a person at a terminal: escape codes in a file, a pipe
/// (`2>log`, `| tee`) or the journal are noise, and NO_COLOR (no-color.org:
/// set and not empty) turns it off everywhere.
fn colour(journald: bool, terminal: bool) -> bool {
    let no_color = std::env::var_os("NO_COLOR").is_some_and(|v| !v.is_empty());
    terminal && !journald && !no_color
}

/// Run the daemon until a signal or its source's end; why the frame thread
/// ended.
async fn serve(cfg: Config) -> anyhow::Result<EndReason> {
    use tokio::signal::unix::{signal, SignalKind};
    let publisher = Publisher::open(&cfg.outputs).map_err(DaemonError::from)?;
    let mut term = signal(SignalKind::terminate()).context("SIGTERM handler")?;
    let mut int = signal(SignalKind::interrupt()).context("SIGINT handler")?;
    let mut hup = signal(SignalKind::hangup()).context("SIGHUP handler")?;
    // Blocked since main began (see there): one that came meanwhile is
    // delivered now, to the handler. This thread runs the runtime; the
    // threads started since keep it blocked, so it comes here.
    let _ = SigSet::from(Signal::SIGHUP).thread_unblock();
    let (reload_tx, reload_rx) = tokio::sync::mpsc::channel(4);
    tokio::spawn(async move {
        // Told by the supervisor's reloads (merged, by the rule for
        // repeated lines); a full queue already holds a reload to come.
        while hup.recv().await.is_some() {
            let _ = reload_tx.try_send(());
        }
    });
    let shutdown = async move {
        tokio::select! {
            _ = term.recv() => tracing::info!("SIGTERM"),
            _ = int.recv() => tracing::info!("SIGINT"),
        }
    };
    let running = lightposed::wiring::start(&cfg, publisher).await?;
    let supervised = lightposed::supervisor::supervise_to_end(&cfg, running, shutdown, reload_rx);
    Ok(supervised.await.1)
}

/// The exit code of a run that ended: 1 for a failure (the supervisor has
/// said it, in one ERROR line), else 0.
fn ended(end: &EndReason) -> ExitCode {
    if end.is_failure() {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

/// The one line a failure leaves on stderr, and its exit code.
fn fail(e: &(dyn std::error::Error + 'static), code: u8) -> ExitCode {
    eprintln!("lightposed: {}", report(e));
    ExitCode::from(code)
}

/// Print a result on stdout and exit 0. Not `println!`, which panics when
/// the reader has gone (`| head`): a closed pipe is a quiet success, as
/// for any Unix tool; another failure to write is one line and exit 1.
fn say(text: impl std::fmt::Display) -> ExitCode {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    match writeln!(o, "{text}").and_then(|()| o.flush()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("lightposed: writing to stdout: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Print a report and exit 0, or the one line and its exit code.
fn print_report<R: std::fmt::Display>(r: Result<R, DaemonError>) -> ExitCode {
    match r {
        Ok(r) => say(r),
        Err(e) => fail(&e, e.exit_code()),
    }
}

/// `--check-config`: the file, then everything a start would read.
fn check_config(p: &std::path::Path) -> ExitCode {
    let checked = Config::load(p)
        .map_err(DaemonError::from)
        .and_then(|c| lightposed::wiring::check(&c));
    match checked {
        Ok(()) => say(format_args!("{}: ok", p.display())),
        Err(e) => fail(&e, e.exit_code()),
    }
}

/// The first log line: where poses go and how to listen.
fn log_start(cfg: &Config) {
    let o = &cfg.outputs;
    let dests: Vec<String> = o.destinations.iter().map(|d| d.to_string()).collect();
    let multicast = o.multicast.as_ref().map_or(String::new(), |m| {
        format!(" + multicast {} ttl {}", m.group, m.ttl)
    });
    let to = match (dests.is_empty(), multicast.is_empty()) {
        (true, true) => "publishing nowhere".to_string(),
        (true, false) => format!("publishing to{multicast}"),
        _ => format!("publishing to {}{multicast}", dests.join(", ")),
    };
    tracing::info!(
        "lightposed {} ({}): {to}; {}",
        env!("CARGO_PKG_VERSION"),
        cfg.origin,
        lightposed::outputs::udp::listen_hint(o)
    );
}

/// Why `--frames` cannot be taken, if it cannot: it needs --bench or
/// --soak, and 0 frames measure nothing (the latencies would be NaN).
fn frames_refused(frames: Option<u64>, measuring: bool) -> Option<&'static str> {
    match frames {
        Some(_) if !measuring => Some("--frames goes with --bench or --soak"),
        Some(0) => Some("--frames 0: nothing to measure (give at least 1)"),
        _ => None,
    }
}

fn main() -> ExitCode {
    // SIGHUP's default is to end the process, and its handler is set only
    // once the runtime runs: a `systemctl reload` in the first milliseconds
    // killed the daemon without a line. Held until then (every thread
    // started from here inherits the mask); a measuring run (--soak,
    // --bench, --check-config) lets it end the run as usual.
    let hup = SigSet::from(Signal::SIGHUP);
    let _ = hup.thread_block();
    let args = Args::parse();
    if args.check_config.is_some() || args.soak || args.bench {
        let _ = hup.thread_unblock();
    }
    if let Some(p) = &args.check_config {
        return check_config(p);
    }
    let cfg = match load(args.config.as_ref()) {
        Ok(c) => c,
        Err(e) => return fail(&e, 2),
    };
    if let Some(why) = frames_refused(args.frames, args.bench || args.soak) {
        eprintln!("lightposed: {why}");
        return ExitCode::from(2);
    }
    if args.soak {
        let frames = args.frames.unwrap_or(lightposed::bench::SOAK_FRAMES);
        return print_report(lightposed::bench::soak(&cfg, frames));
    }
    if args.bench {
        return print_report(lightposed::bench::bench(
            &cfg,
            args.frames.unwrap_or(100_000),
        ));
    }
    // What a start would read is checked before logging is set up, so a
    // refused config (a replayed log that is no log, a calibration that is
    // wrong) is one line on stderr and exit 2, as at --check-config.
    if let Err(e) = lightposed::wiring::check(&cfg) {
        return fail(&e, e.exit_code());
    }
    let logging = init_logging(&cfg);
    log_start(&cfg);
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("lightposed: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    rt.spawn(logging.lost.clone().watch());
    let served = rt.block_on(serve(cfg));
    // A thread that did not stop (a hung device) must not hold the exit.
    rt.shutdown_timeout(Duration::from_millis(500));
    logging.lost.report(true);
    let code = match served {
        Ok(end) => ended(&end),
        Err(e) => {
            // Logging is set up: the one line goes there, not twice.
            tracing::error!("{}", report(e.as_ref()));
            let code = e
                .downcast_ref::<DaemonError>()
                .map_or(1, DaemonError::exit_code);
            ExitCode::from(code)
        }
    };
    logging.finish();
    code
}

#[cfg(test)]
mod tests {
    use super::{ended, frames_refused, EndReason, LostLines};
    use std::process::ExitCode;

    /// Audit: a panicked frame thread exited 0, so systemd never restarted
    /// the daemon; 2 would not do either (refused config, not restarted).
    #[test]
    fn a_panicked_frame_thread_exits_1() {
        assert_eq!(
            ended(&EndReason::Panicked("boom".into())),
            ExitCode::from(1)
        );
        for r in [EndReason::Stopped, EndReason::SourceEnded] {
            assert_eq!(ended(&r), ExitCode::SUCCESS, "{r:?}");
        }
    }

    #[test]
    fn frames_must_be_measured_and_more_than_none() {
        assert_eq!(frames_refused(None, false), None);
        assert_eq!(frames_refused(Some(10), true), None);
        assert!(frames_refused(Some(10), false).is_some_and(|w| w.contains("--bench")));
        assert!(frames_refused(Some(0), true).is_some_and(|w| w.starts_with("--frames 0")));
    }

    /// Lost log lines are said once the stall is over (the count unchanged
    /// between two looks), once per stall, and at exit whatever the count.
    #[test]
    fn lost_log_lines_are_said_once_a_stall_ends() {
        let mut l = LostLines::default();
        assert_eq!(l.note(0, false), None, "nothing lost");
        assert_eq!(l.note(0, false), None);
        assert_eq!(l.note(40, false), None, "stalled: said later");
        assert_eq!(l.note(90, false), None, "still stalled");
        assert_eq!(l.note(90, false), Some(90), "the stall is over");
        assert_eq!(l.note(90, false), None, "said once");
        assert_eq!(l.note(95, false), None);
        assert_eq!(l.note(99, true), Some(9), "at exit, what was not said");
    }
}
