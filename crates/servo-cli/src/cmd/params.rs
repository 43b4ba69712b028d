//! `servo params`: print the default plant parameter file with units in comments.

use crate::model_file::ModelFile;

#[derive(Debug, clap::Parser)]
pub struct Params {}

impl Params {
    pub fn run(self) -> anyhow::Result<()> {
        out!("{}", ModelFile::default().to_toml_commented());
        Ok(())
    }
}
