//! Hardware abstraction: every way the daemon can get a frame of the array
//! (ADC boards over SPI, I²C and serial, the simulator-driven mock, a
//! recorded log) behind one trait, so that the daemon cannot tell them apart.

use lightpose_core::Frame;

/// Why a source could not give a frame. The daemon counts and logs these and
/// keeps going; `Ended` means there will be no more frames (a log or a
/// non-looping simulation ran out).
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("{place}: bus error: {msg}")]
    Bus { place: String, msg: String },
    #[error("{place}: timed out waiting for data")]
    Timeout { place: String },
    #[error("{place}: device unavailable: {msg}")]
    Unavailable { place: String, msg: String },
    #[error("{place}: bad data: {msg}")]
    BadData { place: String, msg: String },
    #[error("source ended")]
    Ended,
}

/// "Give me the next frame": 25 channels in MODEL.md's order, the ADC
/// resolution, the capture time and the temperature.
///
/// `next_frame` blocks until the frame is due (a source paces itself at its
/// configured rate, or as fast as possible where that is configured).
pub trait FrameSource: Send {
    fn next_frame(&mut self) -> Result<Frame, SourceError>;
    /// ADC resolution of the frames this source gives.
    fn adc_bits(&self) -> u8;
    /// One line saying what this source is (for logs and STATUS).
    fn describe(&self) -> String;
}
