//! `servo design` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Design {}

impl Design {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo design` is not implemented yet")
    }
}
