//! `servo identify` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Identify {}

impl Identify {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo identify` is not implemented yet")
    }
}
