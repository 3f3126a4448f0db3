//! One serial board's bursts cut into frames: the samples of its LPBST
//! blocks ([`super::burst`]) placed by their index, frame j being samples
//! jN .. jN + N − 1 of the board's counter, so that boards that share one
//! sample clock cut the same instants into the same frame. A frame is
//! handed on only whole and in order: a gap in the index (a lost or
//! damaged packet) drops the frame it falls in, counted, rather than make
//! a frame of half a burst. Its buffers are made once: no allocation per
//! frame.

use crate::chanmap::{RawBoard, MAX_CH};

use super::burst::Block;

/// What happened to samples that made no frame, for the health report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameCounts {
    /// Breaks in the sample index (a packet lost, damaged or cut).
    pub gaps: u64,
    /// Frames begun and dropped unfinished, by a gap or a reset.
    pub dropped: u64,
    /// Whole frames no read took before a newer one was whole.
    pub superseded: u64,
}

/// The board's frames, one filling and one whole.
#[derive(Debug, Clone)]
pub struct FrameAssembler {
    n: u64,
    sample_s: f64,
    filling: Vec<RawBoard>,
    filling_frame: Option<u64>,
    filled: usize,
    ready: Vec<RawBoard>,
    ready_frame: Option<u64>,
    /// When the whole frame's first sample was taken.
    ready_t: f64,
    /// The whole frame has not been taken yet.
    fresh: bool,
    /// The index the next block should start at, extended past 2³².
    next: Option<u64>,
    pub counts: FrameCounts,
}

impl FrameAssembler {
    /// Frames of `n` samples taken `sample_s` apart.
    pub fn new(n: usize, sample_s: f64) -> Self {
        let n = n.max(1);
        FrameAssembler {
            n: n as u64,
            sample_s,
            filling: vec![[0; MAX_CH]; n],
            filling_frame: None,
            filled: 0,
            ready: vec![[0; MAX_CH]; n],
            ready_frame: None,
            ready_t: 0.0,
            fresh: false,
            next: None,
            counts: FrameCounts::default(),
        }
    }

    /// Forget the stream (the port reopened): its next block starts anew.
    pub fn reset(&mut self) {
        self.abandon();
        self.next = None;
        self.ready_frame = None;
        self.fresh = false;
    }

    fn abandon(&mut self) {
        if self.filled > 0 {
            self.counts.dropped += 1;
        }
        self.filling_frame = None;
        self.filled = 0;
    }

    /// The block's samples into their frames; `last_t` is when its last
    /// sample was taken. A block that does not start where the last one
    /// ended is a gap (forward) or a board that reset (backward: its
    /// counter starts over).
    pub fn put(&mut self, b: &Block, last_t: f64) {
        let first = match self.next {
            Some(want) if b.first == want as u32 => want,
            Some(want) => {
                self.counts.gaps += 1;
                self.abandon();
                let ahead = b.first.wrapping_sub(want as u32);
                if ahead < 1 << 31 {
                    want + u64::from(ahead)
                } else {
                    u64::from(b.first)
                }
            }
            None => u64::from(b.first),
        };
        let k = u64::from(b.samples);
        self.next = Some(first + k);
        let last = first + k - 1;
        for i in 0..k {
            let idx = first + i;
            let (j, off) = (idx / self.n, (idx % self.n) as usize);
            if self.filling_frame != Some(j) || off != self.filled {
                // A frame left unfinished, or one joined part-way (the
                // stream's start): nothing until the next frame begins.
                self.abandon();
                if off != 0 {
                    continue;
                }
                self.filling_frame = Some(j);
            }
            let s = b.sample(i as usize);
            self.filling[off][..s.len()].copy_from_slice(s);
            self.filled += 1;
            if self.filled as u64 == self.n {
                if self.fresh {
                    self.counts.superseded += 1;
                }
                std::mem::swap(&mut self.filling, &mut self.ready);
                self.ready_frame = Some(j);
                self.ready_t = last_t - (last - j * self.n) as f64 * self.sample_s;
                self.fresh = true;
                self.filling_frame = None;
                self.filled = 0;
            }
        }
    }

    /// The whole frame not taken yet: its number and its first sample's
    /// time.
    pub fn ready(&self) -> Option<(u64, f64)> {
        self.ready_frame
            .filter(|_| self.fresh)
            .map(|j| (j, self.ready_t))
    }

    /// The last whole frame's number, taken or not.
    pub fn last_frame(&self) -> Option<u64> {
        self.ready_frame
    }

    /// Mark the whole frame taken.
    pub fn take(&mut self) {
        self.fresh = false;
    }

    /// Sample `i` of the whole frame.
    pub fn sample(&self, i: usize) -> Option<&RawBoard> {
        self.ready.get(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(first: u32, k: u16, c: u8) -> Block {
        let mut b = Block {
            board: 0,
            bits: 12,
            channels: c,
            samples: k,
            first,
            ..Block::default()
        };
        for i in 0..k as usize {
            for ch in 0..c as usize {
                b.values[i * MAX_CH + ch] =
                    ((first as usize + i) as u16).wrapping_mul(10) + ch as u16;
            }
        }
        b
    }

    #[test]
    fn whole_frames_in_order_and_their_times() {
        let mut a = FrameAssembler::new(8, 1e-3);
        // Joined part-way: samples 4..7 make nothing.
        a.put(&block(4, 4, 2), 0.007);
        assert_eq!(a.ready(), None);
        assert_eq!(a.counts, FrameCounts::default());
        a.put(&block(8, 4, 2), 0.011);
        a.put(&block(12, 4, 2), 0.015);
        let (j, t) = a.ready().expect("frame 1");
        assert_eq!(j, 1);
        assert!((t - 0.008).abs() < 1e-12, "{t}");
        assert_eq!(a.sample(0).unwrap()[..2], [80, 81]);
        assert_eq!(a.sample(7).unwrap()[..2], [150, 151]);
        a.take();
        assert_eq!(a.ready(), None);
    }

    #[test]
    fn a_gap_drops_its_frame_and_a_reset_starts_over() {
        let mut a = FrameAssembler::new(8, 1e-3);
        a.put(&block(0, 4, 1), 0.0);
        // 4..7 lost: frame 0 dropped, frame 1 whole.
        a.put(&block(8, 4, 1), 0.0);
        a.put(&block(12, 4, 1), 0.0);
        assert_eq!(a.counts.gaps, 1);
        assert_eq!(a.counts.dropped, 1);
        assert_eq!(a.ready().map(|r| r.0), Some(1));
        // Frame 2 whole while 1 was not taken: superseded.
        a.put(&block(16, 8, 1), 0.0);
        assert_eq!((a.ready().map(|r| r.0), a.counts.superseded), (Some(2), 1));
        // The board resets: its counter starts at 0 again.
        a.put(&block(0, 8, 1), 0.0);
        assert_eq!(a.counts.gaps, 2);
        assert_eq!(a.ready().map(|r| r.0), Some(0));
    }

    #[test]
    fn the_counter_wraps_without_a_gap() {
        let mut a = FrameAssembler::new(4, 1e-3);
        a.put(&block(u32::MAX - 3, 4, 1), 0.0);
        a.put(&block(0, 4, 1), 0.0);
        assert_eq!(a.counts.gaps, 0);
        assert_eq!(a.ready().map(|r| r.0), Some((1u64 << 32) / 4));
    }
}
