//! `servo board` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Board {}

impl Board {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo board` is not implemented yet")
    }
}
