//! `servo compare` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Compare {}

impl Compare {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo compare` is not implemented yet")
    }
}
