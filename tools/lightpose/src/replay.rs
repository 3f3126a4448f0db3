//! `lightpose replay` (being built).

#[derive(clap::Args)]
pub struct ReplayArgs {}

pub fn run(_a: ReplayArgs) -> anyhow::Result<()> {
    anyhow::bail!("replay is not built yet")
}
