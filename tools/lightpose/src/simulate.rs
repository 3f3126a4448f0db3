//! `lightpose simulate` and `lightpose sweep` (being built).

#[derive(clap::Args)]
pub struct SimulateArgs {}
#[derive(clap::Args)]
pub struct SweepArgs {}

pub fn simulate(_a: SimulateArgs) -> anyhow::Result<()> {
    anyhow::bail!("simulate is not built yet")
}
pub fn sweep(_a: SweepArgs) -> anyhow::Result<()> {
    anyhow::bail!("sweep is not built yet")
}
