//! MCP3008/MCP3208 boards on SPI, each on its own chip select: one bank
//! read converts the wanted channels chip by chip, in order.

use embedded_hal::spi::SpiDevice;

use super::{bus_error, channels_of, no_board, Bank, ChipPlaces};
use crate::chanmap::{BoardSpec, RawBoard, MAX_CH};
use crate::drivers::mcp3x08::Mcp3x08;
use crate::text::Recent;
use crate::SourceError;

/// MCP3008/MCP3208 chips, each on its own chip select.
pub struct SpiBank<S> {
    chips: Vec<(String, Mcp3x08<S>)>,
    places: Vec<ChipPlaces>,
    recent: Recent,
}

impl<S: SpiDevice + Send> SpiBank<S> {
    pub fn new(chips: Vec<(String, Mcp3x08<S>)>) -> Self {
        let places = chips
            .iter()
            .map(|(name, c)| ChipPlaces::new(format!("board {name} ({})", c.kind().name()), 8))
            .collect();
        SpiBank {
            chips,
            places,
            recent: Recent::default(),
        }
    }
    /// Give the chips back (tests check their mocks).
    pub fn into_chips(self) -> Vec<(String, Mcp3x08<S>)> {
        self.chips
    }
}

impl<S: SpiDevice + Send> Bank for SpiBank<S> {
    fn boards(&self) -> Vec<BoardSpec> {
        self.chips
            .iter()
            .map(|(n, _)| BoardSpec {
                name: n.clone(),
                channels: 8,
            })
            .collect()
    }
    fn bits(&self) -> u8 {
        self.chips.first().map_or(10, |(_, c)| c.kind().bits())
    }
    fn describe(&self) -> String {
        let kind = self
            .chips
            .first()
            .map_or("MCP3x08", |(_, c)| c.kind().name());
        format!("{} x{} on SPI", kind, self.chips.len())
    }
    fn read(&mut self, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError> {
        for (b, ((_, chip), places)) in self.chips.iter_mut().zip(&self.places).enumerate() {
            let mask = wanted.get(b).copied().unwrap_or(0);
            for ch in channels_of(mask) {
                raw[b][ch as usize] = chip
                    .read_channel(ch)
                    .map_err(|e| bus_error(&places.channel(ch), e, &mut self.recent))?;
            }
        }
        Ok(())
    }
    /// Every MCP3x08 conversion is its own transfer, so any order costs
    /// the same bus time: a burst converts in detector order.
    fn read_in_order(
        &mut self,
        order: &[(usize, u8)],
        _: &[u16],
        raw: &mut [RawBoard],
    ) -> Result<(), SourceError> {
        for &(b, ch) in order {
            let (Some((_, chip)), Some(places), Some(out)) =
                (self.chips.get_mut(b), self.places.get(b), raw.get_mut(b))
            else {
                return Err(no_board());
            };
            out[ch as usize % MAX_CH] = chip
                .read_channel(ch)
                .map_err(|e| bus_error(&places.channel(ch), e, &mut self.recent))?;
        }
        Ok(())
    }
    fn converts_in_order(&self) -> bool {
        true
    }
}
