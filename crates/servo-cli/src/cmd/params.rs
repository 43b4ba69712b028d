//! `servo params`: print the default simulated plant as a parameter file, units in comments:
//! the lab plant (Table 2 with the friction and inertia the Padova groups measured on real
//! SRV-02s), the plant every simulating command uses unless told otherwise.
//! `servo params --preset table2`: the handout's Table 2 as printed (no friction).

use crate::plant_args::{PlantPreset, DEFAULT_PLANT};

#[derive(Debug, clap::Parser)]
pub struct Params {
    /// Which built-in plant: `lab` (the default simulated plant: J_eq = 7.0e-7 kg m^2,
    /// B_eq = 1.0e-6 N m s/rad, Coulomb tau_sf = 9.0e-3 N m, as measured on real SRV-02s) or
    /// `table2` (the handout's Table 2, no friction).
    #[arg(long, value_enum, value_name = "PRESET")]
    pub preset: Option<PlantPreset>,
    /// Same as `--preset lab` (kept for scripts).
    #[arg(long, hide = true, conflicts_with = "preset")]
    pub lab: bool,
}

impl Params {
    pub fn run(self) -> anyhow::Result<()> {
        let preset = match (self.preset, self.lab) {
            (Some(p), _) => p,
            (None, true) => PlantPreset::Lab,
            (None, false) => DEFAULT_PLANT,
        };
        out!("{}", preset.model_file().to_toml_commented());
        Ok(())
    }
}
