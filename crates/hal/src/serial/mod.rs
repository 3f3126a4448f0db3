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

pub mod protocol;

use std::time::{Duration, Instant};

use serialport::SerialPort;

use crate::bank::Bank;
use crate::chanmap::{BoardSpec, RawBoard};
use crate::pace::Stop;
use crate::{SourceError, SourceHealth};
use protocol::{parse_line, LineAssembler, LineError, Sample};

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
    /// The most recent parse error, for the health report.
    pub last_error: Option<LineError>,
}

struct Port {
    cfg: SerialBoard,
    port: Option<Box<dyn SerialPort>>,
    opened_once: bool,
    lines: LineAssembler,
    latest: Option<Sample>,
    /// `latest` arrived since the last frame used a line of this board.
    fresh: bool,
}

/// All serial boards of a frame.
pub struct SerialBank {
    ports: Vec<Port>,
    bits: u8,
    timeout: Duration,
    counters: SerialCounters,
    buf: [u8; 512],
    stop: Stop,
}

impl SerialBank {
    /// Ports are opened lazily by the first frame, so that a board that is
    /// not plugged in yet is a per-frame error, not a startup failure.
    pub fn new(boards: Vec<SerialBoard>, bits: u8, timeout: Duration) -> Self {
        SerialBank {
            ports: boards
                .into_iter()
                .map(|cfg| Port {
                    cfg,
                    port: None,
                    opened_once: false,
                    lines: LineAssembler::default(),
                    latest: None,
                    fresh: false,
                })
                .collect(),
            bits,
            timeout,
            counters: SerialCounters::default(),
            buf: [0; 512],
            stop: Stop::new(),
        }
    }

    /// End a wait for a line (at most 100 ms later) when `stop` is raised,
    /// with [`SourceError::Stopped`], whatever the timeout.
    pub fn stoppable(mut self, stop: Stop) -> Self {
        self.stop = stop;
        self
    }

    pub fn counters(&self) -> SerialCounters {
        self.counters
    }

    /// Read whatever `p` has (waiting at most `wait`) and parse it.
    /// Returns Err only when the port failed; it is then closed.
    fn pump(
        p: &mut Port,
        buf: &mut [u8],
        counters: &mut SerialCounters,
        wait: Duration,
    ) -> Result<(), SourceError> {
        let place = || format!("board {} ({})", p.cfg.name, p.cfg.path);
        let port = match p.port.as_mut() {
            Some(port) => port,
            None => {
                return Err(SourceError::Unavailable {
                    place: place(),
                    msg: "port closed".into(),
                })
            }
        };
        // serialport waits up to its timeout for the first byte
        if let Err(e) = port.set_timeout(wait.max(Duration::from_millis(1))) {
            p.port = None;
            return Err(SourceError::Unavailable {
                place: place(),
                msg: e.to_string(),
            });
        }
        let n = match port.read(buf) {
            Ok(0) => {
                // end of file: the other end is gone
                p.port = None;
                return Err(SourceError::Unavailable {
                    place: place(),
                    msg: "device closed".into(),
                });
            }
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => return Ok(()),
            Err(e) => {
                p.port = None;
                return Err(SourceError::Unavailable {
                    place: place(),
                    msg: e.to_string(),
                });
            }
        };
        let id = p.cfg.id;
        let (latest, fresh) = (&mut p.latest, &mut p.fresh);
        p.lines
            .push(&buf[..n], |line| match line.and_then(parse_line) {
                Ok(s) if s.board == id => {
                    if *fresh {
                        counters.superseded += 1;
                    }
                    *latest = Some(s);
                    *fresh = true;
                }
                Ok(_) => counters.wrong_board += 1,
                Err(e) => {
                    counters.bad_lines += 1;
                    counters.last_error = Some(e);
                }
            });
        Ok(())
    }

    fn open(p: &mut Port, counters: &mut SerialCounters) -> Result<(), SourceError> {
        if p.port.is_some() {
            return Ok(());
        }
        let port = serialport::new(p.cfg.path.as_str(), p.cfg.baud)
            .timeout(Duration::from_millis(10))
            .open()
            .map_err(|e| SourceError::Unavailable {
                place: format!("board {} ({})", p.cfg.name, p.cfg.path),
                msg: e.to_string(),
            })?;
        // Whatever the OS buffered while we were away is old.
        let _ = port.clear(serialport::ClearBuffer::Input);
        if p.opened_once {
            counters.reopens += 1;
            tracing::info!("serial board {} reopened at {}", p.cfg.name, p.cfg.path);
        }
        p.opened_once = true;
        p.port = Some(port);
        p.lines.clear();
        p.latest = None;
        p.fresh = false;
        Ok(())
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
        format!("{} serial LPADC board(s)", self.ports.len())
    }

    fn read(&mut self, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError> {
        let deadline = Instant::now() + self.timeout;
        for (b, p) in self.ports.iter_mut().enumerate() {
            let mask = wanted.get(b).copied().unwrap_or(0);
            if mask == 0 {
                continue;
            }
            Self::open(p, &mut self.counters)?;
            // Drain what is already there, so that the newest line is used,
            // then wait for a line if none is fresh.
            loop {
                if self.stop.is_raised() {
                    return Err(SourceError::Stopped);
                }
                let now = Instant::now();
                let wait = if p.fresh {
                    Duration::ZERO
                } else if now >= deadline {
                    return Err(SourceError::Timeout {
                        place: format!("board {} ({})", p.cfg.name, p.cfg.path),
                    });
                } else {
                    deadline - now
                };
                let pending = match p.port.as_ref().map(|port| port.bytes_to_read()) {
                    Some(Ok(n)) => n,
                    _ => 0,
                };
                if p.fresh && pending == 0 {
                    break;
                }
                Self::pump(
                    p,
                    &mut self.buf,
                    &mut self.counters,
                    wait.min(Duration::from_millis(100)),
                )?;
            }
            let place = || format!("board {} ({})", p.cfg.name, p.cfg.path);
            p.fresh = false;
            let Some(s) = p.latest else {
                return Err(SourceError::Timeout { place: place() });
            };
            if s.bits != self.bits {
                return Err(SourceError::BadData {
                    place: place(),
                    msg: format!(
                        "line seq {} says {} bits, configured {}",
                        s.seq, s.bits, self.bits
                    ),
                });
            }
            let highest = 15 - mask.leading_zeros() as u8;
            if highest >= s.n {
                return Err(SourceError::BadData {
                    place: place(),
                    msg: format!(
                        "line seq {} has {} values, channel {highest} is mapped",
                        s.seq, s.n
                    ),
                });
            }
            raw[b][..s.n as usize].copy_from_slice(&s.values[..s.n as usize]);
        }
        Ok(())
    }

    fn health(&self, h: &mut SourceHealth) {
        h.bad_lines += self.counters.bad_lines;
        h.wrong_board_lines += self.counters.wrong_board;
        h.reopens += self.counters.reopens;
        if let Some(e) = self.counters.last_error {
            h.last_bad_line = Some(e.to_string());
        }
    }
}
