//! `servo run` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Run {}

impl Run {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo run` is not implemented yet")
    }
}
