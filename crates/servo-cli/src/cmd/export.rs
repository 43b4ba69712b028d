//! `servo export` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Export {}

impl Export {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo export` is not implemented yet")
    }
}
