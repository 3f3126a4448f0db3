//! Damaged MCAP: a recording cut at many offsets (what kill -9 or a power
//! loss leaves of an append-only file) reads its complete chunks and not a
//! frame more; a zero-filled tail is a cut too; garbage, a wrong schema, a
//! compressed chunk or a file that is not MCAP give one line naming the
//! file and the byte; a chunk that fails its CRC costs its own frames only;
//! random bytes never panic.

mod common;

use common::{assert_one_line_at, frame, header, record, records};
use lightpose_core::{Cut, Frame, FrameLog, LogError};
use lightpose_logs::{McapReader, McapWriter};
use mcap::records::op;
use proptest::prelude::*;
use std::collections::BTreeMap;

/// Frames in each chunk, counted by the `mcap` crate's own chunk reader:
/// (chunk end, frames in it).
fn chunk_frames(bytes: &[u8]) -> Vec<(usize, usize)> {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let frame_channel = summary
        .channels
        .values()
        .find(|c| c.topic == "/lightpose/frame")
        .unwrap()
        .id;
    records(bytes)
        .into_iter()
        .filter(|r| r.0 == op::CHUNK)
        .map(|(_, start, end)| {
            let rec = mcap::parse_record(op::CHUNK, &bytes[start + 9..end]).unwrap();
            let mcap::records::Record::Chunk { header, data } = rec else { panic!() };
            let n = mcap::read::ChunkReader::new(header, &data)
                .unwrap()
                .filter(|r| {
                    matches!(r, Ok(mcap::records::Record::Message { header, .. }) if header.channel_id == frame_channel)
                })
                .count();
            (end, n)
        })
        .collect()
}

/// The frames `frame(0..n)` as a reader gives them (degrees in a log go
/// through radians, so a written frame is not always bit for bit the one
/// read back: compare with what the JSONL of the same frames gives).
fn as_read_from_jsonl(n: u64) -> Vec<Frame> {
    let mut w = lightpose_core::LogWriter::new(Vec::new(), &header()).unwrap();
    for seq in 0..n {
        w.write_frame(&frame(seq)).unwrap();
    }
    let bytes = w.into_inner();
    let r = lightpose_core::LogReader::new(&bytes[..], "j.jsonl").unwrap();
    r.map(Result::unwrap).collect()
}

/// Frames, errors and cut of a whole read.
type Read = (Vec<Frame>, Vec<LogError>, Option<Cut>);

fn read(bytes: &[u8], name: &str) -> Result<Read, LogError> {
    let mut r = McapReader::new(bytes, name, Some(bytes.len() as u64))?;
    let (mut frames, mut errors) = (Vec::new(), Vec::new());
    for item in r.by_ref() {
        match item {
            Ok(f) => frames.push(f),
            Err(e) => errors.push(e),
        }
    }
    Ok((frames, errors, r.cut()))
}

#[test]
fn a_cut_recording_reads_its_complete_chunks_and_no_more() {
    // Chunks of about one frame with its pose: every chunk boundary is a
    // frame boundary to be found.
    let bytes = record(30, 1 << 10);
    let chunks = chunk_frames(&bytes);
    assert!(chunks.len() >= 25, "{} chunks", chunks.len());
    assert_eq!(chunks.iter().map(|c| c.1).sum::<usize>(), 30);
    let header_end = records(&bytes)
        .iter()
        .find(|r| r.0 == op::METADATA)
        .unwrap()
        .2;
    let data_end = records(&bytes).last().unwrap().2;
    // Every byte of the header, a few around each chunk boundary, a spread
    // over the rest, and around the end of the data.
    let mut cuts: Vec<usize> = (0..header_end + 16).collect();
    for &(end, _) in &chunks {
        cuts.extend(end.saturating_sub(6)..end + 6);
    }
    cuts.extend((0..bytes.len()).step_by(53));
    cuts.extend(data_end - 3..data_end + 3);
    cuts.push(bytes.len());
    cuts.retain(|&c| c <= bytes.len());
    cuts.sort_unstable();
    cuts.dedup();
    let originals = as_read_from_jsonl(30);
    let mut seen = BTreeMap::new();
    for c in cuts {
        let r = read(&bytes[..c], "cut.mcap");
        if c < header_end {
            let e = r
                .err()
                .unwrap_or_else(|| panic!("cut at {c} before the header opened"));
            assert_one_line_at(&e, "cut.mcap");
            continue;
        }
        let (frames, errors, cut) = r.unwrap_or_else(|e| panic!("cut at {c}: {e}"));
        assert!(errors.is_empty(), "cut at {c}: {errors:?}");
        let want: usize = chunks
            .iter()
            .filter(|(end, _)| *end <= c)
            .map(|x| x.1)
            .sum();
        assert_eq!(frames.len(), want, "cut at {c}");
        assert_eq!(frames[..], originals[..want], "cut at {c}");
        match cut {
            None => assert!(c >= data_end, "cut at {c} not reported"),
            Some(Cut::Bytes { offset, dropped }) => {
                assert_eq!(offset + dropped, c as u64, "cut at {c}");
                assert!(c < data_end);
            }
            Some(other) => panic!("{other:?}"),
        }
        seen.insert(want, ());
    }
    assert!(
        seen.len() > 25,
        "cuts landed after {} distinct chunk counts",
        seen.len()
    );
}

#[test]
fn a_zero_filled_tail_is_a_cut() {
    let bytes = record(40, 2 << 10);
    let chunks = chunk_frames(&bytes);
    let (end, _) = chunks[chunks.len() / 2];
    let want: usize = chunks.iter().filter(|(e, _)| *e <= end).map(|x| x.1).sum();
    let mut damaged = bytes[..end].to_vec();
    damaged.extend(std::iter::repeat_n(0u8, 10_000));
    let (frames, errors, cut) = read(&damaged, "z.mcap").unwrap();
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(frames.len(), want);
    assert_eq!(
        cut,
        Some(Cut::Bytes {
            offset: end as u64,
            dropped: 10_000
        })
    );
    // Zeros followed by anything else are garbage.
    damaged.push(1);
    let (frames, errors, _) = read(&damaged, "z.mcap").unwrap();
    assert_eq!(frames.len(), want);
    assert_eq!(errors.len(), 1);
    assert_one_line_at(&errors[0], "z.mcap");
    assert!(
        errors[0].to_string().contains(&format!("byte {end}: ")),
        "{}",
        errors[0]
    );
}

/// A recording of 40 frames in chunks of about 2 KiB, and its middle
/// chunk: where it starts and ends, the frames before it and in it.
struct MiddleChunk {
    bytes: Vec<u8>,
    start: usize,
    end: usize,
    before: usize,
    frames: usize,
}

fn middle_chunk() -> MiddleChunk {
    let bytes = record(40, 2 << 10);
    let chunks = records(&bytes)
        .into_iter()
        .filter(|r| r.0 == op::CHUNK)
        .collect::<Vec<_>>();
    let counts = chunk_frames(&bytes);
    let k = chunks.len() / 2;
    let (_, start, end) = chunks[k];
    MiddleChunk {
        bytes,
        start,
        end,
        before: counts[..k].iter().map(|c| c.1).sum(),
        frames: counts[k].1,
    }
}

#[test]
fn a_chunk_that_fails_its_crc_costs_its_own_frames() {
    let MiddleChunk {
        bytes,
        start,
        end,
        frames: in_it,
        ..
    } = middle_chunk();
    let mut damaged = bytes;
    damaged[end - 20] ^= 0x55; // inside its records
    let (frames, errors, cut) = read(&damaged, "crc.mcap").unwrap();
    assert_eq!(cut, None);
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(errors[0].skippable());
    let e = errors[0].to_string();
    assert!(
        e.starts_with(&format!("crc.mcap: byte {start}: chunk CRC")),
        "{e}"
    );
    assert_eq!(frames.len(), 40 - in_it);
}

#[test]
fn garbage_in_the_middle_ends_the_log_with_one_line() {
    let MiddleChunk {
        bytes,
        start,
        before,
        ..
    } = middle_chunk();
    let mut damaged = bytes;
    damaged[start..start + 9]
        .copy_from_slice(&[0x42, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f]);
    let (frames, errors, _) = read(&damaged, "g.mcap").unwrap();
    assert_eq!(frames.len(), before);
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(!errors[0].skippable());
    assert_one_line_at(&errors[0], "g.mcap");
    assert!(errors[0]
        .to_string()
        .contains(&format!("byte {start}: a record (opcode 0x42)")));
}

#[test]
fn what_is_not_a_lightpose_mcap_is_named() {
    let jsonl = std::fs::read(common::data("dive.jsonl")).unwrap();
    let e = read(&jsonl, "dive.mcap").err().unwrap();
    assert_eq!(
        e.to_string(),
        "dive.mcap: byte 0: not an MCAP file (no MCAP magic)"
    );
    let mut noise = mcap::MAGIC.to_vec();
    noise.extend((0..500u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8));
    let e = read(&noise, "noise.mcap").err().unwrap();
    assert_one_line_at(&e, "noise.mcap");
    assert!(e.to_string().starts_with("noise.mcap: byte 8: "), "{e}");
    // An MCAP of someone else's: no lightpose header.
    let mut w = mcap::Writer::new(std::io::Cursor::new(Vec::new())).unwrap();
    let ch = w
        .add_channel(0, "/other", "json", &BTreeMap::new())
        .unwrap();
    let h = at_time_zero(ch);
    w.write_to_known_channel(&h, b"{}").unwrap();
    w.finish().unwrap();
    let other = w.into_inner().into_inner();
    let e = read(&other, "other.mcap").err().unwrap();
    assert_one_line_at(&e, "other.mcap");
    assert!(
        e.to_string().contains("no lightpose-header metadata"),
        "{e}"
    );
}

/// A message on channel `ch`, sequence and times 0.
fn at_time_zero(ch: u16) -> mcap::records::MessageHeader {
    mcap::records::MessageHeader {
        channel_id: ch,
        sequence: 0,
        log_time: 0,
        publish_time: 0,
    }
}

/// An MCAP with lightpose's header whose frame channel has `schema` and
/// `encoding`, and one message.
fn with_frame_channel(schema: (&str, &str), encoding: &str, message: &[u8]) -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .create(std::io::Cursor::new(Vec::new()))
        .unwrap();
    let mut meta = BTreeMap::new();
    let header = "{\"adc_bits\":10,\"class\":\"HEADER\",\"cols\":5,\"format\":\"lightpose-intensity\",\"rate_hz\":5.0,\"rows\":5,\"version\":1}";
    meta.insert("json".to_string(), header.to_string());
    w.write_metadata(&mcap::records::Metadata {
        name: "lightpose-header".into(),
        metadata: meta,
    })
    .unwrap();
    let sid = w.add_schema(schema.0, schema.1, b"{}").unwrap();
    let ch = w
        .add_channel(sid, "/lightpose/frame", encoding, &BTreeMap::new())
        .unwrap();
    let h = at_time_zero(ch);
    w.write_to_known_channel(&h, message).unwrap();
    let line = b"{\"class\":\"FRAME\",\"seq\":1,\"t\":0.2,\"counts\":[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,25]}";
    w.write_to_known_channel(&h, line).unwrap();
    w.finish().unwrap();
    w.into_inner().into_inner()
}

#[test]
fn a_frame_channel_with_another_schema_is_refused() {
    let good = with_frame_channel(("lightpose.Frame", "jsonschema"), "json", b"garbage");
    let (frames, errors, _) = read(&good, "s.mcap").unwrap();
    assert_eq!(frames.len(), 1, "the good message after the bad one");
    assert_eq!(errors.len(), 1);
    assert!(errors[0].skippable());
    assert_one_line_at(&errors[0], "s.mcap");
    assert!(
        errors[0].to_string().contains("not valid JSON"),
        "{}",
        errors[0]
    );
    for (schema, enc) in [
        (("foo.Bar", "protobuf"), "protobuf"),
        (("lightpose.Frame", "jsonschema"), "cdr"),
        (("lightpose.Pose", "jsonschema"), "json"),
    ] {
        let bytes = with_frame_channel(schema, enc, b"{}");
        let (frames, errors, _) = read(&bytes, "s.mcap").unwrap();
        assert!(frames.is_empty());
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert_one_line_at(&errors[0], "s.mcap");
        let e = errors[0].to_string();
        assert!(e.contains("channel /lightpose/frame has schema"), "{e}");
        assert!(
            e.contains("lightpose reads schema lightpose.Frame (jsonschema) with json messages"),
            "{e}"
        );
    }
}

#[test]
fn a_compressed_chunk_is_named() {
    let bytes = record(3, 64 << 10);
    let chunk = records(&bytes)
        .into_iter()
        .find(|r| r.0 == op::CHUNK)
        .unwrap();
    // The same chunk, said to be zstd (its CRC is left at 0: unchecked).
    let body = &bytes[chunk.1 + 9..chunk.2];
    let csize_at = 8 * 3 + 4 + 4; // times, size, crc, empty compression string
    let records_start = csize_at + 8;
    let mut rec = Vec::new();
    rec.extend_from_slice(&body[..24]);
    rec.extend_from_slice(&0u32.to_le_bytes());
    rec.extend_from_slice(&4u32.to_le_bytes());
    rec.extend_from_slice(b"zstd");
    rec.extend_from_slice(&body[csize_at..]);
    let mut damaged = bytes[..chunk.1].to_vec();
    damaged.push(op::CHUNK);
    damaged.extend_from_slice(&(rec.len() as u64).to_le_bytes());
    damaged.extend_from_slice(&rec);
    assert_eq!(rec.len(), body.len() + 4);
    assert!(records_start < body.len());
    let (frames, errors, _) = read(&damaged, "z.mcap").unwrap();
    assert!(frames.is_empty());
    assert_one_line_at(&errors[0], "z.mcap");
    assert!(errors[0]
        .to_string()
        .contains(&format!("byte {}: chunk compressed with zstd", chunk.1)));
}

#[test]
fn a_truncated_file_converts_with_what_it_dropped_named() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = record(50, 2 << 10);
    let chunks = chunk_frames(&bytes);
    let (end, _) = chunks[chunks.len() - 4];
    let want: usize = chunks.iter().filter(|(e, _)| *e <= end).map(|x| x.1).sum();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..end + 100]).unwrap();
    let out = dir.path().join("out.jsonl");
    let s = lightpose_logs::convert(&cut, &out, None, &Default::default(), |_| {}).unwrap();
    assert_eq!(s.frames as usize, want);
    assert_eq!(
        s.cut,
        Some(Cut::Bytes {
            offset: end as u64,
            dropped: 100
        })
    );
    // The recovered MCAP is finished: the mcap crate reads its summary.
    let fixed = dir.path().join("fixed.mcap");
    lightpose_logs::convert(&cut, &fixed, None, &Default::default(), |_| {}).unwrap();
    let fixed = std::fs::read(&fixed).unwrap();
    assert!(mcap::Summary::read(&fixed).unwrap().is_some());
    let (frames, _, cut) = read(&fixed, "fixed.mcap").unwrap();
    assert_eq!((frames.len(), cut), (want, None));
}

fn small_recording() -> Vec<u8> {
    let opts = lightpose_logs::McapOptions {
        chunk_bytes: 512,
        foxglove: true,
    };
    let mut w = McapWriter::new(Vec::new(), &header(), &opts).unwrap();
    for seq in 0..6 {
        w.write_frame(&frame(seq)).unwrap();
    }
    w.finish().unwrap()
}

/// Read to the end; whatever comes out keeps the format's invariants.
fn read_anything(bytes: &[u8], size: Option<u64>) {
    if let Ok(mut r) = McapReader::new(bytes, "p.mcap", size) {
        let fs = (1u32 << r.header().adc_bits) - 1;
        for f in r.by_ref().flatten() {
            assert!(f.t.is_finite());
            assert!(f.counts.iter().all(|&c| c as u32 <= fs));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_bytes_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..600), magic in any::<bool>()) {
        let mut bytes = if magic { mcap::MAGIC.to_vec() } else { Vec::new() };
        bytes.extend(tail);
        read_anything(&bytes, Some(bytes.len() as u64));
        read_anything(&bytes, None);
    }

    #[test]
    fn a_damaged_recording_never_panics(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut bytes = small_recording();
        for (at, v) in flips {
            let i = at.index(bytes.len());
            bytes[i] = v;
        }
        let n = cut.index(bytes.len() + 1);
        read_anything(&bytes[..n], Some(n as u64));
        read_anything(&bytes, None);
    }
}

/// The first chunk holds the Schema and Channel records; one flipped bit in
/// it lost the whole file (an audit: "a message on channel 1, which no
/// Channel record declared before it", 7 of 40 random flips). Opened from
/// a file, a finished recording's summary declares the channels again, so
/// the chunk costs its own frames only; read as a stream (no summary to
/// seek to) it still ends with the one line naming the message.
#[test]
fn a_first_chunk_that_fails_its_crc_costs_its_own_frames_too() {
    let bytes = record(40, 2 << 10);
    let (_, start, end) = records(&bytes)
        .into_iter()
        .find(|r| r.0 == op::CHUNK)
        .unwrap();
    let in_first = chunk_frames(&bytes)[0].1;
    let mut damaged = bytes;
    damaged[end - 20] ^= 0x55;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("first.mcap");
    std::fs::write(&path, &damaged).unwrap();
    let mut r = McapReader::open(&path).unwrap();
    let (mut frames, mut errors) = (Vec::new(), Vec::new());
    for item in r.by_ref() {
        match item {
            Ok(f) => frames.push(f),
            Err(e) => errors.push(e),
        }
    }
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(errors[0].skippable(), "{}", errors[0]);
    assert!(
        errors[0]
            .to_string()
            .contains(&format!("byte {start}: chunk CRC")),
        "{}",
        errors[0]
    );
    // (At 2 KiB chunks the declarations, with their schemas, fill it.)
    assert!(in_first < 40);
    assert_eq!(frames.len(), 40 - in_first);
    assert_eq!(frames, as_read_from_jsonl(40)[in_first..].to_vec());
    let streamed = read(&damaged, "first.mcap");
    let fatal = match streamed {
        Ok((_, errors, _)) => errors.into_iter().find(|e| !e.skippable()),
        Err(e) => Some(e),
    };
    assert!(
        fatal.is_some_and(|e| e.to_string().contains("no Channel record declared")),
        "read as a stream"
    );
}
