//! `servo ports` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Ports {}

impl Ports {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo ports` is not implemented yet")
    }
}
