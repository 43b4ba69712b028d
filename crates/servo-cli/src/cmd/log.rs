//! `servo log` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Log {}

impl Log {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo log` is not implemented yet")
    }
}
