//! `lightpose calibrate` (being built).

#[derive(clap::Args)]
pub struct CalibrateArgs {}

pub fn run(_a: CalibrateArgs) -> anyhow::Result<()> {
    anyhow::bail!("calibrate is not built yet")
}
