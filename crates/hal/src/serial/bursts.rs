//! A serial bank in burst mode (spec v3: a blinking beacon): each board
//! samples on its own timer and sends LPBST blocks ([`super::burst`]);
//! the bank cuts them into frames ([`super::frames`]) and hands on a
//! burst once every board has the same frame whole. Boards must share
//! one sample clock (lpadc.ino's SYNC wire), so that frame j is the same
//! instants on each; boards out of step are said at the timeout, naming
//! both frame numbers. Bad packets, gaps and frames no read took are
//! counted in the health report; no frame is made from part of a burst.

use std::fmt;

use serialport::SerialPort;
use std::time::{Duration, Instant};

use super::burst::{payload_len, Block, PacketAssembler, PacketError, OVERHEAD};
use super::frames::FrameAssembler;
use super::{device, BadLine, Port, SerialBank, SerialCounters};
use crate::chanmap::RawBoard;
use crate::text::Text;
use crate::SourceError;

/// How a bank in burst mode samples: N samples a frame, `sample_hz`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BurstPlan {
    pub samples_per_frame: usize,
    pub sample_hz: f64,
}

/// Why a block was thrown away.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockRefusal {
    /// The bytes did not make a packet.
    Packet(PacketError),
    /// A good packet of another resolution than configured.
    Bits { said: u8, configured: u8 },
    /// A good packet with another number of channels than configured
    /// (the boards' conversion order counts them).
    Channels { said: u8, configured: u8 },
}

impl fmt::Display for BlockRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BlockRefusal::Packet(e) => write!(f, "{e}"),
            BlockRefusal::Bits { said, configured } => {
                write!(
                    f,
                    "packets say {said} bits, configured adc_bits = {configured}"
                )
            }
            BlockRefusal::Channels { said, configured } => write!(
                f,
                "packets carry {said} channels, configured channels = {configured}"
            ),
        }
    }
}

/// A port's burst state: bytes into packets, packets into frames.
pub(super) struct PortBursts {
    packets: PacketAssembler,
    pub(super) frames: FrameAssembler,
    /// Channels every packet must carry: the board's `channels`.
    channels: u8,
    /// The last good packet's refusal, until a block is taken.
    refused: Option<BlockRefusal>,
    /// The resolution every packet must declare.
    bits: u8,
}

impl PortBursts {
    pub(super) fn new(plan: BurstPlan, bits: u8, channels: u8) -> Box<Self> {
        Box::new(PortBursts {
            packets: PacketAssembler::default(),
            frames: FrameAssembler::new(plan.samples_per_frame, 1.0 / plan.sample_hz),
            channels,
            refused: None,
            bits,
        })
    }
    /// The port reopened: what it had is old.
    pub(super) fn reset(&mut self) {
        self.packets.clear();
        self.frames.reset();
        self.refused = None;
    }
}

/// The bytes `bytes` of port `port`, read at `read_s`, into its frames.
pub(super) fn feed(
    p: &mut Port,
    port: usize,
    bytes: &[u8],
    counters: &mut SerialCounters,
    read_s: f64,
) {
    let s_per_byte = 10.0 / f64::from(p.cfg.baud.max(1));
    let id = p.cfg.id;
    let (clock, foreign) = (&mut p.clock, &mut p.foreign);
    let Some(b) = p.bursts.as_deref_mut() else {
        return;
    };
    let PortBursts {
        packets,
        frames,
        channels,
        refused,
        bits,
    } = b;
    let bits = *bits;
    packets.push(bytes, |r| {
        let block: &Block = match r {
            Ok(block) => block,
            Err(e) => {
                counters.bad_lines += 1;
                counters.last_bad = Some(BadLine::Packet {
                    port,
                    error: BlockRefusal::Packet(e),
                });
                return;
            }
        };
        if block.board != id {
            counters.wrong_board += 1;
            counters.last_bad = Some(BadLine::WrongBoard {
                port,
                seen: block.board,
            });
            *foreign = Some(block.board);
            return;
        }
        *foreign = None;
        let why = if block.bits != bits {
            Some(BlockRefusal::Bits {
                said: block.bits,
                configured: bits,
            })
        } else if block.channels != *channels {
            Some(BlockRefusal::Channels {
                said: block.channels,
                configured: *channels,
            })
        } else {
            None
        };
        if let Some(w) = why {
            counters.bad_lines += 1;
            counters.last_bad = Some(BadLine::Packet { port, error: w });
            *refused = Some(w);
            return;
        }
        *refused = None;
        // The block's last sample was taken just before the board sent it:
        // its read time less its bytes' time on the wire, the wait in the
        // buffer taken off by the blocks' steady rate (`seqclock`).
        let len = OVERHEAD
            + payload_len(
                usize::from(block.samples),
                usize::from(block.channels),
                usize::from(block.bits),
            );
        let t = clock.stamp(block.last(), read_s - len as f64 * s_per_byte);
        frames.put(block, t);
    });
}

impl SerialBank {
    /// Burst mode: the boards send LPBST blocks sampled at
    /// `plan.sample_hz`, and the bank gives frames of
    /// `plan.samples_per_frame` samples ([`crate::bank::Bank::take_burst`]).
    /// Every buffer is made here.
    pub fn with_bursts(mut self, plan: BurstPlan) -> Self {
        for p in &mut self.ports {
            p.bursts = Some(PortBursts::new(plan, self.bits, p.cfg.channels));
        }
        self.plan = Some(plan);
        self
    }

    /// Wait until every board read (a bit in `wanted`) has the same frame
    /// whole, and take it: its first sample's time, the boards' mean.
    pub(super) fn take_frame(&mut self, wanted: &[u16]) -> Result<f64, SourceError> {
        let deadline = Instant::now() + self.timeout;
        let used = |b: usize| wanted.get(b).copied().unwrap_or(0) != 0;
        loop {
            if self.stop.is_raised() {
                return Err(SourceError::Stopped);
            }
            self.stop.beat();
            let (mut lo, mut hi, mut all) = (u64::MAX, 0u64, true);
            for b in 0..self.ports.len() {
                if !used(b) {
                    continue;
                }
                self.drain(b)?;
                match self.ports[b].bursts.as_ref().and_then(|x| x.frames.ready()) {
                    Some((j, _)) => (lo, hi) = (lo.min(j), hi.max(j)),
                    None => all = false,
                }
            }
            if all && lo == hi && lo != u64::MAX {
                return Ok(self.take_ready(wanted));
            }
            // A board's whole frame older than another's will never be
            // matched: let it go, and wait for its next.
            for p in self.ports.iter_mut() {
                if let Some(x) = p.bursts.as_deref_mut() {
                    if x.frames.ready().is_some_and(|(j, _)| j < hi) {
                        x.frames.take();
                        x.frames.counts.superseded += 1;
                    }
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(self.no_frame(wanted));
            }
            self.listen((deadline - now).min(Duration::from_millis(100)), wanted);
        }
    }

    /// Open board `b`'s port if need be and read everything it holds.
    fn drain(&mut self, b: usize) -> Result<(), SourceError> {
        let Some(p) = self.ports.get_mut(b) else {
            return Ok(());
        };
        Self::open(p, &mut self.counters, &mut self.recent)?;
        // What is there now, and no more: a board that sends as fast as it
        // is read must not keep the reader here.
        let pending = match p.port.as_ref().map(|port| port.bytes_to_read()) {
            Some(Ok(n)) => n as usize,
            _ => 0,
        };
        for _ in 0..pending.div_ceil(self.buf.len()) {
            Self::pump(
                p,
                b,
                &mut self.buf,
                &mut self.counters,
                &mut self.recent,
                Duration::ZERO,
            )?;
        }
        Ok(())
    }

    /// Wait up to `wait` for bytes on the boards read, reading them as
    /// they come (a port that fails is closed; the next drain reopens it
    /// and says why).
    fn listen(&mut self, wait: Duration, wanted: &[u16]) {
        let n = self.ports.len().max(1) as u32;
        let slice = wait.min(super::IDLE_SLICE) / n;
        for (b, p) in self.ports.iter_mut().enumerate() {
            if wanted.get(b).copied().unwrap_or(0) == 0 {
                continue;
            }
            let Some(dev) = p.port.as_ref() else { continue };
            if device::readable(dev, slice) {
                let (buf, counters, recent) = (&mut self.buf, &mut self.counters, &mut self.recent);
                if let Err(e) = Self::pump(p, b, buf, counters, recent, Duration::ZERO) {
                    p.closed_by = Some(e);
                }
            }
        }
    }

    fn take_ready(&mut self, wanted: &[u16]) -> f64 {
        let (mut sum, mut used) = (0.0, 0u32);
        for (b, p) in self.ports.iter_mut().enumerate() {
            if wanted.get(b).copied().unwrap_or(0) == 0 {
                continue;
            }
            if let Some(x) = p.bursts.as_deref_mut() {
                if let Some((_, t)) = x.frames.ready() {
                    sum += t;
                    used += 1;
                }
                x.frames.take();
            }
        }
        sum / f64::from(used.max(1))
    }

    /// Why no frame came in time: the first board read that has none
    /// (its packets refused, another board's id, its counter out of step
    /// with the others', or silence).
    fn no_frame(&mut self, wanted: &[u16]) -> SourceError {
        let used = |b: usize| wanted.get(b).copied().unwrap_or(0) != 0;
        let newest = (0..self.ports.len())
            .filter(|&b| used(b))
            .filter_map(|b| {
                let x = self.ports[b].bursts.as_ref()?;
                Some((b, x.frames.last_frame()?))
            })
            .max_by_key(|&(_, j)| j);
        for b in (0..self.ports.len()).filter(|&b| used(b)) {
            let p = &self.ports[b];
            let Some(x) = p.bursts.as_ref() else { continue };
            if x.frames.ready().is_some() {
                continue;
            }
            if let Some(w) = x.refused {
                return SourceError::BadData {
                    place: p.place(),
                    msg: self.recent.text(format_args!("{w}")),
                };
            }
            if p.foreign.is_some() {
                return self.no_line(b);
            }
            if let (Some(mine), Some((other, theirs))) = (x.frames.last_frame(), newest) {
                if theirs > mine {
                    let other = self.ports[other].cfg.name.as_str();
                    return SourceError::BadData {
                        place: p.place(),
                        msg: self.recent.text(format_args!(
                            "its sample counter is at frame {mine}, board {other}'s at {theirs}: boards on one sample clock must start together (reset them together)"
                        )),
                    };
                }
            }
            return SourceError::Timeout { place: p.place() };
        }
        SourceError::Timeout {
            place: Text::from_static("serial boards"),
        }
    }

    /// Sample `i` of the frame taken, board by board into `raw`.
    pub(super) fn frame_sample(&self, i: usize, raw: &mut [RawBoard]) {
        for (p, r) in self.ports.iter().zip(raw.iter_mut()) {
            if let Some(s) = p.bursts.as_ref().and_then(|x| x.frames.sample(i)) {
                *r = *s;
            }
        }
    }

    /// The boards' burst counters summed: (gaps, frames dropped unfinished,
    /// frames superseded).
    pub(super) fn burst_counts(&self) -> (u64, u64, u64) {
        self.ports
            .iter()
            .filter_map(|p| p.bursts.as_ref())
            .fold((0, 0, 0), |(g, d, s), x| {
                let c = x.frames.counts;
                (g + c.gaps, d + c.dropped, s + c.superseded)
            })
    }
}
