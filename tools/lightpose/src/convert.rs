//! `lightpose convert`: an intensity log from one container to the other
//! (JSON Lines ↔ MCAP, by extension), with the POSE lines of the JSONL side
//! as a file of their own. Thin: the work is `lightpose_logs::convert`.

use lightpose_logs::McapOptions;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ConvertArgs {
    /// Log to read (.jsonl or .mcap; an MCAP cut short is read up to its
    /// last complete chunk: `lightpose recover` keeps every whole record).
    #[arg(long = "in")]
    input: PathBuf,
    /// Log to write (.jsonl or .mcap).
    #[arg(long)]
    out: PathBuf,
    /// POSE lines of the JSONL side (`lightpose replay --out`): read into
    /// the MCAP's /lightpose/pose when writing MCAP, written from it when
    /// reading MCAP.
    #[arg(long)]
    poses: Option<PathBuf>,
    /// MCAP chunk size, KiB: the unit that survives a power loss.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u64).range(1..=65536))]
    chunk_kib: u64,
    /// Leave out the Foxglove channels (image, vehicle pose, transform).
    #[arg(long)]
    no_foxglove: bool,
}

pub fn run(a: ConvertArgs) -> anyhow::Result<()> {
    let opts = McapOptions {
        chunk_bytes: a.chunk_kib << 10,
        foxglove: !a.no_foxglove,
    };
    let mut shown = 0u32;
    let s = lightpose_logs::convert(&a.input, &a.out, a.poses.as_deref(), &opts, |e| {
        shown += 1;
        if shown <= 20 {
            eprintln!("lightpose: skipped {e}");
        }
    })?;
    eprintln!(
        "{} frames, {} poses: {} -> {}; {} skipped, {} other messages and {} metadata records carried, {} other records passed over",
        s.frames,
        s.poses,
        a.input.display(),
        a.out.display(),
        s.skipped,
        s.carried,
        s.metadata,
        s.other
    );
    if let Some(cut) = s.cut {
        eprintln!("lightpose: {}: {cut}", a.input.display());
    }
    if s.seq_gaps.0 > 0 {
        eprintln!(
            "lightpose: {}: {} gaps in seq, {} frames lost",
            a.input.display(),
            s.seq_gaps.0,
            s.seq_gaps.1
        );
    }
    Ok(())
}
