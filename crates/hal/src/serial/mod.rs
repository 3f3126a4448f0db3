//! Serial ADC boards: microcontroller boards that stream `$LPADC` lines over
//! USB serial ([`protocol`]), read as a [`Bank`] so that they make frames
//! like any other board.
//!
//! Each board is its own port and streams at its own rate; a frame takes the
//! newest line of each board that it has not used before, so that a board
//! faster than the frame rate adds no latency and a silent board is noticed.
//! A port that fails (USB unplugged: the read errors or hangs up) is closed
//! and reopened by the next frame, so a board that comes back (same path,
//! e.g. a udev symlink) is picked up without restarting the daemon.
//!
//! A port whose lines all carry another board's id (two boards' cables
//! swapped, or a board flashed with the wrong id) does not just time out:
//! its frame fails naming the id seen and the id expected, and the health
//! report's last bad line says the same.
//!
//! In burst mode ([`SerialBank::with_bursts`], spec v3) the boards send
//! binary LPBST blocks of samples instead ([`burst`], [`bursts`]).

pub mod burst;
mod bursts;
mod device;
mod frames;
pub mod protocol;
mod seqclock;

use std::fmt;
use std::io::Read;
use std::time::{Duration, Instant};

use serialport::SerialPort;

use crate::bank::Bank;
use crate::chanmap::{BoardSpec, RawBoard};
use crate::pace::Stop;
use crate::text::{Recent, Text};
use crate::{SourceError, SourceHealth};
pub use bursts::{BlockRefusal, BurstPlan};
use device::Device;
use protocol::{parse_line, LineAssembler, LineError, Sample};
use seqclock::SeqClock;

/// One configured serial board.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialBoard {
    pub name: String,
    /// The board id its lines carry.
    pub id: u8,
    pub path: String,
    pub baud: u32,
    pub channels: u8,
}

/// Counters of what was read and thrown away.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SerialCounters {
    /// Lines that did not parse (garbage, checksum, too long, ...).
    pub bad_lines: u64,
    /// Good lines from a board id other than the port's.
    pub wrong_board: u64,
    /// Lines a board sent that no frame used (board faster than frames).
    pub superseded: u64,
    /// Times a port was (re)opened after the first.
    pub reopens: u64,
    /// The most recent bad line (one that did not parse, or another
    /// board's), for the health report.
    pub last_bad: Option<BadLine>,
}

/// What was wrong with a line thrown away, and on which port (an index
/// into the bank's boards).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BadLine {
    /// The line did not parse.
    Parse { port: usize, error: LineError },
    /// A good line carrying board id `seen`, not the port's.
    WrongBoard { port: usize, seen: u8 },
    /// Burst mode: bytes that made no packet, or a packet refused.
    Packet { port: usize, error: BlockRefusal },
}

struct Port {
    cfg: SerialBoard,
    /// Where an error of this board happened, for messages: built once.
    place: Text,
    port: Option<Device>,
    opened_once: bool,
    lines: LineAssembler,
    latest: Option<Sample>,
    /// When `latest` was sampled, as near as the port tells
    /// ([`crate::clock::monotonic_s`]): read, less its time on the wire.
    latest_at: f64,
    /// When its lines were sampled, from their `seq` (`seqclock`).
    clock: Box<SeqClock>,
    /// `latest` arrived since the last frame used a line of this board.
    fresh: bool,
    /// The board id of the last line of another board since this board's
    /// own last line: what a timeout of this port says.
    foreign: Option<u8>,
    /// Why the port closed between frames (`idle`), told when it reopens:
    /// no frame failed, so nothing else would say it.
    closed_by: Option<SourceError>,
    /// Burst mode: its packets and frames.
    bursts: Option<Box<bursts::PortBursts>>,
}

/// The longest a serial bank's idle listens to its ports before it looks
/// at the time and the stop again: a line is stamped within this (shared
/// by the ports) of its arrival.
const IDLE_SLICE: Duration = Duration::from_millis(2);

/// All serial boards of a frame.
pub struct SerialBank {
    ports: Vec<Port>,
    bits: u8,
    timeout: Duration,
    counters: SerialCounters,
    buf: [u8; 512],
    /// The mean sampling time of the lines the last read used.
    sampled_at: Option<f64>,
    stop: Stop,
    /// The words of a failure that repeats (a port that cannot be opened,
    /// lines of another board), built only when they change.
    recent: Recent,
    /// Burst mode, when set.
    plan: Option<BurstPlan>,
}

impl SerialBank {
    /// Ports are opened lazily by the first frame, so that a board that is
    /// not plugged in yet is a per-frame error, not a startup failure.
    pub fn new(boards: Vec<SerialBoard>, bits: u8, timeout: Duration) -> Self {
        SerialBank {
            ports: boards
                .into_iter()
                .map(|cfg| Port {
                    place: Text::from(format!("board {} ({})", cfg.name, cfg.path)),
                    cfg,
                    port: None,
                    opened_once: false,
                    lines: LineAssembler::default(),
                    latest: None,
                    latest_at: 0.0,
                    clock: Box::default(),
                    fresh: false,
                    foreign: None,
                    closed_by: None,
                    bursts: None,
                })
                .collect(),
            bits,
            timeout,
            counters: SerialCounters::default(),
            buf: [0; 512],
            sampled_at: None,
            stop: Stop::new(),
            recent: Recent::default(),
            plan: None,
        }
    }

    /// End a wait for a line (at most 100 ms later) when `stop` is raised,
    /// with [`SourceError::Stopped`], whatever the timeout; the wait beats
    /// `stop` as it goes ([`Stop::beat`]).
    pub fn stoppable(mut self, stop: Stop) -> Self {
        self.stop = stop;
        self
    }

    pub fn counters(&self) -> SerialCounters {
        self.counters
    }

    /// Read whatever `p` (port number `port`) has, waiting at most `wait`,
    /// and parse it. Returns Err only when the port failed; it is then
    /// closed.
    fn pump(
        p: &mut Port,
        port: usize,
        buf: &mut [u8],
        counters: &mut SerialCounters,
        recent: &mut Recent,
        wait: Duration,
    ) -> Result<(), SourceError> {
        let unavailable = |p: &Port, msg: Text| SourceError::Unavailable {
            place: p.place(),
            msg,
        };
        let Some(dev) = p.port.as_mut() else {
            return Err(unavailable(p, Text::from_static("port closed")));
        };
        if !device::readable(dev, wait) {
            return Ok(());
        }
        // serialport waits up to its timeout for the first byte (where
        // `readable` did not wait already)
        if let Err(e) = dev.set_timeout(wait.max(Duration::from_millis(1))) {
            p.port = None;
            return Err(unavailable(p, recent.text(format_args!("{e}"))));
        }
        let n = match dev.read(buf) {
            Ok(0) => {
                // end of file: the other end is gone
                p.port = None;
                return Err(unavailable(p, Text::from_static("device closed")));
            }
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => return Ok(()),
            Err(e) => {
                p.port = None;
                return Err(unavailable(p, recent.text(format_args!("{e}"))));
            }
        };
        // A line is stamped when read, less its bytes' time on the wire
        // (10 bits a byte at 8N1): the board sampled, then sent it. Lines
        // that waited in the kernel's buffer (while the frame thread was
        // busy or pacing) would be late by that wait, up to about a line
        // period for the newest: the board's steady rate and the lines'
        // seq take it off (`seqclock`, docs/hardware.md).
        let read_s = crate::clock::monotonic_s();
        if p.bursts.is_some() {
            bursts::feed(p, port, &buf[..n], counters, read_s);
            return Ok(());
        }
        let s_per_byte = 10.0 / f64::from(p.cfg.baud.max(1));
        let id = p.cfg.id;
        let clock = &mut p.clock;
        let (latest, latest_at) = (&mut p.latest, &mut p.latest_at);
        let (fresh, foreign) = (&mut p.fresh, &mut p.foreign);
        p.lines.push(&buf[..n], |line| {
            match line.and_then(|l| Ok((l.len(), parse_line(l)?))) {
                Ok((len, s)) if s.board == id => {
                    if *fresh {
                        counters.superseded += 1;
                    }
                    // + "\r\n"
                    *latest_at = clock.stamp(s.seq, read_s - (len + 2) as f64 * s_per_byte);
                    *latest = Some(s);
                    *fresh = true;
                    *foreign = None;
                }
                Ok((_, s)) => {
                    counters.wrong_board += 1;
                    counters.last_bad = Some(BadLine::WrongBoard {
                        port,
                        seen: s.board,
                    });
                    *foreign = Some(s.board);
                }
                Err(error) => {
                    counters.bad_lines += 1;
                    counters.last_bad = Some(BadLine::Parse { port, error });
                }
            }
        });
        Ok(())
    }

    /// Open `p`'s port if it is not open. A port that cannot be opened
    /// costs serialport a few allocations each try (the path, the error's
    /// description); its words here are built once while they repeat.
    fn open(
        p: &mut Port,
        counters: &mut SerialCounters,
        recent: &mut Recent,
    ) -> Result<(), SourceError> {
        if p.port.is_some() {
            return Ok(());
        }
        let builder =
            serialport::new(p.cfg.path.as_str(), p.cfg.baud).timeout(Duration::from_millis(10));
        let port = device::open(builder).map_err(|e| SourceError::Unavailable {
            place: p.place(),
            msg: recent.text(format_args!("{e}")),
        })?;
        // Whatever the OS buffered while we were away is old.
        let _ = port.clear(serialport::ClearBuffer::Input);
        if p.opened_once {
            counters.reopens += 1;
            match p.closed_by.take() {
                Some(e) => tracing::warn!(
                    "serial board {} reopened at {}; it closed between frames: {e}",
                    p.cfg.name,
                    p.cfg.path
                ),
                None => tracing::info!("serial board {} reopened at {}", p.cfg.name, p.cfg.path),
            }
        }
        p.opened_once = true;
        p.port = Some(port);
        p.lines.clear();
        p.latest = None;
        p.clock.reset();
        p.fresh = false;
        p.foreign = None;
        if let Some(b) = p.bursts.as_deref_mut() {
            b.reset();
        }
        Ok(())
    }

    /// Open board `b`'s port if need be, drain what is already there (so
    /// that the newest line is used), then wait until `deadline` for a
    /// line if none is fresh. Ok(false): no fresh line by then.
    fn wait_fresh(&mut self, b: usize, deadline: Instant) -> Result<bool, SourceError> {
        let Some(p) = self.ports.get_mut(b) else {
            return Ok(false);
        };
        Self::open(p, &mut self.counters, &mut self.recent)?;
        loop {
            if self.stop.is_raised() {
                return Err(SourceError::Stopped);
            }
            // Alive and waiting as configured (`timeout_ms` may be a
            // minute): a sign of life every slice of at most 100 ms.
            self.stop.beat();
            let now = Instant::now();
            let wait = if p.fresh {
                Duration::ZERO
            } else if now >= deadline {
                return Ok(false);
            } else {
                deadline - now
            };
            let pending = match p.port.as_ref().map(|port| port.bytes_to_read()) {
                Some(Ok(n)) => n,
                _ => 0,
            };
            if p.fresh && pending == 0 {
                return Ok(true);
            }
            Self::pump(
                p,
                b,
                &mut self.buf,
                &mut self.counters,
                &mut self.recent,
                wait.min(Duration::from_millis(100)),
            )?;
        }
    }

    /// Why board `b` has no line for the frame: only another board's
    /// lines came on its port (said, with both ids), or none at all.
    fn no_line(&mut self, b: usize) -> SourceError {
        let Some(p) = self.ports.get(b) else {
            return SourceError::Timeout {
                place: Text::format(format_args!("board #{b}")),
            };
        };
        match p.foreign {
            Some(seen) => {
                let said = wrong_board(&self.ports, p, seen);
                SourceError::BadData {
                    place: p.place(),
                    msg: self.recent.text(format_args!("{said}")),
                }
            }
            None => SourceError::Timeout { place: p.place() },
        }
    }

    /// The health report's words for `bad`: the port's path, then why.
    fn describe_bad(&self, bad: BadLine) -> Option<String> {
        match bad {
            BadLine::Parse { port, error } => {
                let p = self.ports.get(port)?;
                Some(format!("{}: {error}", p.cfg.path))
            }
            BadLine::WrongBoard { port, seen } => {
                let p = self.ports.get(port)?;
                let said = wrong_board(&self.ports, p, seen);
                Some(format!("{}: {said}", p.cfg.path))
            }
            BadLine::Packet { port, error } => {
                let p = self.ports.get(port)?;
                Some(format!("{}: {error}", p.cfg.path))
            }
        }
    }
}

/// What lines of board id `seen` on a port expecting `expected` mean;
/// `owner` is the board configured with `seen`, if any. Said as it is
/// printed, without building a string of its own.
struct WrongBoard<'a> {
    seen: u8,
    expected: u8,
    owner: Option<&'a str>,
}

fn wrong_board<'a>(ports: &'a [Port], p: &Port, seen: u8) -> WrongBoard<'a> {
    WrongBoard {
        seen,
        expected: p.cfg.id,
        owner: ports
            .iter()
            .find(|q| q.cfg.id == seen)
            .map(|q| q.cfg.name.as_str()),
    }
}

impl fmt::Display for WrongBoard<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (seen, expected) = (self.seen, self.expected);
        write!(f, "lines carry board id {seen}, expected {expected} (")?;
        match self.owner {
            Some(name) => write!(f, "board {name}'s id: cables swapped?)"),
            None => write!(
                f,
                "no board is configured with id {seen}: a board's id set wrong?)"
            ),
        }
    }
}

impl Port {
    /// Where an error of this board happened, for messages.
    fn place(&self) -> Text {
        self.place.clone()
    }
}

impl Bank for SerialBank {
    fn boards(&self) -> Vec<BoardSpec> {
        self.ports
            .iter()
            .map(|p| BoardSpec {
                name: p.cfg.name.clone(),
                channels: p.cfg.channels,
            })
            .collect()
    }
    fn bits(&self) -> u8 {
        self.bits
    }
    fn describe(&self) -> String {
        match self.plan {
            Some(_) => format!("{} serial LPBST burst board(s)", self.ports.len()),
            None => format!("{} serial LPADC board(s)", self.ports.len()),
        }
    }
    fn samples_itself(&self) -> bool {
        self.plan.is_some()
    }
    fn take_burst(&mut self, wanted: &[u16]) -> Result<f64, SourceError> {
        self.take_frame(wanted)
    }
    fn burst_sample(&self, i: usize, raw: &mut [RawBoard]) {
        self.frame_sample(i, raw);
    }

    fn read(&mut self, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError> {
        let deadline = Instant::now() + self.timeout;
        let (mut sum, mut used) = (0.0, 0u32);
        for (b, r) in raw.iter_mut().enumerate().take(self.ports.len()) {
            let mask = wanted.get(b).copied().unwrap_or(0);
            if mask == 0 {
                continue;
            }
            if !self.wait_fresh(b, deadline)? {
                return Err(self.no_line(b));
            }
            let p = &mut self.ports[b];
            p.fresh = false;
            let Some(s) = p.latest else {
                return Err(self.no_line(b));
            };
            // Both kept inline: no allocation, though the seq differs on
            // every frame (the second, for a line of 10 or more values,
            // below seq 10^9).
            if s.bits != self.bits {
                return Err(SourceError::BadData {
                    place: p.place(),
                    msg: Text::format(format_args!(
                        "line seq {} says {} bits, configured {}",
                        s.seq, s.bits, self.bits
                    )),
                });
            }
            let highest = 15 - mask.leading_zeros() as u8;
            if highest >= s.n {
                return Err(SourceError::BadData {
                    place: p.place(),
                    msg: Text::format(format_args!(
                        "line seq {} has {} values, channel {highest} is mapped",
                        s.seq, s.n
                    )),
                });
            }
            r[..s.n as usize].copy_from_slice(&s.values[..s.n as usize]);
            sum += p.latest_at;
            used += 1;
        }
        self.sampled_at = (used > 0).then(|| sum / f64::from(used));
        Ok(())
    }

    fn sampled_at(&self) -> Option<f64> {
        self.sampled_at
    }

    /// Listen to the open ports until the next frame is due, so that each
    /// line is read, and stamped, as it arrives: read only at the frame,
    /// the newest line had waited in the buffer for a fixed 0–50 ms at a
    /// divisor rate (5 Hz frames, 20 lines/s), which no fit of the read
    /// stamps can see (`seqclock`). Each port is asked in turn for up to
    /// [`IDLE_SLICE`], so a line is stamped within a slice per port of
    /// its arrival. A port that fails here is closed and left for the
    /// frame to reopen, which tells why. Beats the stop's heart as it goes.
    fn idle(&mut self, until: Instant, stop: &Stop) {
        let n = self.ports.len().max(1) as u32;
        loop {
            if stop.is_raised() {
                return;
            }
            stop.beat();
            let now = Instant::now();
            if now >= until {
                return;
            }
            let slice = (until - now).min(IDLE_SLICE) / n;
            let mut open = false;
            for (b, p) in self.ports.iter_mut().enumerate() {
                let Some(dev) = p.port.as_ref() else { continue };
                open = true;
                if device::readable(dev, slice) {
                    let (buf, counters, recent) =
                        (&mut self.buf, &mut self.counters, &mut self.recent);
                    if let Err(e) = Self::pump(p, b, buf, counters, recent, Duration::ZERO) {
                        p.closed_by = Some(e);
                    }
                }
            }
            if !open {
                // Nothing open yet (the first frame opens them): sleep.
                stop.sleep_until(until);
                return;
            }
        }
    }

    fn health(&self, h: &mut SourceHealth) {
        h.bad_lines += self.counters.bad_lines;
        h.wrong_board_lines += self.counters.wrong_board;
        h.superseded_lines += self.counters.superseded;
        h.reopens += self.counters.reopens;
        let (gaps, dropped, superseded) = self.burst_counts();
        h.burst_gaps += gaps;
        h.bursts_dropped += dropped;
        h.superseded_lines += superseded;
        if let Some(said) = self.counters.last_bad.and_then(|b| self.describe_bad(b)) {
            h.last_bad_line = Some(said);
        }
    }
}
