//! `servo params`: print the default plant parameter file with units in comments.
//! `servo params --lab`: the realistic lab plant instead (Table 2 with the friction and inertia
//! the Padova groups measured on real SRV-02s; the default plant of `servo identify --ramp` and of
//! the QEMU board).

use crate::model_file::ModelFile;

#[derive(Debug, clap::Parser)]
pub struct Params {
    /// Print the realistic lab plant: Table 2 with J_eq = 7.0e-7 kg m^2, B_eq = 1.0e-6 N m s/rad
    /// and Coulomb friction tau_sf = 9.0e-3 N m, as measured on real SRV-02s.
    #[arg(long)]
    pub lab: bool,
}

impl Params {
    pub fn run(self) -> anyhow::Result<()> {
        let file = if self.lab {
            ModelFile::from_plant(&servo_core::Plant::lab())
        } else {
            ModelFile::default()
        };
        out!("{}", file.to_toml_commented());
        Ok(())
    }
}
