//! `servo demo` (not yet implemented).

#[derive(Debug, clap::Parser)]
pub struct Demo {}

impl Demo {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`servo demo` is not implemented yet")
    }
}
