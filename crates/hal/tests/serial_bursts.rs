//! Serial boards in burst mode (LPBST packets, docs/serial-protocol.md
//! "Bursts") on real pseudo-terminals: a fake firmware of two boards that
//! share one sample clock writes bursts of a simulated beacon blinking at
//! 250 Hz through daylight and its flicker, sampled at 2 kHz with the
//! channels skewed as MODEL.md says; the hal source cuts them into frames
//! and lightpose-demod recovers every detector's amplitude. Garbage, a
//! bad CRC and a cut packet are counted, and the frames they fall in are
//! dropped whole: each frame taken is exactly one frame the boards sent.
//! The config side: the keys, the conversion order and the baud check.

mod common;

use std::fs::File;
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use common::{bare_source, validate};
use lightpose_core::samples::{BeaconInfo, Burst};
use lightpose_core::NDET;
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};
use lightpose_hal::bank::BoardSource;
use lightpose_hal::chanmap::ChannelMap;
use lightpose_hal::serial::burst::encode;
use lightpose_hal::serial::{BurstPlan, SerialBank, SerialBoard};
use lightpose_hal::{FrameSource, Sampling, Take, ValidBackend};
use lightpose_testkit::pty::Pty;

const SAMPLE_HZ: f64 = 2000.0;
const RATE_HZ: f64 = 5.0;
const N: usize = 400;
const BLOCK: usize = 16;
const SKEW_S: f64 = 10e-6;
const MOD_HZ: f64 = 250.0;
/// Channels of the two boards: detectors 0..15 on b0, 16..24 on b1.
const CHANNELS: [usize; 2] = [16, 9];

/// Detector k's beacon amplitude, counts.
fn amplitude(k: usize) -> f64 {
    200.0 + 10.0 * k as f64
}

/// Detector k's sample i of the boards' counter: daylight (a level per
/// detector, flickering at 3 Hz) and the beacon, on for the first half of
/// each period, taken k · skew after the tick.
fn sample(k: usize, i: u64) -> u16 {
    let t = i as f64 / SAMPLE_HZ + k as f64 * SKEW_S;
    let day = 1000.0 + 20.0 * k as f64 + 300.0 * (2.0 * std::f64::consts::PI * 3.0 * t).sin();
    let on = (t * MOD_HZ + 0.3).rem_euclid(1.0) < 0.5;
    (day + if on { amplitude(k) } else { 0.0 }).round() as u16
}

/// What the fake firmware does to one block of one board.
#[derive(Clone, Copy, PartialEq)]
enum Fault {
    None,
    Garbage,
    BadCrc,
    Cut,
}

/// Blocks 30 (garbage before b0's), 55 (b0's CRC broken: frame 2 lost)
/// and 80 (b1's cut short: frame 3 lost) of frames of 25 blocks.
fn fault(board: usize, m: u64) -> Fault {
    match (board, m) {
        (0, 30) => Fault::Garbage,
        (0, 55) => Fault::BadCrc,
        (1, 80) => Fault::Cut,
        _ => Fault::None,
    }
}

/// The boards' packets, block after block in real time (a block every
/// 8 ms), until `stop`; all encoded before the first is sent.
fn firmware(masters: [File; 2], stop: Arc<AtomicBool>, blocks: u64) -> thread::JoinHandle<()> {
    let mut bytes: Vec<[Vec<u8>; 2]> = Vec::new();
    for m in 0..blocks {
        let mut pair: [Vec<u8>; 2] = [Vec::new(), Vec::new()];
        let mut first_slot = 0;
        for (b, &c) in CHANNELS.iter().enumerate() {
            let mut v = Vec::new();
            for i in 0..BLOCK as u64 {
                for ch in 0..c {
                    v.push(sample(first_slot + ch, m * BLOCK as u64 + i));
                }
            }
            let mut p = Vec::new();
            encode(b as u8, 12, c as u8, (m * BLOCK as u64) as u32, &v, &mut p);
            match fault(b, m) {
                Fault::None => {}
                Fault::Garbage => {
                    let mut g = b"\x00\xffhello".to_vec();
                    g.extend(&p);
                    p = g;
                }
                Fault::BadCrc => {
                    let last = p.len() - 1;
                    p[last] ^= 0x01;
                }
                Fault::Cut => p.truncate(20),
            }
            pair[b] = p;
            first_slot += c;
        }
        bytes.push(pair);
    }
    thread::spawn(move || {
        let mut masters = masters;
        let start = Instant::now();
        for (m, pair) in bytes.iter().enumerate() {
            if stop.load(Ordering::Relaxed) {
                return;
            }
            for (master, p) in masters.iter_mut().zip(pair) {
                // The reader may have gone: the test's business.
                let _ = master.write_all(p);
            }
            let due = start + Duration::from_secs_f64((m + 1) as f64 * BLOCK as f64 / SAMPLE_HZ);
            thread::sleep(due.saturating_duration_since(Instant::now()));
        }
    })
}

fn boards(paths: &[std::path::PathBuf]) -> Vec<SerialBoard> {
    paths
        .iter()
        .zip(CHANNELS)
        .enumerate()
        .map(|(i, (p, c))| SerialBoard {
            name: format!("b{i}"),
            id: i as u8,
            path: p.display().to_string(),
            baud: 921_600,
            channels: c as u8,
        })
        .collect()
}

fn source(paths: &[std::path::PathBuf]) -> BoardSource<SerialBank> {
    let bank =
        SerialBank::new(boards(paths), 12, Duration::from_millis(1000)).with_bursts(BurstPlan {
            samples_per_frame: N,
            sample_hz: SAMPLE_HZ,
        });
    bare_source(bank, ChannelMap::sequential(16)).with_sampling(Some(Sampling {
        sample_hz: SAMPLE_HZ,
        samples_per_frame: N,
        channel_skew_s: SKEW_S,
        beacons: vec![BeaconInfo {
            id: "beacon".into(),
            mod_hz: MOD_HZ,
        }],
    }))
}

/// The boards' frame j, as detector-major samples.
fn frame_of(j: u64) -> Vec<u16> {
    let mut v = Vec::with_capacity(NDET * N);
    for k in 0..NDET {
        for i in 0..N as u64 {
            v.push(sample(k, j * N as u64 + i));
        }
    }
    v
}

#[test]
fn bursts_from_two_boards_are_demodulated_and_faults_drop_whole_frames() {
    let dir = tempfile::tempdir().unwrap();
    let paths = [dir.path().join("lpbst0"), dir.path().join("lpbst1")];
    let ptys = [Pty::plug(&paths[0]), Pty::plug(&paths[1])];
    let mut src = source(&paths);
    assert_eq!(src.sampling().map(|s| s.samples_per_frame), Some(N));
    let mut burst = Burst::new(N);
    // The first take opens the ports (flushing what was there): the
    // firmware starts once they are open, at block 0.
    let e = src.next_take(&mut burst);
    assert!(e.is_err(), "nothing sent yet");
    let stop = Arc::new(AtomicBool::new(false));
    let masters = [
        ptys[0].master.try_clone().unwrap(),
        ptys[1].master.try_clone().unwrap(),
    ];
    let writer = firmware(masters, stop.clone(), 8 * 25);

    let mut cfg = DemodConfig::new(SAMPLE_HZ, RATE_HZ, vec![BeaconSpec::new("beacon", MOD_HZ)]);
    cfg.channel_skew_s = SKEW_S;
    let mut demod = Demodulator::new(cfg.validate().expect("valid"));
    let mut out = demod.output();
    let mut taken = Vec::new();
    let mut last_t = f64::NEG_INFINITY;
    for _ in 0..12 {
        match src.next_take(&mut burst) {
            Ok(Take::Burst) => {}
            Ok(Take::Frame(_)) => panic!("a serial burst bank gives bursts"),
            Err(e) => {
                eprintln!("take: {e}");
                continue;
            }
        }
        // Exactly one frame the boards sent, whole.
        let j = (0..8)
            .find(|&j| burst.samples() == &frame_of(j)[..])
            .unwrap_or_else(|| panic!("burst seq {} is no frame the boards sent", burst.seq));
        assert!(burst.t > last_t, "t goes on");
        last_t = burst.t;
        taken.push(j);
        demod
            .demodulate_burst(&burst, &mut out)
            .expect("demodulated");
        let a = &out.light.beacons[0];
        for k in 0..NDET {
            let err = a.amplitude[k] - amplitude(k);
            assert!(
                err.abs() < 2.0,
                "frame {j} detector {k}: {} for {}",
                a.amplitude[k],
                amplitude(k)
            );
        }
        if taken.len() == 5 {
            break;
        }
    }
    stop.store(true, Ordering::Relaxed);
    writer.join().unwrap();
    eprintln!("frames taken: {taken:?}");
    assert!(taken.len() >= 4, "{taken:?}");
    assert!(!taken.contains(&2) && !taken.contains(&3), "{taken:?}");
    let h = src.health();
    eprintln!("{h:?}");
    assert!(h.bad_lines >= 3, "garbage, CRC, cut: {h:?}");
    assert!(h.burst_gaps >= 2, "{h:?}");
    assert!(h.bursts_dropped >= 2, "{h:?}");
    assert!(h.last_bad_line.is_some());
}

/// A board's packets of another resolution or width fail the frame
/// naming the board and why; another board's id is named as with lines.
#[test]
fn packets_of_the_wrong_width_or_board_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let paths = [dir.path().join("w0"), dir.path().join("w1")];
    let mut ptys = [Pty::plug(&paths[0]), Pty::plug(&paths[1])];
    let bank =
        SerialBank::new(boards(&paths), 12, Duration::from_millis(300)).with_bursts(BurstPlan {
            samples_per_frame: 16,
            sample_hz: SAMPLE_HZ,
        });
    let mut src = bare_source(bank, ChannelMap::sequential(16)).with_sampling(Some(Sampling {
        sample_hz: SAMPLE_HZ,
        samples_per_frame: 16,
        channel_skew_s: SKEW_S,
        beacons: Vec::new(),
    }));
    let mut burst = Burst::new(16);
    let _ = src.next_take(&mut burst); // opens the ports
    let mut p = Vec::new();
    encode(0, 10, 16, 0, &[0; 16 * 16], &mut p);
    ptys[0].master.write_all(&p).unwrap();
    let e = src.next_take(&mut burst).unwrap_err().to_string();
    assert!(
        e.contains("board b0") && e.contains("packets say 10 bits, configured adc_bits = 12"),
        "{e}"
    );
    let mut p = Vec::new();
    encode(0, 12, 16, 16, &[0; 16 * 16], &mut p);
    ptys[0].master.write_all(&p).unwrap();
    let mut q = Vec::new();
    encode(5, 12, 9, 16, &[0; 16 * 9], &mut q);
    ptys[1].master.write_all(&q).unwrap();
    let e = src.next_take(&mut burst).unwrap_err().to_string();
    assert!(e.contains("board b1") && e.contains("board id 5"), "{e}");
}

fn serial_table(extra: &str, baud: u32) -> String {
    let map: String = (0..25)
        .map(|k| {
            let (b, ch) = if k < 16 { (0, k) } else { (1, k - 16) };
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"m{b}\"\nchannel = {ch}\n",
                k / 5,
                k % 5
            )
        })
        .collect();
    format!(
        "kind = \"serial\"\nrate_hz = 5.0\nadc_bits = 12\n{extra}\nboards = [\n  {{ name = \"m0\", id = 0, path = \"/dev/ttyACM0\", baud = {baud}, channels = 16 }},\n  {{ name = \"m1\", id = 1, path = \"/dev/ttyACM1\", baud = {baud}, channels = 9 }},\n]\n{map}"
    )
}

const BURSTS: &str =
    "sample_hz = 2000.0\nchannel_skew_s = 10e-6\nbeacons = [{ id = \"beacon\", mod_hz = 250.0 }]";

/// A serial board sampling a blinking beacon: its sampling is what the
/// demodulator is set up from; a line too slow for it is refused at the
/// board's baud with the figures, the skew is needed and must let a scan
/// fit a sample period, and detector k must be the k-th channel converted.
#[test]
fn a_serial_burst_config_is_checked_at_its_keys() {
    let v = validate(&serial_table(BURSTS, 921_600)).expect("fits");
    let ValidBackend::Serial { common, .. } = &v else {
        panic!("{v:?}")
    };
    let s = common.sampling().expect("bursts");
    assert_eq!(
        (s.samples_per_frame, s.sample_hz, s.channel_skew_s),
        (400, 2000.0, 10e-6)
    );
    assert_eq!(s.beacons[0].mod_hz, 250.0);

    let e = validate(&serial_table(BURSTS, 115_200)).unwrap_err();
    assert!(
        e.starts_with("source config: boards.m0.baud: 115200 baud moves 11520 bytes/s")
            && e.contains("need 49750 bytes/s")
            && e.contains("at most 370 Hz fits"),
        "{e}"
    );
    let e = validate(&serial_table(
        "sample_hz = 2000.0\nbeacons = [{ id = \"beacon\", mod_hz = 250.0 }]",
        921_600,
    ))
    .unwrap_err();
    assert!(
        e.starts_with("source config: channel_skew_s: needed with sample_hz"),
        "{e}"
    );
    let e = validate(&serial_table(&BURSTS.replace("10e-6", "30e-6"), 921_600)).unwrap_err();
    assert!(
        e.contains("channel_skew_s") && e.contains("the scans would overlap"),
        "{e}"
    );
    let e = validate(&serial_table(
        "sample_hz = 2000.0\nchannel_skew_s = 1e-5",
        921_600,
    ))
    .unwrap_err();
    assert!(e.starts_with("source config: beacons:"), "{e}");
    let e = validate(&serial_table("channel_skew_s = 1e-5", 921_600)).unwrap_err();
    assert!(
        e.starts_with("source config: channel_skew_s: given without"),
        "{e}"
    );
    // Detectors 0 and 1 swapped: not the boards' conversion order.
    let swapped = serial_table(BURSTS, 921_600)
        .replacen(
            "board = \"m0\"\nchannel = 0\n",
            "board = \"m0\"\nchannel = X\n",
            1,
        )
        .replacen(
            "board = \"m0\"\nchannel = 1\n",
            "board = \"m0\"\nchannel = 0\n",
            1,
        )
        .replacen("channel = X", "channel = 1", 1);
    let e = validate(&swapped).unwrap_err();
    assert!(
        e.starts_with(
            "source config: map: bursts need detector k to be the k-th channel converted"
        ) && e.contains("detector 0 (r = 0, c = 0) is board m0's channel 1"),
        "{e}"
    );
    // One line a frame, as before: no burst keys needed.
    assert!(validate(&serial_table("", 115_200)).is_ok());
}
