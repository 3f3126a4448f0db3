//! `lightpose recover`: an MCAP cut short (kill -9, a power loss) rewritten
//! as a finished file with its summary, which every reader opens. Thin: the
//! work is `lightpose_logs::recover`; one line says what was kept and lost.

use lightpose_logs::RecoverOptions;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct RecoverArgs {
    /// MCAP to read (cut anywhere; it is only read).
    #[arg(long = "in")]
    input: PathBuf,
    /// MCAP to write (.mcap): finished, with summary and indexes.
    #[arg(long)]
    out: PathBuf,
    /// Chunk size of the output, KiB.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u64).range(1..=65536))]
    chunk_kib: u64,
}

pub fn run(a: RecoverArgs) -> anyhow::Result<()> {
    if lightpose_logs::Format::of_path(&a.out) != Some(lightpose_logs::Format::Mcap) {
        anyhow::bail!("{}: the output must be named .mcap", a.out.display());
    }
    let opts = RecoverOptions {
        chunk_bytes: a.chunk_kib << 10,
    };
    let s = lightpose_logs::recover(&a.input, &a.out, &opts)?;
    eprintln!("{} -> {}: {s}", a.input.display(), a.out.display());
    Ok(())
}
