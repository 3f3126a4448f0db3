//! `lightpose montecarlo` (being built).

#[derive(clap::Args)]
pub struct MontecarloArgs {}

pub fn run(_a: MontecarloArgs) -> anyhow::Result<()> {
    anyhow::bail!("montecarlo is not built yet")
}
