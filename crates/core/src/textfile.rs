//! Reading the project's text files (scene, trajectory, calibration, daemon
//! config) and turning a TOML parse error into one line that names the file
//! and the line: every reader does it the same way, through here.
//!
//! Text from outside is bounded three times: a file larger than
//! [`MAX_TEXT_BYTES`] is refused before it is read whole, a line longer than
//! [`MAX_LINE_BYTES`] is refused by a line reader ([`read_line_bounded`])
//! without being kept, and whatever an error message quotes of it is cut to
//! an [`excerpt`]. A byte-order mark that an editor put at the start is
//! dropped.

use crate::textpos::line_of_offset;
use std::borrow::Cow;
use std::io::{self, BufRead, Read};
use std::path::{Path, PathBuf};

/// Largest text file we read whole: far above any scene, calibration, config
/// or trajectory a user writes (the shipped ones are a few kB), far below
/// what would hurt a small on-board computer.
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// Most characters of outside text an error message quotes.
pub const EXCERPT_CHARS: usize = 80;

/// Longest line a line reader (intensity logs, trajectory CSVs) accepts: a
/// FRAME line with every optional reading is under 1 kB and a CSV knot under
/// 200 bytes, so only garbage is this long.
pub const MAX_LINE_BYTES: usize = 64 << 10;

/// The UTF-8 byte-order mark some editors put at the start of a file.
pub const BOM: char = '\u{feff}';

/// What [`read_line_bounded`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineRead {
    /// The end of the input: nothing was read.
    Eof,
    /// A line is in the buffer, with its newline unless it was the last.
    Line,
    /// The line was longer than the bound: it was read to its end (or the
    /// input's) and thrown away, never held whole.
    TooLong,
}

/// Why a text file could not be read. Every message is one line that
/// already says its cause, so no variant has a `source()`: a reporter that
/// joins the chain (`{:#}`) would otherwise say the I/O error twice.
#[derive(Debug)]
pub enum TextError {
    /// `source` is the I/O error, shown in the message (not chained).
    Io {
        file: String,
        source: std::io::Error,
    },
    TooLarge {
        file: String,
        size: u64,
        max: u64,
    },
    NotUtf8 {
        file: String,
    },
    /// A TOML syntax or type error; `line` is 1-based.
    Syntax {
        file: String,
        line: usize,
        msg: String,
    },
}

// By hand, not thiserror: the derive makes a field named `source` the
// error's source, and the name is part of the public variant.
impl std::fmt::Display for TextError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TextError::Io { file, source } => write!(f, "{file}: {source}"),
            TextError::TooLarge { file, size, max } => write!(
                f,
                "{file}: {size} bytes is too large for this kind of file (at most {max})"
            ),
            TextError::NotUtf8 { file } => write!(f, "{file}: not valid UTF-8 text"),
            TextError::Syntax { file, line, msg } => write!(f, "{file}:{line}: {msg}"),
        }
    }
}

impl std::error::Error for TextError {}

/// `path` opened for reading without waiting in `open` for a FIFO's
/// writer: a calibration replaced by a FIFO no one writes had hung the
/// daemon's reload, its start and `--check-config` in `open(2)`. Opened
/// non-blocking, then a FIFO is made blocking again, so that a writer
/// there (`--config <(…)`) is read to its end, and one not there reads as
/// an empty file (refused as such). Regular files are as before.
fn open_never_waiting(path: &Path) -> std::io::Result<std::fs::File> {
    use nix::fcntl::{fcntl, FcntlArg, OFlag};
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    use std::os::unix::io::AsRawFd;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(OFlag::O_NONBLOCK.bits())
        .open(path)?;
    if f.metadata()?.file_type().is_fifo() {
        fcntl(f.as_raw_fd(), FcntlArg::F_SETFL(OFlag::empty())).map_err(std::io::Error::from)?;
    }
    Ok(f)
}

/// The whole text of `path`, refusing files over [`MAX_TEXT_BYTES`] without
/// reading them.
pub fn read_text(path: &Path) -> Result<String, TextError> {
    let file = path.display().to_string();
    let io = |source| TextError::Io {
        file: file.clone(),
        source,
    };
    let f = open_never_waiting(path).map_err(io)?;
    let size = f.metadata().map_err(io)?.len();
    if size > MAX_TEXT_BYTES {
        return Err(TextError::TooLarge {
            file,
            size,
            max: MAX_TEXT_BYTES,
        });
    }
    // `take` as well: a pipe or a growing file can outrun its metadata.
    let mut bytes = Vec::with_capacity(size as usize);
    f.take(MAX_TEXT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_TEXT_BYTES {
        return Err(TextError::TooLarge {
            file,
            size: bytes.len() as u64,
            max: MAX_TEXT_BYTES,
        });
    }
    let mut text = String::from_utf8(bytes).map_err(|_| TextError::NotUtf8 { file })?;
    if text.starts_with(BOM) {
        text.drain(..BOM.len_utf8());
    }
    Ok(text)
}

/// Read one line of `src` into `buf` (cleared first), keeping at most `max`
/// bytes: a longer line is consumed to its newline without being stored, so
/// that a 200 MB line costs no more memory than a short one.
pub fn read_line_bounded<R: BufRead>(
    src: &mut R,
    buf: &mut Vec<u8>,
    max: usize,
) -> io::Result<LineRead> {
    buf.clear();
    let n = src.by_ref().take(max as u64 + 1).read_until(b'\n', buf)?;
    if n == 0 {
        return Ok(LineRead::Eof);
    }
    if buf.len() <= max || buf.ends_with(b"\n") {
        return Ok(LineRead::Line);
    }
    buf.clear();
    loop {
        let chunk = src.fill_buf()?;
        if chunk.is_empty() {
            break;
        }
        match chunk.iter().position(|&b| b == b'\n') {
            Some(i) => {
                src.consume(i + 1);
                break;
            }
            None => {
                let len = chunk.len();
                src.consume(len);
            }
        }
    }
    Ok(LineRead::TooLong)
}

/// `s` without a leading byte-order mark.
pub fn strip_bom(s: &str) -> &str {
    s.strip_prefix(BOM).unwrap_or(s)
}

/// Deserialize TOML `text`; a refusal names `file`, the line of the error's
/// span (1 when the parser gives none) and the parser's message on one line.
pub fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, file: &str) -> Result<T, TextError> {
    toml::from_str(text).map_err(|e| TextError::Syntax {
        file: file.to_string(),
        line: e.span().map_or(1, |s| line_of_offset(text, s.start)),
        msg: one_line(e.message()),
    })
}

/// A message on one line, quoting at most a bounded amount of it.
pub fn one_line(msg: &str) -> String {
    let flat = msg.trim().replace(['\n', '\r'], " ");
    excerpt(&flat, 4 * EXCERPT_CHARS)
}

/// `s` with its control characters escaped (`\n`, `\u{0}`), and the
/// line separators and direction overrides that are not controls
/// (`\u{2028}`, `\u{202e}`), cut to at
/// most `max` characters of that (never inside an escape), with an
/// ellipsis when something was cut. An excerpt quotes outside text in a
/// one-line message, and a JSON or TOML string can hold a newline (the
/// attitude fuzz target found a class "A#b\ny…" that split its refusal
/// over lines); the bound is on what is written, so that a run of NULs
/// (five characters each escaped) cannot make a message long.
pub fn excerpt(s: &str, max: usize) -> String {
    let mut out = String::with_capacity(s.len().min(4 * max) + 3);
    let mut n = 0;
    for c in s.chars() {
        let w = if escaped(c) {
            c.escape_default().count()
        } else {
            1
        };
        if n + w > max {
            out.push('…');
            return out;
        }
        n += w;
        // A control character escapes to two or more.
        if w == 1 {
            out.push(c);
        } else {
            out.extend(c.escape_default());
        }
    }
    out
}

/// Characters an excerpt escapes: control characters, and those that
/// break a line or turn the text's direction without being controls (a
/// DVL audit forged an ERROR inside a WARN line with U+2028 and U+202E).
fn escaped(c: char) -> bool {
    c.is_control()
        || matches!(
            c,
            '\u{2028}'
                | '\u{2029}'
                | '\u{061C}'
                | '\u{200E}'
                | '\u{200F}'
                | '\u{202A}'..='\u{202E}'
                | '\u{2066}'..='\u{2069}'
        )
}

/// Where a text a program reads comes from: a file, read when it is needed
/// (so that a changed file is seen on reload), or text the program already
/// holds (compiled into a binary) under the name messages give it. Readers
/// of scenes, trajectories and calibrations take this, so that they need not
/// know how a program resolves names such as the daemon's `embedded:NAME`.
#[derive(Debug, Clone, PartialEq)]
pub enum TextSource {
    File(PathBuf),
    Held {
        /// How messages name it, e.g. `embedded:tank-scene`.
        name: String,
        text: Cow<'static, str>,
    },
}

impl TextSource {
    /// How messages name it: the path, or the held text's name.
    pub fn describe(&self) -> String {
        match self {
            TextSource::File(p) => p.display().to_string(),
            TextSource::Held { name, .. } => name.clone(),
        }
    }

    /// The text: a file is read now, through [`read_text`].
    pub fn read(&self) -> Result<Cow<'_, str>, TextError> {
        match self {
            TextSource::File(p) => read_text(p).map(Cow::Owned),
            TextSource::Held { text, .. } => Ok(Cow::Borrowed(text)),
        }
    }

    /// The text as a stream, for readers that take it line by line
    /// ([`read_line_bounded`]) rather than whole.
    pub fn reader(&self) -> Result<Box<dyn BufRead + '_>, TextError> {
        match self {
            TextSource::File(p) => {
                let f = std::fs::File::open(p).map_err(|source| TextError::Io {
                    file: p.display().to_string(),
                    source,
                })?;
                Ok(Box::new(io::BufReader::new(f)))
            }
            TextSource::Held { text, .. } => Ok(Box::new(text.as_bytes())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Audit: a calibration replaced by a FIFO with no writer hung the
    /// daemon in open(2) at SIGHUP and at start. It reads as empty now; a
    /// FIFO with a writer is read to the writer's end.
    #[test]
    fn a_fifo_is_read_without_waiting_for_a_writer() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cal.toml");
        nix::unistd::mkfifo(&p, nix::sys::stat::Mode::S_IRWXU).unwrap();
        assert_eq!(read_text(&p).unwrap(), "");
        // A writer holding it open (read-write: open does not wait), which
        // closes a moment after writing.
        let mut w = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&p)
            .unwrap();
        std::io::Write::write_all(&mut w, b"a = 1\n").unwrap();
        let closer = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(500));
            drop(w);
        });
        let got = std::thread::spawn({
            let p = p.clone();
            move || read_text(&p)
        });
        closer.join().unwrap();
        assert_eq!(got.join().unwrap().unwrap(), "a = 1\n");
    }

    #[test]
    fn excerpts_are_bounded_and_cut_on_characters() {
        assert_eq!(excerpt("abc", 5), "abc");
        assert_eq!(excerpt("abcdef", 3), "abc…");
        assert_eq!(excerpt("ééééé", 2), "éé…");
        assert_eq!(excerpt("A#b\ny\r\u{1b}z", 7), "A#b\\ny…");
        assert_eq!(excerpt("A#b\ny\r\u{1b}z", 16), "A#b\\ny\\r\\u{1b}z");
        // The bound is on what is written: NULs escape to five characters.
        assert_eq!(excerpt(&"\0".repeat(100), 12), "\\u{0}\\u{0}…");
        let long = "x".repeat(1 << 20);
        assert!(one_line(&long).chars().count() <= 4 * EXCERPT_CHARS + 1);
        assert_eq!(one_line("a\nb\r\nc"), "a b  c");
        // Nor can a line separator or a direction override forge a line
        // in the log, or turn what follows.
        assert_eq!(
            excerpt("ok\u{2028}ERROR forged\u{202e}dekrow", 40),
            "ok\\u{2028}ERROR forged\\u{202e}dekrow"
        );
        assert_eq!(excerpt("a\u{2029}\u{2066}b", 40), "a\\u{2029}\\u{2066}b");
    }

    #[test]
    fn long_lines_are_thrown_away_whole_and_reading_goes_on() {
        let text = format!("short\n{}\nnext\nlast", "z".repeat(1000));
        let mut src = text.as_bytes();
        let mut buf = Vec::new();
        let mut got = Vec::new();
        loop {
            match read_line_bounded(&mut src, &mut buf, 100).unwrap() {
                LineRead::Eof => break,
                LineRead::TooLong => {
                    assert!(buf.capacity() <= 1024, "held {}", buf.capacity());
                    got.push("<long>".to_string());
                }
                LineRead::Line => got.push(String::from_utf8(buf.clone()).unwrap()),
            }
        }
        assert_eq!(got, ["short\n", "<long>", "next\n", "last"]);
        // Exactly at the bound, with or without its newline, is a line.
        let mut src = &b"abcd\nabcd"[..];
        assert_eq!(
            read_line_bounded(&mut src, &mut buf, 4).unwrap(),
            LineRead::Line
        );
        assert_eq!(
            read_line_bounded(&mut src, &mut buf, 4).unwrap(),
            LineRead::Line
        );
        assert_eq!(buf, b"abcd");
    }

    #[test]
    fn a_byte_order_mark_is_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bom.csv");
        std::fs::write(&p, "\u{feff}t,x\n").unwrap();
        assert_eq!(read_text(&p).unwrap(), "t,x\n");
        assert_eq!(strip_bom("\u{feff}a"), "a");
        assert_eq!(strip_bom("a"), "a");
    }

    #[test]
    fn toml_errors_name_file_and_line() {
        #[derive(serde::Deserialize, Debug)]
        #[allow(dead_code)]
        struct T {
            a: f64,
        }
        let e = parse_toml::<T>("\n\na = \"x\"\n", "t.toml").unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("t.toml:3: "), "{s}");
        assert_eq!(s.lines().count(), 1);
    }

    #[test]
    fn files_are_read_and_big_or_missing_ones_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.toml");
        std::fs::write(&p, "a = 1\n").unwrap();
        assert_eq!(read_text(&p).unwrap(), "a = 1\n");
        let missing = read_text(&dir.path().join("nope.toml")).unwrap_err();
        assert!(missing.to_string().contains("nope.toml"), "{missing}");
        // The cause is in the message and not chained as well, so that a
        // report of the whole chain says it once.
        match &missing {
            TextError::Io { source, .. } => {
                assert!(missing.to_string().ends_with(&source.to_string()));
            }
            other => panic!("{other:?}"),
        }
        assert!(std::error::Error::source(&missing).is_none());
        let big = dir.path().join("big.toml");
        let f = std::fs::File::create(&big).unwrap();
        f.set_len(MAX_TEXT_BYTES + 1).unwrap();
        let e = read_text(&big).unwrap_err().to_string();
        assert!(e.contains("too large"), "{e}");
        std::fs::write(&p, [0xff, 0xfe]).unwrap();
        assert!(read_text(&p).unwrap_err().to_string().contains("UTF-8"));
    }

    #[test]
    fn text_sources_read_files_now_and_held_text_as_is() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.toml");
        let file = TextSource::File(p.clone());
        assert!(file.read().unwrap_err().to_string().contains("s.toml"));
        std::fs::write(&p, "a = 2\n").unwrap();
        assert_eq!(file.read().unwrap(), "a = 2\n");
        assert_eq!(file.describe(), p.display().to_string());
        let held = TextSource::Held {
            name: "embedded:x".into(),
            text: Cow::Borrowed("b = 1\n"),
        };
        assert_eq!(held.read().unwrap(), "b = 1\n");
        assert_eq!(held.describe(), "embedded:x");
    }
}
