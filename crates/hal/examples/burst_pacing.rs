//! How evenly a board bank's burst samples are spaced: an MCP3008 bank
//! (on an SPI device that answers at once and notes when detector 0 of
//! each sample is converted) read through `BoardSource::next_take`, and
//! each sample's start against t + i / sample_hz. Prints a table of the
//! jitter (the pacing spins the last 2 ms before each sample).
//!
//! `cargo run --release -p lightpose-hal --example burst_pacing`

use std::sync::{Arc, Mutex};

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use lightpose_core::samples::Burst;
use lightpose_hal::bank::{BoardSource, SpiBank};
use lightpose_hal::chanmap::ChannelMap;
use lightpose_hal::clock::monotonic_s;
use lightpose_hal::drivers::mcp3x08::{Mcp3x08, McpKind};
use lightpose_hal::pace::Pacer;
use lightpose_hal::temp::{TempKind, TempReader};
use lightpose_hal::{FrameSource, Sampling, Take};

/// Notes the time of every conversion of channel 0 (chip 0's: detector 0).
struct Noting {
    times: Option<Arc<Mutex<Vec<f64>>>>,
}

impl ErrorType for Noting {
    type Error = embedded_hal::spi::ErrorKind;
}

impl SpiDevice for Noting {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        for op in ops.iter_mut() {
            if let Operation::TransferInPlace(buf) = op {
                let ch = buf.get(1).copied().unwrap_or(0) >> 4 & 7;
                if let (0, Some(t)) = (ch, &self.times) {
                    if let Ok(mut v) = t.lock() {
                        v.push(monotonic_s());
                    }
                }
            }
        }
        Ok(())
    }
}

fn main() {
    println!("| sample_hz | N | bursts | taken | mean |dev| µs | p99 µs | max µs |");
    println!("|---|---|---|---|---|---|---|");
    for (hz, n) in [(1000.0, 100usize), (2000.0, 200), (500.0, 50)] {
        let times = Arc::new(Mutex::new(Vec::with_capacity(n)));
        let chips = (0..4)
            .map(|b| {
                let dev = Noting {
                    times: (b == 0).then(|| times.clone()),
                };
                (format!("u{b}"), Mcp3x08::new(dev, McpKind::Mcp3008))
            })
            .collect();
        let mut src = BoardSource::new(
            SpiBank::new(chips),
            ChannelMap::sequential(8),
            TempReader::new(TempKind::None, 0.0),
            Pacer::new(None),
        )
        .with_sampling(Some(Sampling {
            sample_hz: hz,
            samples_per_frame: n,
            channel_skew_s: 0.0,
            beacons: Vec::new(),
        }));
        let mut burst = Burst::new(n);
        let (bursts, mut taken) = (20, 0);
        let mut dev: Vec<f64> = Vec::new();
        for _ in 0..bursts {
            if let Ok(mut t) = times.lock() {
                t.clear();
            }
            if !matches!(src.next_take(&mut burst), Ok(Take::Burst)) {
                continue;
            }
            taken += 1;
            if let Ok(t) = times.lock() {
                for (i, s) in t.iter().enumerate() {
                    dev.push((s - (burst.t + i as f64 / hz)).abs() * 1e6);
                }
            }
        }
        dev.sort_by(f64::total_cmp);
        let mean = dev.iter().sum::<f64>() / dev.len().max(1) as f64;
        let p99 = dev.get(dev.len() * 99 / 100).copied().unwrap_or(f64::NAN);
        let max = dev.last().copied().unwrap_or(f64::NAN);
        println!("| {hz} | {n} | {bursts} | {taken} | {mean:.1} | {p99:.1} | {max:.1} |");
    }
}
