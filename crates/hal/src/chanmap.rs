//! The channel map: which board and channel feeds which detector (r, c).
//!
//! Wiring is done by hand, and a miswired or half-written map would give
//! frames that look plausible and are wrong, so a map is accepted only if it
//! covers all 25 detectors exactly once and uses no input twice.

use lightpose_core::{COLS, NDET, ROWS};
use serde::Deserialize;

/// Most channels on one board (an Arduino Mega streams 16).
pub const MAX_CH: usize = 16;
/// The raw values of one board, indexed by channel.
pub type RawBoard = [u16; MAX_CH];

/// One line of the map as written in the config file.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapEntry {
    pub r: usize,
    pub c: usize,
    pub board: String,
    pub channel: u8,
}

/// A board as the map sees it: a name and how many channels it has.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BoardSpec {
    pub name: String,
    pub channels: u8,
}

/// Why a map is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MapError {
    #[error("channel map entry {entry}: detector ({r}, {c}) is outside the {ROWS}x{COLS} array")]
    OutOfArray { entry: usize, r: usize, c: usize },
    #[error("channel map entry {entry}: unknown board \"{board}\"")]
    UnknownBoard { entry: usize, board: String },
    #[error(
        "channel map entry {entry}: board \"{board}\" has no channel {channel} (it has {channels})"
    )]
    NoChannel {
        entry: usize,
        board: String,
        channel: u8,
        channels: u8,
    },
    #[error("channel map: detector ({r}, {c}) is mapped twice (entries {first} and {second})")]
    DuplicateDetector {
        r: usize,
        c: usize,
        first: usize,
        second: usize,
    },
    #[error("channel map: board \"{board}\" channel {channel} feeds two detectors (entries {first} and {second})")]
    DuplicateInput {
        board: String,
        channel: u8,
        first: usize,
        second: usize,
    },
    #[error("channel map: detector ({r}, {c}) is not mapped{more}")]
    Missing { r: usize, c: usize, more: String },
}

/// A validated map: for each detector index 5·r + c, its (board, channel).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelMap {
    slots: [(u8, u8); NDET],
}

impl ChannelMap {
    /// Check `entries` against `boards`; entries are numbered from 1 in
    /// errors, as a person counts lines of a config.
    pub fn new(entries: &[MapEntry], boards: &[BoardSpec]) -> Result<Self, MapError> {
        let mut slot_entry: [Option<usize>; NDET] = [None; NDET];
        let mut slots = [(0u8, 0u8); NDET];
        let mut inputs: Vec<((usize, u8), usize)> = Vec::with_capacity(entries.len());
        for (i, e) in entries.iter().enumerate() {
            let entry = i + 1;
            if e.r >= ROWS || e.c >= COLS {
                return Err(MapError::OutOfArray {
                    entry,
                    r: e.r,
                    c: e.c,
                });
            }
            let b = boards
                .iter()
                .position(|b| b.name == e.board)
                .ok_or_else(|| MapError::UnknownBoard {
                    entry,
                    board: e.board.clone(),
                })?;
            let channels = boards[b].channels.min(MAX_CH as u8);
            if e.channel >= channels {
                return Err(MapError::NoChannel {
                    entry,
                    board: e.board.clone(),
                    channel: e.channel,
                    channels,
                });
            }
            let k = e.r * COLS + e.c;
            if let Some(first) = slot_entry[k] {
                return Err(MapError::DuplicateDetector {
                    r: e.r,
                    c: e.c,
                    first,
                    second: entry,
                });
            }
            if let Some(&(_, first)) = inputs.iter().find(|(inp, _)| *inp == (b, e.channel)) {
                return Err(MapError::DuplicateInput {
                    board: e.board.clone(),
                    channel: e.channel,
                    first,
                    second: entry,
                });
            }
            inputs.push(((b, e.channel), entry));
            slot_entry[k] = Some(entry);
            // boards.len() ≤ 255 is checked by the configs that build specs
            slots[k] = (b as u8, e.channel);
        }
        let missing: Vec<usize> = (0..NDET).filter(|&k| slot_entry[k].is_none()).collect();
        if let Some(&k) = missing.first() {
            let more = if missing.len() > 1 {
                format!(" (and {} more)", missing.len() - 1)
            } else {
                String::new()
            };
            return Err(MapError::Missing {
                r: k / COLS,
                c: k % COLS,
                more,
            });
        }
        Ok(ChannelMap { slots })
    }

    /// Row-major over the boards in order, `channels` per board: detector k
    /// on board k / channels, channel k % channels. For tests, the mock and
    /// boards wired in order.
    pub fn sequential(channels: u8) -> Self {
        let mut slots = [(0u8, 0u8); NDET];
        for (k, s) in slots.iter_mut().enumerate() {
            *s = ((k / channels as usize) as u8, (k % channels as usize) as u8);
        }
        ChannelMap { slots }
    }

    /// (board index, channel) of detector `k`.
    #[inline]
    pub fn source_of(&self, k: usize) -> (usize, u8) {
        let (b, c) = self.slots[k];
        (b as usize, c)
    }

    /// Per board, the bit mask of the channels the map uses.
    pub fn wanted(&self, nboards: usize) -> Vec<u16> {
        let mut w = vec![0u16; nboards];
        for &(b, c) in &self.slots {
            if let Some(m) = w.get_mut(b as usize) {
                *m |= 1 << c;
            }
        }
        w
    }

    /// Whether (board, channel) feeds a detector.
    pub fn uses(&self, board: usize, channel: u8) -> bool {
        self.slots
            .iter()
            .any(|&(b, c)| b as usize == board && c == channel)
    }

    /// Scatter the raw board values into frame order.
    #[inline]
    pub fn apply(&self, raw: &[RawBoard], out: &mut [u16; NDET]) {
        for (o, &(b, c)) in out.iter_mut().zip(self.slots.iter()) {
            *o = raw.get(b as usize).map_or(0, |r| r[c as usize]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boards() -> Vec<BoardSpec> {
        (0..4)
            .map(|i| BoardSpec {
                name: format!("u{i}"),
                channels: 8,
            })
            .collect()
    }

    fn full_map() -> Vec<MapEntry> {
        // column-major wiring, to check that the map really permutes
        (0..NDET)
            .map(|i| MapEntry {
                r: i % ROWS,
                c: i / ROWS,
                board: format!("u{}", i / 8),
                channel: (i % 8) as u8,
            })
            .collect()
    }

    #[test]
    fn a_complete_map_is_accepted_and_permutes() {
        let m = ChannelMap::new(&full_map(), &boards()).unwrap();
        // detector (0, 1) is entry 6 (i = 5): board u0 channel 5
        assert_eq!(m.source_of(1), (0, 5));
        // detector (4, 4) is i = 24: board u3 channel 0
        assert_eq!(m.source_of(24), (3, 0));
        let mut raw = vec![[0u16; MAX_CH]; 4];
        for (b, r) in raw.iter_mut().enumerate() {
            for (c, v) in r.iter_mut().enumerate() {
                *v = (b * 100 + c) as u16;
            }
        }
        let mut out = [0u16; NDET];
        m.apply(&raw, &mut out);
        assert_eq!(out[1], 5);
        assert_eq!(out[24], 300);
        assert_eq!(out[5], 1); // (1, 0) is i = 1
        assert_eq!(m.wanted(4), vec![0xFF, 0xFF, 0xFF, 0x01]);
        assert!(m.uses(3, 0) && !m.uses(3, 1));
    }

    #[test]
    fn missing_detector_is_named() {
        let mut e = full_map();
        e.remove(7); // (2, 1)
        let err = ChannelMap::new(&e, &boards()).unwrap_err();
        assert_eq!(
            err,
            MapError::Missing {
                r: 2,
                c: 1,
                more: String::new()
            }
        );
        assert_eq!(
            err.to_string(),
            "channel map: detector (2, 1) is not mapped"
        );
        e.truncate(20);
        let msg = ChannelMap::new(&e, &boards()).unwrap_err().to_string();
        // the first missing in frame order is (1, 4), then (2, 1) and 3 others
        assert!(
            msg.contains("(1, 4)") && msg.contains("and 4 more"),
            "{msg}"
        );
    }

    #[test]
    fn duplicate_detector_is_named_with_both_entries() {
        let mut e = full_map();
        e[3].r = 0;
        e[3].c = 0; // collides with entry 1
        let err = ChannelMap::new(&e, &boards()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "channel map: detector (0, 0) is mapped twice (entries 1 and 4)"
        );
    }

    #[test]
    fn duplicate_input_is_named() {
        let mut e = full_map();
        e[24].board = "u0".into(); // u0 channel 0 again
        let err = ChannelMap::new(&e, &boards()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "channel map: board \"u0\" channel 0 feeds two detectors (entries 1 and 25)"
        );
    }

    #[test]
    fn unknown_board_bad_channel_and_outside_array() {
        let mut e = full_map();
        e[2].board = "u9".into();
        assert_eq!(
            ChannelMap::new(&e, &boards()).unwrap_err().to_string(),
            "channel map entry 3: unknown board \"u9\""
        );
        let mut e = full_map();
        e[2].channel = 8;
        assert!(matches!(
            ChannelMap::new(&e, &boards()),
            Err(MapError::NoChannel {
                entry: 3,
                channel: 8,
                channels: 8,
                ..
            })
        ));
        let mut e = full_map();
        e[0].r = 5;
        assert!(matches!(
            ChannelMap::new(&e, &boards()),
            Err(MapError::OutOfArray {
                entry: 1,
                r: 5,
                c: 0
            })
        ));
    }

    #[test]
    fn sequential_map_is_row_major() {
        let m = ChannelMap::sequential(4);
        assert_eq!(m.source_of(0), (0, 0));
        assert_eq!(m.source_of(5), (1, 1));
        assert_eq!(m.source_of(24), (6, 0));
    }
}
