//! Water temperature for each frame: a fixed value, a DS18B20 through the
//! Linux 1-wire sysfs, or a thermistor on one of the ADC channels.
//!
//! Temperature corrects the light model but is not worth a lost frame: a
//! source that fails gives the configured fallback instead, and says so in
//! [`TempHealth`] so that the daemon can report it. Nothing here blocks the
//! frame: the DS18B20 (whose sysfs read takes ~750 ms for the conversion)
//! is read by a background thread and the frame takes its latest value.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use crate::chanmap::RawBoard;
use lightpose_core::light::WATER_TEMP_C;

/// Why a temperature reading was not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TempError {
    #[error("{path}: {msg}")]
    Io { path: String, msg: String },
    #[error("{path}: CRC check failed (NO)")]
    Crc { path: String },
    #[error("{path}: unreadable w1_slave contents: {msg}")]
    Format { path: String, msg: String },
    #[error("{path}: 85.000 °C is the DS18B20 power-on value, not a reading")]
    PowerOn { path: String },
    #[error("{path}: all-zero scratchpad, which passes its CRC: the 1-wire bus read nothing (device lost or line shorted)")]
    Blank { path: String },
    #[error(
        "{path}: {t_c:.3} °C is not water's ({}..{} °C)",
        WATER_TEMP_C.start(),
        WATER_TEMP_C.end()
    )]
    NotWater { path: String, t_c: f64 },
    #[error("no DS18B20 (28-*) under {root}")]
    NoDevice { root: String },
    #[error("no reading for {age_s:.1} s")]
    Stale { age_s: f64 },
    #[error("thermistor reads {counts} counts (open or shorted)")]
    ThermistorRail { counts: u16 },
    #[error("thermistor gives {t_c:.1} °C, outside {min_c}..{max_c} °C")]
    OutOfRange { t_c: f64, min_c: f64, max_c: f64 },
}

impl TempError {
    /// The file the error is about, for those that have one.
    fn path(&self) -> Option<&str> {
        match self {
            TempError::Io { path, .. }
            | TempError::Crc { path }
            | TempError::Format { path, .. }
            | TempError::PowerOn { path }
            | TempError::Blank { path }
            | TempError::NotWater { path, .. } => Some(path),
            TempError::NoDevice { root } => Some(root),
            TempError::Stale { .. }
            | TempError::ThermistorRail { .. }
            | TempError::OutOfRange { .. } => None,
        }
    }

    /// The same failure as `other`, its values aside (an age, a reading):
    /// the same kind at the same place. Compares without allocating.
    pub fn same_failure(&self, other: &TempError) -> bool {
        std::mem::discriminant(self) == std::mem::discriminant(other) && self.path() == other.path()
    }
}

/// Parse the contents of a `w1_slave` file into °C:
///
/// ```text
/// 72 01 4b 46 7f ff 0e 10 57 : crc=57 YES
/// 72 01 4b 46 7f ff 0e 10 57 t=23125
/// ```
pub fn parse_w1_slave(text: &str, path: &str) -> Result<f64, TempError> {
    let mut lines = text.lines();
    let crc = lines.next().unwrap_or("").trim_end();
    if crc.ends_with("NO") {
        return Err(TempError::Crc { path: path.into() });
    }
    if !crc.ends_with("YES") {
        return Err(TempError::Format {
            path: path.into(),
            msg: "first line has no YES/NO".into(),
        });
    }
    // A bus that answers nothing reads all zeros, whose CRC is 0: "YES".
    let bytes = crc.split(':').next().unwrap_or("");
    if bytes.split_whitespace().count() == 9 && bytes.split_whitespace().all(|b| b == "00") {
        return Err(TempError::Blank { path: path.into() });
    }
    let data = lines.next().unwrap_or("");
    let t = data
        .split_once("t=")
        .map(|(_, v)| v.trim())
        .ok_or_else(|| TempError::Format {
            path: path.into(),
            msg: "second line has no t=".into(),
        })?;
    let milli: i32 = t.parse().map_err(|_| TempError::Format {
        path: path.into(),
        msg: format!("t={t} is not an integer"),
    })?;
    if milli == 85_000 {
        return Err(TempError::PowerOn { path: path.into() });
    }
    // A glitch can give any value the 12 bits hold (−55…125 °C): one no
    // water has would be a wrong correction of every channel, so the
    // fallback is taken instead, as for any other failed reading.
    let t_c = milli as f64 / 1000.0;
    if !WATER_TEMP_C.contains(&t_c) {
        return Err(TempError::NotWater {
            path: path.into(),
            t_c,
        });
    }
    Ok(t_c)
}

/// Find and read one DS18B20 under a sysfs root (normally
/// `/sys/bus/w1/devices`; tests give a tempdir).
#[derive(Debug, Clone)]
pub struct Ds18b20 {
    pub root: PathBuf,
    /// `28-xxxxxxxxxxxx`; `None` takes the first one found (sorted).
    pub device: Option<String>,
}

impl Ds18b20 {
    fn slave_path(&self) -> Result<PathBuf, TempError> {
        if let Some(d) = &self.device {
            return Ok(self.root.join(d).join("w1_slave"));
        }
        let no_device = || TempError::NoDevice {
            root: self.root.display().to_string(),
        };
        let mut ids: Vec<String> = fs::read_dir(&self.root)
            .map_err(|_| no_device())?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("28-"))
            .collect();
        ids.sort();
        ids.first()
            .map(|d| self.root.join(d).join("w1_slave"))
            .ok_or_else(no_device)
    }

    /// One blocking reading (≈ 750 ms on real hardware).
    pub fn read_once(&self) -> Result<f64, TempError> {
        let path = self.slave_path()?;
        let p = path.display().to_string();
        let text = fs::read_to_string(&path).map_err(|e| TempError::Io {
            path: p.clone(),
            msg: e.to_string(),
        })?;
        parse_w1_slave(&text, &p)
    }
}

#[derive(Debug, Default)]
struct W1Shared {
    last: Option<(f64, Instant)>,
    error: Option<TempError>,
    reads: u64,
}

/// A DS18B20 read every `interval` by its own thread.
#[derive(Debug)]
pub struct Ds18b20Watcher {
    shared: Arc<Mutex<W1Shared>>,
    stop: Arc<AtomicBool>,
    max_age: Duration,
}

impl Ds18b20Watcher {
    pub fn spawn(sensor: Ds18b20, interval: Duration, max_age: Duration) -> Self {
        let shared = Arc::new(Mutex::new(W1Shared::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (sh, st) = (shared.clone(), stop.clone());
        let spawned = thread::Builder::new()
            .name("ds18b20".into())
            .spawn(move || {
                while !st.load(Ordering::Relaxed) {
                    let r = sensor.read_once();
                    if let Ok(mut s) = sh.lock() {
                        s.reads += 1;
                        match r {
                            Ok(v) => {
                                s.last = Some((v, Instant::now()));
                                s.error = None;
                            }
                            Err(e) => s.error = Some(e),
                        }
                    }
                    // sleep in slices so that dropping the watcher ends us soon
                    let until = Instant::now() + interval;
                    while !st.load(Ordering::Relaxed) && Instant::now() < until {
                        thread::sleep(Duration::from_millis(20).min(interval));
                    }
                }
            });
        if let Err(e) = spawned {
            // Out of threads: the watcher stays empty, every frame gets the
            // fallback and the health says why.
            if let Ok(mut s) = shared.lock() {
                s.error = Some(TempError::Io {
                    path: "ds18b20 thread".into(),
                    msg: e.to_string(),
                });
            }
        }
        Ds18b20Watcher {
            shared,
            stop,
            max_age,
        }
    }

    /// The latest fresh value, or why there is none.
    pub fn latest(&self) -> Result<f64, TempError> {
        self.with_latest(|r| r.map_err(TempError::clone))
    }

    /// `f` of the latest fresh value, or of why there is none: the error
    /// lent, not cloned (per frame, a clone would allocate its path).
    pub fn with_latest<R>(&self, f: impl FnOnce(Result<f64, &TempError>) -> R) -> R {
        let s = match self.shared.lock() {
            Ok(s) => s,
            Err(p) => p.into_inner(),
        };
        match (s.last, &s.error) {
            (Some((v, at)), None) if at.elapsed() <= self.max_age => f(Ok(v)),
            (_, Some(e)) => f(Err(e)),
            (Some((_, at)), None) => f(Err(&TempError::Stale {
                age_s: at.elapsed().as_secs_f64(),
            })),
            (None, None) => f(Err(&TempError::Stale { age_s: 0.0 })),
        }
    }

    /// How many times the thread has read the file.
    pub fn reads(&self) -> u64 {
        self.shared.lock().map(|s| s.reads).unwrap_or(0)
    }
}

impl Drop for Ds18b20Watcher {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Where the thermistor sits in its divider with a fixed resistor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ThermistorPosition {
    /// Thermistor from the ADC input to ground, fixed resistor to supply.
    Low,
    /// Thermistor from supply to the ADC input, fixed resistor to ground.
    High,
}

/// An NTC thermistor on an ADC channel, Steinhart–Hart
/// 1/T = A + B·ln R + C·(ln R)³.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thermistor {
    pub board: usize,
    pub channel: u8,
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub r_fixed_ohm: f64,
    pub position: ThermistorPosition,
    /// Divider supply; the ADC's reference may differ (ADS1115's FSR).
    pub v_supply: f64,
    pub v_ref: f64,
    pub bits: u8,
    pub min_c: f64,
    pub max_c: f64,
}

impl Thermistor {
    /// Temperature from the channel's counts.
    pub fn celsius(&self, counts: u16) -> Result<f64, TempError> {
        let fs = lightpose_core::frame::full_scale(self.bits);
        let v = lightpose_core::frame::counts_to_volts(counts, self.v_ref, self.bits);
        let x = v / self.v_supply;
        if counts == 0 || counts >= fs || !(x > 0.0 && x < 1.0) {
            return Err(TempError::ThermistorRail { counts });
        }
        let r = match self.position {
            ThermistorPosition::Low => self.r_fixed_ohm * x / (1.0 - x),
            ThermistorPosition::High => self.r_fixed_ohm * (1.0 - x) / x,
        };
        let l = r.ln();
        let t_c = 1.0 / (self.a + self.b * l + self.c * l * l * l) - 273.15;
        if !(t_c >= self.min_c && t_c <= self.max_c) {
            return Err(TempError::OutOfRange {
                t_c,
                min_c: self.min_c,
                max_c: self.max_c,
            });
        }
        Ok(t_c)
    }
}

/// Where a frame's temperature comes from.
#[derive(Debug)]
pub enum TempKind {
    None,
    Fixed(f64),
    Ds18b20(Ds18b20Watcher),
    Thermistor(Thermistor),
}

/// What the daemon reports about the temperature source.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TempHealth {
    /// "none", "fixed", "ds18b20" or "thermistor".
    pub source: &'static str,
    /// The last frame got the fallback value.
    pub fallback_active: bool,
    /// Frames that got the fallback value since start.
    pub fallbacks: u64,
    /// Why the source last failed.
    pub last_error: Option<String>,
}

/// A temperature source with its fallback and its health.
#[derive(Debug)]
pub struct TempReader {
    kind: TempKind,
    fallback: f64,
    health: TempHealth,
    /// The failure whose text `health.last_error` holds.
    last_failure: Option<TempError>,
}

impl TempReader {
    pub fn new(kind: TempKind, fallback_c: f64) -> Self {
        let source = match kind {
            TempKind::None => "none",
            TempKind::Fixed(_) => "fixed",
            TempKind::Ds18b20(_) => "ds18b20",
            TempKind::Thermistor(_) => "thermistor",
        };
        TempReader {
            kind,
            fallback: fallback_c,
            health: TempHealth {
                source,
                ..TempHealth::default()
            },
            last_failure: None,
        }
    }

    /// The board and channel a thermistor needs read with every frame.
    pub fn needs_channel(&self) -> Option<(usize, u8)> {
        match &self.kind {
            TempKind::Thermistor(t) => Some((t.board, t.channel)),
            _ => None,
        }
    }

    /// The temperature to stamp on a frame whose raw board values are `raw`.
    /// Allocates only when the failure changes (in kind or place): a
    /// sensor that keeps failing the same way costs no allocation a frame.
    pub fn for_frame(&mut self, raw: &[RawBoard]) -> Option<f64> {
        let TempReader {
            kind,
            fallback,
            health,
            last_failure,
        } = self;
        let mut took = |r: Result<f64, &TempError>| match r {
            Ok(v) => {
                health.fallback_active = false;
                v
            }
            Err(e) => {
                failed(health, last_failure, *fallback, e);
                *fallback
            }
        };
        match kind {
            TempKind::None => None,
            TempKind::Fixed(v) => Some(*v),
            TempKind::Ds18b20(w) => Some(w.with_latest(took)),
            TempKind::Thermistor(t) => {
                let r = match raw.get(t.board) {
                    Some(b) => t.celsius(b[t.channel as usize]),
                    None => Err(TempError::ThermistorRail { counts: 0 }),
                };
                Some(took(r.as_ref().copied()))
            }
        }
    }

    pub fn health(&self) -> &TempHealth {
        &self.health
    }
}

/// A frame got the fallback because of `e`: counted; said (a log line,
/// the health's text) when the source starts failing or fails otherwise.
fn failed(health: &mut TempHealth, last: &mut Option<TempError>, fallback: f64, e: &TempError) {
    let otherwise = !last.as_ref().is_some_and(|l| l.same_failure(e));
    if !health.fallback_active || otherwise {
        tracing::warn!(
            "temperature source {} failed, using {fallback} °C: {e}",
            health.source
        );
    }
    if otherwise {
        health.last_error = Some(e.to_string());
        *last = Some(e.clone());
    }
    health.fallback_active = true;
    health.fallbacks += 1;
}

/// Write a fake `w1_slave` (tests and examples).
pub fn write_fake_w1(root: &Path, id: &str, contents: &str) -> std::io::Result<()> {
    let dir = root.join(id);
    fs::create_dir_all(&dir)?;
    fs::write(dir.join("w1_slave"), contents)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str =
        "72 01 4b 46 7f ff 0e 10 57 : crc=57 YES\n72 01 4b 46 7f ff 0e 10 57 t=23125\n";
    const BADCRC: &str =
        "72 01 4b 46 7f ff 0e 10 57 : crc=12 NO\n72 01 4b 46 7f ff 0e 10 57 t=23125\n";

    #[test]
    fn parses_w1_slave() {
        assert_eq!(parse_w1_slave(GOOD, "x"), Ok(23.125));
        let neg = "ff ff : crc=aa YES\nff ff t=-1250\n";
        assert_eq!(parse_w1_slave(neg, "x"), Ok(-1.25));
        assert_eq!(
            parse_w1_slave(BADCRC, "x"),
            Err(TempError::Crc { path: "x".into() })
        );
        assert!(matches!(
            parse_w1_slave("00 : crc=00 YES\n00 t=85000\n", "x"),
            Err(TempError::PowerOn { .. })
        ));
        assert!(matches!(
            parse_w1_slave("", "x"),
            Err(TempError::Format { .. })
        ));
        let blank = "00 00 00 00 00 00 00 00 00 : crc=00 YES\n00 00 00 00 00 00 00 00 00 t=0\n";
        let e = parse_w1_slave(blank, "/sys/x/w1_slave").unwrap_err();
        assert!(matches!(e, TempError::Blank { .. }), "{e}");
        assert!(
            e.to_string().starts_with("/sys/x/w1_slave: all-zero"),
            "{e}"
        );
        // A real 0 °C reading is not blank.
        let zero = "00 00 4b 46 7f ff 0c 10 1c : crc=1c YES\n00 00 4b 46 7f ff 0c 10 1c t=0\n";
        assert_eq!(parse_w1_slave(zero, "x"), Ok(0.0));
        let hot = "f8 07 4b 46 7f ff 08 10 87 : crc=87 YES\nf8 07 4b 46 7f ff 08 10 87 t=127500\n";
        let e = parse_w1_slave(hot, "/sys/x/w1_slave").unwrap_err();
        assert_eq!(
            e.to_string(),
            "/sys/x/w1_slave: 127.500 °C is not water's (-10..60 °C)"
        );
        assert!(matches!(
            parse_w1_slave("a YES\nb t=2x1\n", "x"),
            Err(TempError::Format { .. })
        ));
    }

    #[test]
    fn fake_sysfs_tree_good_crc_no_and_file_gone() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        let s = Ds18b20 {
            root: root.to_path_buf(),
            device: None,
        };
        assert!(matches!(s.read_once(), Err(TempError::NoDevice { .. })));
        write_fake_w1(root, "00-notathermometer", "junk").unwrap();
        write_fake_w1(root, "28-0000075a1b2c", GOOD).unwrap();
        assert_eq!(s.read_once(), Ok(23.125));
        write_fake_w1(root, "28-0000075a1b2c", BADCRC).unwrap();
        assert!(matches!(s.read_once(), Err(TempError::Crc { .. })));
        let named = Ds18b20 {
            root: root.to_path_buf(),
            device: Some("28-0000075a1b2c".into()),
        };
        fs::remove_file(root.join("28-0000075a1b2c/w1_slave")).unwrap();
        let e = named.read_once().unwrap_err();
        assert!(matches!(e, TempError::Io { .. }));
        assert!(e.to_string().contains("28-0000075a1b2c/w1_slave"), "{e}");
    }

    fn wait_for_reads(w: &Ds18b20Watcher, n: u64) {
        let t0 = Instant::now();
        while w.reads() < n {
            assert!(t0.elapsed() < Duration::from_secs(5), "watcher never read");
            thread::sleep(Duration::from_millis(5));
        }
    }

    /// A watcher of the first DS18B20 under `root`, read every 10 ms, once
    /// it has read.
    fn watcher_read_once(root: &Path) -> Ds18b20Watcher {
        let w = Ds18b20Watcher::spawn(
            Ds18b20 {
                root: root.to_path_buf(),
                device: None,
            },
            Duration::from_millis(10),
            Duration::from_secs(5),
        );
        wait_for_reads(&w, 1);
        w
    }

    #[test]
    fn watcher_falls_back_and_recovers_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().to_path_buf();
        write_fake_w1(&root, "28-aa", GOOD).unwrap();
        let w = watcher_read_once(&root);
        let mut r = TempReader::new(TempKind::Ds18b20(w), 19.5);
        assert_eq!(r.for_frame(&[]), Some(23.125));
        assert!(!r.health().fallback_active);

        write_fake_w1(&root, "28-aa", BADCRC).unwrap();
        let TempKind::Ds18b20(w) = &r.kind else {
            unreachable!()
        };
        let n = w.reads();
        wait_for_reads(w, n + 2);
        assert_eq!(r.for_frame(&[]), Some(19.5));
        assert_eq!(r.for_frame(&[]), Some(19.5));
        let h = r.health().clone();
        assert!(h.fallback_active);
        assert_eq!(h.fallbacks, 2);
        assert!(h.last_error.unwrap().contains("CRC"));

        fs::remove_dir_all(root.join("28-aa")).unwrap();
        let TempKind::Ds18b20(w) = &r.kind else {
            unreachable!()
        };
        let n = w.reads();
        wait_for_reads(w, n + 2);
        assert_eq!(r.for_frame(&[]), Some(19.5));
        assert_eq!(r.health().fallbacks, 3);

        write_fake_w1(&root, "28-aa", GOOD).unwrap();
        let TempKind::Ds18b20(w) = &r.kind else {
            unreachable!()
        };
        let n = w.reads();
        wait_for_reads(w, n + 2);
        assert_eq!(r.for_frame(&[]), Some(23.125));
        assert!(!r.health().fallback_active);
    }

    #[test]
    fn a_reading_no_water_has_gives_the_fallback_and_says_why() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().to_path_buf();
        let hot = "f8 07 4b 46 7f ff 08 10 87 : crc=87 YES\nf8 07 4b 46 7f ff 08 10 87 t=127500\n";
        write_fake_w1(&root, "28-aa", hot).unwrap();
        let w = watcher_read_once(&root);
        let mut r = TempReader::new(TempKind::Ds18b20(w), 14.0);
        assert_eq!(r.for_frame(&[]), Some(14.0));
        let h = r.health().clone();
        assert!(h.fallback_active && h.fallbacks == 1, "{h:?}");
        let why = h.last_error.unwrap();
        assert!(
            why.contains("28-aa/w1_slave: 127.500 °C is not water's"),
            "{why}"
        );
    }

    /// A β = 3950 NTC (R0 = 10 kΩ at 25 °C) written as Steinhart–Hart with
    /// C = 0 (A = 1/T0 − ln R0 / β, B = 1/β), so that exact values are known;
    /// r_fixed is chosen so that 512 counts of 1023 is exactly R0.
    fn ntc(position: ThermistorPosition) -> Thermistor {
        let x = 512.0 / 1023.0;
        let r_fixed = match position {
            ThermistorPosition::Low => 10_000.0 * (1.0 - x) / x,
            ThermistorPosition::High => 10_000.0 * x / (1.0 - x),
        };
        Thermistor {
            board: 0,
            channel: 7,
            a: 1.0 / 298.15 - 10_000f64.ln() / 3950.0,
            b: 1.0 / 3950.0,
            c: 0.0,
            r_fixed_ohm: r_fixed,
            position,
            v_supply: 5.0,
            v_ref: 5.0,
            bits: 10,
            min_c: -5.0,
            max_c: 45.0,
        }
    }

    #[test]
    fn thermistor_steinhart_hart_and_divider() {
        let t = ntc(ThermistorPosition::Low);
        let c = t.celsius(512).unwrap();
        assert!((c - 25.0).abs() < 1e-9, "{c}");
        // 0 °C: R = R0·exp(β(1/273.15 − 1/298.15)); on the low side the
        // input is x = R/(R + r_fixed), i.e. this many counts:
        let r0 = 10_000.0 * (3950.0 * (1.0 / 273.15 - 1.0 / 298.15f64)).exp();
        let x = r0 / (r0 + t.r_fixed_ohm);
        let counts = (x * 1023.0).round() as u16;
        let c0 = t.celsius(counts).unwrap();
        assert!(c0.abs() < 0.2, "{c0}"); // within a count of quantization
                                         // lower side: a smaller voltage is a smaller R, i.e. warmer
        assert!(t.celsius(400).unwrap() > c);
        let h = ntc(ThermistorPosition::High);
        assert!((h.celsius(512).unwrap() - 25.0).abs() < 1e-9);
        assert!(h.celsius(400).unwrap() < 25.0);
        assert_eq!(t.celsius(0), Err(TempError::ThermistorRail { counts: 0 }));
        assert_eq!(
            t.celsius(1023),
            Err(TempError::ThermistorRail { counts: 1023 })
        );
        assert!(matches!(t.celsius(50), Err(TempError::OutOfRange { .. })));
    }

    #[test]
    fn thermistor_failure_falls_back_and_counts() {
        let mut r = TempReader::new(TempKind::Thermistor(ntc(ThermistorPosition::Low)), 20.0);
        assert_eq!(r.needs_channel(), Some((0, 7)));
        let mut raw = [[0u16; 16]];
        raw[0][7] = 512;
        let good = r.for_frame(&raw).unwrap();
        assert!((good - 25.0).abs() < 1e-9);
        raw[0][7] = 1023;
        assert_eq!(r.for_frame(&raw), Some(20.0));
        assert_eq!(r.health().fallbacks, 1);
        assert!(r.health().last_error.as_deref().unwrap().contains("1023"));
        let mut f = TempReader::new(TempKind::Fixed(17.0), 20.0);
        assert_eq!(f.for_frame(&[]), Some(17.0));
        let mut n = TempReader::new(TempKind::None, 20.0);
        assert_eq!(n.for_frame(&[]), None);
        assert_eq!(n.health().source, "none");
    }
}
