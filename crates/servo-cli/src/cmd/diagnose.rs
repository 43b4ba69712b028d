//! `servo diagnose` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Diagnose {}

impl Diagnose {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo diagnose` is not implemented yet")
    }
}
