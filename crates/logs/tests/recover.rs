//! `lightpose recover`'s library: a recording cut anywhere (what kill -9
//! or a power loss leaves) comes back as a finished MCAP holding every
//! whole message written before the cut, exactly; a chunk that fails its
//! CRC costs its own messages, counted; metadata, attachments, private
//! records and other programs' channels are kept; a compressed chunk is
//! refused in one line; and no truncation or corruption panics, while
//! whatever it writes reads back through the `mcap` crate's summary.

mod common;

use common::{record, records};
use lightpose_core::{Cut, FrameLog};
use lightpose_logs::{recover, McapReader, RecoverError, RecoverOptions, RecoverSummary};
use mcap::records::op;
use proptest::prelude::*;
use std::collections::BTreeMap;

/// Recover `bytes`: the summary (or error) and the file written.
fn recover_bytes(bytes: &[u8]) -> (Result<RecoverSummary, RecoverError>, Vec<u8>) {
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.mcap"), dir.path().join("out.mcap"));
    std::fs::write(&input, bytes).unwrap();
    let opts = RecoverOptions { chunk_bytes: 4096 };
    let r = recover(&input, &output, &opts);
    (r, std::fs::read(&output).unwrap_or_default())
}

/// Every message of a finished file, read by the `mcap` crate: from the
/// data section, and through its summary (chunk and message indexes).
fn messages(bytes: &[u8]) -> Vec<(u16, u32, u64, Vec<u8>)> {
    let summary = mcap::Summary::read(bytes)
        .expect("the summary parses")
        .expect("a summary");
    let linear: Vec<_> = mcap::MessageStream::new(bytes)
        .expect("opens")
        .map(|m| {
            let m = m.expect("every message reads");
            (m.channel.id, m.sequence, m.log_time, m.data.into_owned())
        })
        .collect();
    let mut indexed = 0;
    for chunk in &summary.chunk_indexes {
        indexed += summary
            .stream_chunk(bytes, chunk)
            .expect("indexed chunk")
            .count();
    }
    assert_eq!(indexed, linear.len(), "the indexes reach every message");
    let stats = summary.stats.as_ref().expect("statistics");
    assert_eq!(stats.message_count as usize, linear.len());
    linear
}

/// End offsets of every message record of a finished file, top level or
/// in a chunk, in file order.
fn message_ends(bytes: &[u8]) -> Vec<usize> {
    let mut ends = Vec::new();
    let mut p = 8;
    while p + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[p + 1..p + 9].try_into().unwrap()) as usize;
        let end = p + 9 + len;
        match bytes[p] {
            op::MESSAGE => ends.push(end),
            op::CHUNK => {
                let body = &bytes[p + 9..end];
                let clen = u32::from_le_bytes(body[28..32].try_into().unwrap()) as usize;
                let mut q = p + 9 + 32 + clen + 8;
                while q < end {
                    let l = u64::from_le_bytes(bytes[q + 1..q + 9].try_into().unwrap()) as usize;
                    if bytes[q] == op::MESSAGE {
                        ends.push(q + 9 + l);
                    }
                    q += 9 + l;
                }
            }
            op::DATA_END => break,
            _ => {}
        }
        p = end;
    }
    ends
}

#[test]
fn a_recording_cut_anywhere_keeps_every_whole_message_written_before_it() {
    let bytes = record(60, 2 << 10);
    let ends = message_ends(&bytes);
    let full = messages(&bytes);
    assert_eq!(ends.len(), full.len());
    let frames_of = |b: &[u8]| {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.mcap");
        std::fs::write(&p, b).unwrap();
        let mut r = McapReader::open(&p).unwrap();
        let n = r.by_ref().map(Result::unwrap).count();
        (n, r.cut())
    };
    let data_end = records(&bytes)
        .into_iter()
        .find(|r| r.0 == op::DATA_END)
        .map(|r| r.2)
        .unwrap();
    let mut cuts: Vec<usize> = (40..bytes.len()).step_by(173).collect();
    cuts.push(bytes.len());
    for cut in cuts {
        let (r, out) = recover_bytes(&bytes[..cut]);
        let s = r.unwrap_or_else(|e| panic!("cut at {cut}: {e}"));
        let want = ends.iter().filter(|&&e| e <= cut).count();
        assert_eq!(s.messages as usize, want, "cut at {cut}: {s}");
        let got = messages(&out);
        // The same messages, in the same order, on the same channels.
        assert_eq!(got[..], full[..want], "cut at {cut}");
        assert_eq!(s.out_bytes as usize, out.len());
        assert!(
            s.kept_bytes + s.lost_bytes <= cut as u64,
            "cut at {cut}: {s}"
        );
        let line = s.to_string();
        assert!(!line.contains('\n'), "{line}");
        assert!(line.starts_with(&format!("kept {want} messages")), "{line}");
        if cut == bytes.len() {
            assert_eq!((s.cut, s.lost_bytes, s.lost_messages), (None, 0, 0), "{s}");
        } else if cut >= data_end {
            // Only the summary or footer is cut: the data are whole.
            assert_eq!((s.cut, s.lost_bytes), (None, 0), "cut at {cut}: {s}");
        } else if want > 0 {
            assert!(
                matches!(s.cut, Some(Cut::Bytes { .. })),
                "cut at {cut}: {s}"
            );
            // Ours reads it finished, with at least the frames it read
            // from the cut file (those of the complete chunks).
            let (before, _) = frames_of(&bytes[..cut]);
            let (after, c) = frames_of(&out);
            assert_eq!(c, None, "cut at {cut}");
            assert!(after >= before, "cut at {cut}: {after} < {before}");
        }
    }
}

#[test]
fn the_messages_of_the_chunk_cut_short_are_counted_unverified() {
    let bytes = record(40, 64 << 10);
    // One chunk holds everything: cut it in the middle.
    let ends = message_ends(&bytes);
    let cut = ends[ends.len() / 2] + 5;
    let (r, out) = recover_bytes(&bytes[..cut]);
    let s = r.unwrap();
    assert_eq!(s.messages as usize, ends.len() / 2 + 1);
    assert_eq!(s.unverified, s.messages);
    assert_eq!((s.chunks, s.lost_messages), (0, 1), "{s}");
    assert_eq!(messages(&out).len() as u64, s.messages);
    let line = s.to_string();
    assert!(
        line.contains("from the chunk cut short: whole records, its CRC not checkable"),
        "{line}"
    );
    assert!(line.contains("(first: byte "), "{line}");
}

#[test]
fn a_chunk_that_fails_its_crc_costs_its_own_messages_counted() {
    let bytes = record(40, 2 << 10);
    let ends = message_ends(&bytes);
    let chunks: Vec<_> = records(&bytes)
        .into_iter()
        .filter(|r| r.0 == op::CHUNK)
        .collect();
    let (_, start, end) = chunks[chunks.len() / 2];
    let in_it = ends.iter().filter(|&&e| e > start && e <= end).count();
    let mut damaged = bytes.clone();
    damaged[end - 20] ^= 0x55;
    // Cut too, after the damaged chunk: the loss is named by its chunk.
    let cut = chunks[chunks.len() - 1].2;
    let (r, out) = recover_bytes(&damaged[..cut]);
    let s = r.unwrap();
    let before_cut = ends.iter().filter(|&&e| e <= cut).count();
    assert_eq!(s.messages as usize, before_cut - in_it, "{s}");
    assert_eq!(s.lost_messages as usize, in_it, "{s}");
    assert!(s.lost_bytes >= (end - start) as u64, "{s}");
    let first = s.first_loss.clone().unwrap_or_default();
    assert!(
        first.starts_with(&format!("byte {start}: chunk CRC ")) && first.contains("dropped"),
        "{first}"
    );
    assert_eq!(messages(&out).len() as u64, s.messages);
}

/// A file as another program writes it: two schemas, a channel with
/// metadata and one without a schema, metadata, an attachment, a private
/// record, messages in small chunks.
fn foreign() -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .chunk_size(Some(300))
        .profile("ros2")
        .create(std::io::Cursor::new(Vec::new()))
        .unwrap();
    let s1 = w.add_schema("a.A", "jsonschema", b"{}").unwrap();
    let meta: BTreeMap<String, String> = [("k".to_string(), "v".to_string())].into();
    let c1 = w.add_channel(s1, "/a", "json", &meta).unwrap();
    let c2 = w
        .add_channel(0, "/raw", "octets", &BTreeMap::new())
        .unwrap();
    w.write_metadata(&mcap::records::Metadata {
        name: "m1".into(),
        metadata: [("x".to_string(), "1".to_string())].into(),
    })
    .unwrap();
    for i in 0..40u32 {
        let h = |c| mcap::records::MessageHeader {
            channel_id: c,
            sequence: i,
            log_time: u64::from(i) * 1000,
            publish_time: u64::from(i) * 1000 + 1,
        };
        w.write_to_known_channel(&h(c1), format!("{{\"i\":{i}}}").as_bytes())
            .unwrap();
        w.write_to_known_channel(&h(c2), &[i as u8; 7]).unwrap();
        if i == 10 {
            w.attach(&mcap::Attachment {
                log_time: 5,
                create_time: 6,
                name: "cal.toml".into(),
                media_type: "text/plain".into(),
                data: std::borrow::Cow::Borrowed(b"gain = 1\n"),
            })
            .unwrap();
            w.write_private_record(0x90, b"private", Default::default())
                .unwrap();
        }
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

#[test]
fn metadata_attachments_and_other_programs_channels_are_kept() {
    let bytes = foreign();
    let ends = message_ends(&bytes);
    // Cut just after the third message from the end.
    let cut = ends[ends.len() - 3] + 2;
    let (r, out) = recover_bytes(&bytes[..cut]);
    let s = r.unwrap();
    assert_eq!(s.messages as usize, ends.len() - 2, "{s}");
    assert_eq!(
        (s.schemas, s.channels, s.metadata, s.attachments),
        (1, 2, 1, 1)
    );
    let summary = mcap::Summary::read(&out).unwrap().unwrap();
    let a = summary.channels.values().find(|c| c.topic == "/a").unwrap();
    assert_eq!(a.metadata.get("k").map(String::as_str), Some("v"));
    assert_eq!(a.schema.as_ref().unwrap().name, "a.A");
    let raw = summary
        .channels
        .values()
        .find(|c| c.topic == "/raw")
        .unwrap();
    assert!(raw.schema.is_none());
    assert_eq!(summary.attachment_indexes.len(), 1);
    assert_eq!(summary.attachment_indexes[0].name, "cal.toml");
    assert_eq!(summary.metadata_indexes.len(), 1);
    let got = messages(&out);
    let full = messages(&bytes);
    assert_eq!(got[..], full[..got.len()]);
    // The profile, and the private record, as they were.
    let header = mcap::read::LinearReader::new(&out)
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    assert!(
        matches!(&header, mcap::records::Record::Header(h) if h.profile == "ros2"),
        "{header:?}"
    );
    assert!(out.windows(7).any(|w| w == b"private"));
}

#[test]
fn a_compressed_chunk_is_refused_in_one_line() {
    let bytes = record(3, 64 << 10);
    let chunk = records(&bytes)
        .into_iter()
        .find(|r| r.0 == op::CHUNK)
        .unwrap();
    let body = &bytes[chunk.1 + 9..chunk.2];
    let mut rec = body[..24].to_vec();
    rec.extend_from_slice(&0u32.to_le_bytes());
    rec.extend_from_slice(&4u32.to_le_bytes());
    rec.extend_from_slice(b"zstd");
    rec.extend_from_slice(&body[32..]);
    let mut damaged = bytes[..chunk.1].to_vec();
    damaged.push(op::CHUNK);
    damaged.extend_from_slice(&(rec.len() as u64).to_le_bytes());
    damaged.extend_from_slice(&rec);
    let (r, _) = recover_bytes(&damaged);
    let e = r.unwrap_err().to_string();
    assert!(!e.contains('\n'), "{e}");
    assert!(
        e.contains(&format!(
            "in.mcap: byte {}: chunk compressed with zstd",
            chunk.1
        )),
        "{e}"
    );
    let (r, _) = recover_bytes(b"{\"class\":\"HEADER\"}\n");
    let e = r.unwrap_err().to_string();
    assert!(
        e.ends_with("in.mcap: byte 0: not an MCAP file (no MCAP magic): nothing to recover"),
        "{e}"
    );
}

#[test]
fn a_zero_filled_tail_is_a_cut() {
    let bytes = record(40, 2 << 10);
    let ends = message_ends(&bytes);
    let at = ends[ends.len() / 2];
    let chunk_end = records(&bytes)
        .into_iter()
        .filter(|r| r.0 == op::CHUNK && r.2 <= at)
        .map(|r| r.2)
        .next_back()
        .unwrap();
    let mut damaged = bytes[..chunk_end].to_vec();
    damaged.extend(std::iter::repeat_n(0u8, 5000));
    let (r, out) = recover_bytes(&damaged);
    let s = r.unwrap();
    assert_eq!(
        s.messages as usize,
        ends.iter().filter(|&&e| e <= chunk_end).count()
    );
    assert_eq!(s.lost_bytes, 5000, "{s}");
    assert_eq!(messages(&out).len() as u64, s.messages);
}

/// A small recording: frames, poses, STATUS in 512-byte chunks.
fn small() -> Vec<u8> {
    record(6, 512)
}

/// Recover anything: no panic; what it writes is a finished MCAP holding
/// what it says.
fn recover_anything(bytes: &[u8]) {
    let (r, out) = recover_bytes(bytes);
    if let Ok(s) = r {
        assert_eq!(messages(&out).len() as u64, s.messages, "{s}");
        assert!(!s.to_string().contains('\n'));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn random_bytes_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..600), magic in any::<bool>()) {
        let mut bytes = if magic { mcap::MAGIC.to_vec() } else { Vec::new() };
        bytes.extend(tail);
        recover_anything(&bytes);
    }

    #[test]
    fn a_damaged_recording_never_panics(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut bytes = small();
        for (at, v) in flips {
            let i = at.index(bytes.len());
            bytes[i] = v;
        }
        let n = cut.index(bytes.len() + 1);
        recover_anything(&bytes[..n]);
    }

    #[test]
    fn a_damaged_foreign_file_never_panics(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut bytes = foreign();
        for (at, v) in flips {
            let i = at.index(bytes.len());
            bytes[i] = v;
        }
        let n = cut.index(bytes.len() + 1);
        recover_anything(&bytes[..n]);
    }
}
