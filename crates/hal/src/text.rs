//! The words of a [`SourceError`](crate::SourceError) — its place and its
//! message — made so that a source that fails on every frame (a silent
//! board, a chip that NAKs, for hours) does not allocate per frame:
//!
//! - [`Text`] is cheap to clone and to build: static text, short text
//!   (up to [`INLINE`] bytes, numbers and all) kept inline, or longer text
//!   shared behind an `Arc`. A board's place is built once, at open, and
//!   cloned into each failure.
//! - [`Recent`] builds text that a failure repeats (an error from the bus,
//!   the OS or a serial port) only when it changes: it formats into a
//!   buffer it keeps and hands out the same shared text while the words
//!   stay the same.

use std::fmt::{self, Write as _};
use std::ops::Deref;
use std::sync::Arc;

/// The longest text kept inline (no allocation), in bytes: a serial
/// line's "line seq 123456789 has 8 values, channel 15 is mapped" fits, as
/// does a simulator's injected fault before frame 10^15. As large as it
/// can be with a `SourceError` of two texts under clippy's 128 bytes for
/// an error (`result_large_err`): a [`Text`] is 56 bytes.
pub const INLINE: usize = 54;

/// Text of an error: a place or a message. Derefs to `str`; compares,
/// prints and debugs as its words, whatever way they are kept.
#[derive(Clone)]
pub struct Text(Repr);

#[derive(Clone)]
enum Repr {
    Static(&'static str),
    Inline { len: u8, bytes: [u8; INLINE] },
    Shared(Arc<str>),
}

/// Fills an inline buffer; refuses (with `fmt::Error`) a piece that does
/// not fit, so that what it holds is always whole `str` pieces.
struct Fill {
    len: usize,
    bytes: [u8; INLINE],
}

impl fmt::Write for Fill {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        let room = self.bytes.get_mut(self.len..end).ok_or(fmt::Error)?;
        room.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

impl Text {
    /// Static text: no allocation, ever.
    pub const fn from_static(s: &'static str) -> Self {
        Text(Repr::Static(s))
    }

    /// Format `args` (`format_args!`): inline when the result fits in
    /// [`INLINE`] bytes (no allocation), else in one shared allocation.
    pub fn format(args: fmt::Arguments<'_>) -> Self {
        if let Some(s) = args.as_str() {
            return Text::from_static(s);
        }
        let mut fill = Fill {
            len: 0,
            bytes: [0; INLINE],
        };
        if fill.write_fmt(args).is_ok() {
            return Text::inline(fill);
        }
        let mut s = String::new();
        // A Display that fails leaves what it wrote: an error's text, not
        // worth a panic.
        let _ = s.write_fmt(args);
        Text(Repr::Shared(Arc::from(s)))
    }

    fn inline(fill: Fill) -> Self {
        Text(Repr::Inline {
            // fill.len <= INLINE < 256
            len: fill.len as u8,
            bytes: fill.bytes,
        })
    }

    pub fn as_str(&self) -> &str {
        match &self.0 {
            Repr::Static(s) => s,
            // Only whole `str` pieces are ever copied in (`Fill`).
            Repr::Inline { len, bytes } => {
                std::str::from_utf8(&bytes[..*len as usize]).unwrap_or_default()
            }
            Repr::Shared(s) => s,
        }
    }
}

impl Default for Text {
    fn default() -> Self {
        Text::from_static("")
    }
}

impl Deref for Text {
    type Target = str;
    fn deref(&self) -> &str {
        self.as_str()
    }
}

impl AsRef<str> for Text {
    fn as_ref(&self) -> &str {
        self.as_str()
    }
}

impl fmt::Display for Text {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self.as_str(), f)
    }
}

impl fmt::Debug for Text {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self.as_str(), f)
    }
}

impl PartialEq for Text {
    fn eq(&self, other: &Text) -> bool {
        self.as_str() == other.as_str()
    }
}

impl Eq for Text {}

impl PartialEq<str> for Text {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<&str> for Text {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

impl std::hash::Hash for Text {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        self.as_str().hash(h)
    }
}

/// Copied: inline when short, else shared. For static text with no copy,
/// [`Text::from_static`].
impl From<&str> for Text {
    fn from(s: &str) -> Self {
        let mut fill = Fill {
            len: 0,
            bytes: [0; INLINE],
        };
        match fill.write_str(s) {
            Ok(()) => Text::inline(fill),
            Err(_) => Text(Repr::Shared(Arc::from(s))),
        }
    }
}

impl From<String> for Text {
    fn from(s: String) -> Self {
        if s.len() <= INLINE {
            Text::from(s.as_str())
        } else {
            Text(Repr::Shared(Arc::from(s)))
        }
    }
}

impl From<Arc<str>> for Text {
    fn from(s: Arc<str>) -> Self {
        Text(Repr::Shared(s))
    }
}

/// Text a failure repeats, built only when it changes: each call formats
/// into a buffer kept from call to call (it allocates only to grow) and
/// returns the last text again, a clone, while the words are the same.
/// Short text is inline anyway; this matters for long text (an OS
/// error's description, a hint naming boards).
#[derive(Debug, Default)]
pub struct Recent {
    buf: String,
    last: Text,
}

impl Recent {
    pub fn text(&mut self, args: fmt::Arguments<'_>) -> Text {
        self.buf.clear();
        let _ = self.buf.write_fmt(args);
        if self.last != *self.buf.as_str() {
            self.last = Text::from(self.buf.as_str());
        }
        self.last.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shared(t: &Text) -> bool {
        matches!(t.0, Repr::Shared(_))
    }

    #[test]
    fn short_text_is_inline_and_long_text_shared() {
        let seq = 10u64.pow(15) - 1;
        let t = Text::format(format_args!("sim board channel 24 (injected, frame {seq})"));
        assert_eq!(t, "sim board channel 24 (injected, frame 999999999999999)");
        assert!(!shared(&t), "{t}");
        let (seq, n) = (123_456_789, 8);
        let t = Text::format(format_args!(
            "line seq {seq} has {n} values, channel 15 is mapped"
        ));
        assert!(!shared(&t), "{t}");
        assert_eq!(std::mem::size_of::<Text>(), 56);
        let exact = "x".repeat(INLINE);
        assert!(!shared(&Text::from(exact.as_str())));
        assert!(!shared(&Text::format(format_args!("{exact}"))));
        let long = "é".repeat(INLINE / 2 + 1);
        for t in [
            Text::from(long.as_str()),
            Text::from(long.clone()),
            Text::format(format_args!("{long}")),
        ] {
            assert!(shared(&t));
            assert_eq!(t, long.as_str());
        }
        // A multi-byte character across the limit goes whole to the heap.
        let edge = format!("{}é", "x".repeat(INLINE - 1));
        assert_eq!(Text::format(format_args!("{edge}")).as_str(), edge);
    }

    #[test]
    fn text_prints_compares_and_debugs_as_its_words() {
        let a = Text::from_static("board a");
        let b = Text::from(String::from("board a"));
        assert_eq!(a, b);
        assert_eq!(format!("[{a:>9}]"), "[  board a]");
        assert_eq!(format!("{b:?}"), "\"board a\"");
        assert_eq!(&*Text::default(), "");
    }

    #[test]
    fn recent_text_is_built_once_while_it_stays_the_same() {
        let mut r = Recent::default();
        let long = "a description longer than the inline limit of text kept in place";
        let t1 = r.text(format_args!("{long}: {}", 7));
        let t2 = r.text(format_args!("{long}: {}", 7));
        assert!(shared(&t1));
        match (&t1.0, &t2.0) {
            (Repr::Shared(x), Repr::Shared(y)) => assert!(Arc::ptr_eq(x, y)),
            _ => panic!("shared"),
        }
        let t3 = r.text(format_args!("{long}: {}", 8));
        assert_eq!(t3, format!("{long}: 8").as_str());
        assert_ne!(t1, t3);
    }
}
