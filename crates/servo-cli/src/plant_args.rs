//! The simulated plant on the command line: `--plant FILE`, `--plant-effect`, sensor options.
//!
//! Commands that simulate (`run`, `demo`, `identify`, `board`) flatten [`PlantArgs`]:
//!
//! ```text
//! --plant truth.toml                          model file: [params], [effects.<name>], [sensors]
//! --plant-preset table2                       a built-in plant instead of a file (default: lab)
//! --plant-effect NAME:KEY=VALUE,...           repeatable; registry syntax (see --help)
//! --seed 7 --counts-per-rev 4096 --current-noise-a 2e-3
//! ```
//!
//! Precedence: the built-in plant [`DEFAULT_PLANT`] (the lab motor, with friction as measured
//! on real SRV-02s) when no file or preset is given; the file's params and effects; then each
//! `--plant-effect` activates or replaces its effect; the sensor flags override `[sensors]`.

use crate::model_file::ModelFile;
use anyhow::{bail, Context};
use servo_core::effects::Effect;
use servo_core::sim::SensorConfig;
use servo_core::Plant;
use std::path::PathBuf;

/// The built-in simulated plants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlantPreset {
    /// A realistic SRV-02 (`servo params`): Table 2 with J_eq = 7.0e-7 kg m^2, viscous
    /// B_eq = 1.0e-6 N m s/rad and Coulomb tau_sf = 9.0e-3 N m, the levels the Padova groups
    /// measured on their lab motors.
    Lab,
    /// The handout's Table 2 as printed: no friction (B_m = B_l = 0), J_eq from eq. 10.
    Table2,
}

/// The simulated plant of every command when no `--plant`/`--plant-preset` is given.
pub const DEFAULT_PLANT: PlantPreset = PlantPreset::Lab;

impl PlantPreset {
    /// The preset as a model file (no sensors section).
    pub fn model_file(self) -> ModelFile {
        match self {
            PlantPreset::Lab => ModelFile::from_plant(&Plant::lab()),
            PlantPreset::Table2 => ModelFile::default(),
        }
    }
    /// Its name in messages.
    pub fn describe(self) -> &'static str {
        match self {
            PlantPreset::Lab => "the lab plant (Table 2 with measured friction)",
            PlantPreset::Table2 => "Table 2 (no friction)",
        }
    }
}

/// Options that define the simulated plant ("truth") and its sensors.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PlantArgs {
    /// Plant file (TOML model file: [params], [effects.<name>], [sensors]); default: the lab
    /// plant of `servo params` (Table 2 with friction as measured on real SRV-02s).
    #[arg(long = "plant", value_name = "FILE")]
    pub plant: Option<PathBuf>,

    /// A built-in plant instead of a file: `lab` (the default) or `table2` (the handout's
    /// Table 2 without friction).
    #[arg(
        long = "plant-preset",
        value_enum,
        value_name = "PRESET",
        conflicts_with = "plant"
    )]
    pub plant_preset: Option<PlantPreset>,

    /// Activate or replace a physical effect of the simulated plant, e.g.
    /// `coulomb:tau_sf=0.006`. Repeatable; `--help` lists every effect and its parameters.
    #[arg(
        long = "plant-effect",
        value_name = "NAME[:KEY=VALUE,...]",
        value_parser = parse_plant_effect,
        long_help = plant_effect_help()
    )]
    pub plant_effect: Vec<Effect>,

    /// Seed of the simulated sensor noise (overrides [sensors] seed).
    #[arg(long = "seed", value_name = "N")]
    pub seed: Option<u64>,

    /// Simulated encoder resolution [counts/rev] at the load; 0 = no quantisation (default 4096).
    #[arg(long = "counts-per-rev", value_name = "COUNTS")]
    pub counts_per_rev: Option<u32>,

    /// Standard deviation of the simulated current-sensor noise [A] (default 2e-3).
    #[arg(long = "current-noise-a", value_name = "AMPS")]
    pub current_noise_a: Option<f64>,
}

/// The long help of `--plant-effect`: every registered effect with its parameters and units.
fn plant_effect_help() -> String {
    format!(
        "Activate or replace a physical effect of the simulated plant, e.g. `coulomb:tau_sf=0.006`. Repeatable. Effects: {}.",
        servo_core::effects::ParamsSummary
    )
}

/// Parses one `--plant-effect` value; every parameter must end up set (given or defaulted).
fn parse_plant_effect(s: &str) -> Result<Effect, String> {
    let e = Effect::parse(s).map_err(|e| e.to_string())?;
    e.check_complete().map_err(|e| e.to_string())?;
    Ok(e)
}

impl PlantArgs {
    /// The plant in one word, as a gains file's `[design] plant` records it: the preset's name
    /// (`lab`, `table2`) or the `--plant` file as given; `+effects` when `--plant-effect` adds
    /// some.
    pub fn key(&self) -> String {
        let base = match &self.plant {
            Some(p) => p.display().to_string(),
            None => match self.plant_preset.unwrap_or(DEFAULT_PLANT) {
                PlantPreset::Lab => "lab".to_string(),
                PlantPreset::Table2 => "table2".to_string(),
            },
        };
        if self.plant_effect.is_empty() {
            base
        } else {
            format!("{base}+effects")
        }
    }

    /// The plant in words, for the one line a simulating command prints.
    pub fn words(&self) -> String {
        let base = match &self.plant {
            Some(p) => format!("the plant of {}", p.display()),
            None => self
                .plant_preset
                .unwrap_or(DEFAULT_PLANT)
                .describe()
                .to_string(),
        };
        if self.plant_effect.is_empty() {
            base
        } else {
            let e: Vec<String> = self.plant_effect.iter().map(|e| e.to_string()).collect();
            format!("{base} with {}", e.join(", "))
        }
    }

    /// The transmission of the `--plant` file (the handout's gear for a preset).
    pub fn transmission(&self) -> anyhow::Result<servo_core::Transmission> {
        match &self.plant {
            Some(path) => Ok(ModelFile::load(path).context("--plant")?.transmission),
            None => Ok(servo_core::Transmission::GEAR),
        }
    }

    /// The drive of the `--plant` file (`[drive]`; the presets' voltage amplifier).
    pub fn drive(&self) -> anyhow::Result<servo_core::drive::Drive> {
        match &self.plant {
            Some(path) => Ok(ModelFile::load(path).context("--plant")?.drive),
            None => Ok(self
                .plant_preset
                .unwrap_or(DEFAULT_PLANT)
                .model_file()
                .drive),
        }
    }

    /// The base plant's linear parameters (the file or preset, without `--plant-effect`),
    /// read without a word: what a gains file's `[design.plant_params]` is compared with.
    pub fn base_params(&self) -> Option<servo_core::PlantParams> {
        let file = match &self.plant {
            Some(path) => ModelFile::load(path).ok()?,
            None => self.plant_preset.unwrap_or(DEFAULT_PLANT).model_file(),
        };
        file.plant().ok().map(|p| p.linear_params())
    }

    /// The plant and sensor configuration these options describe.
    pub fn load(&self) -> anyhow::Result<(Plant, SensorConfig)> {
        let preset = self.plant_preset.unwrap_or(DEFAULT_PLANT);
        let file = match &self.plant {
            Some(path) => {
                let file = ModelFile::load(path).context("--plant")?;
                let given: Vec<&str> = self
                    .plant_effect
                    .iter()
                    .filter_map(|e| match e.kind {
                        servo_core::effects::EffectKind::Coulomb => Some("tau_sf"),
                        servo_core::effects::EffectKind::Viscous => Some("b_eq"),
                        _ => None,
                    })
                    .collect();
                file.warn_defaults(&format!("--plant {}", path.display()), &given);
                file
            }
            None => preset.model_file(),
        };
        let mut plant = file.plant().with_context(|| match &self.plant {
            Some(p) => format!("--plant {}", p.display()),
            None => format!("built-in plant: {}", preset.describe()),
        })?;
        for e in &self.plant_effect {
            e.check_complete()
                .with_context(|| format!("--plant-effect {e}"))?;
            plant.effects.insert(*e);
        }
        let mut sensors = file.sensors.unwrap_or_default();
        if let Some(seed) = self.seed {
            sensors.seed = seed;
        }
        if let Some(c) = self.counts_per_rev {
            sensors.counts_per_rev = c;
        }
        if let Some(n) = self.current_noise_a {
            if !(n.is_finite() && n >= 0.0) {
                bail!("--current-noise-a must be a finite standard deviation >= 0 A, got {n}");
            }
            sensors.current_noise_a = n;
        }
        sensors
            .validate()
            .context("simulated sensors ([sensors] or sensor flags)")?;
        // Build a simulator once so that every effect combination is checked here (e.g. a delay
        // longer than the delay line, a contact's inertia fraction outside (0, 1)).
        servo_core::sim::PlantSim::new(&plant, 1e-3).context("simulated plant")?;
        Ok((plant, sensors))
    }
}

/// Refuses a `--plant` whose drive is not a voltage amplifier for `what`, a simulation that
/// applies volts: a current reference or a duty applied as volts would be silent garbage.
pub fn voltage_drive_only(plant: &PlantArgs, what: &str) -> anyhow::Result<()> {
    let drive = plant.drive()?;
    if drive.kind != servo_core::drive::DriveKind::Voltage {
        bail!(
            "--plant: {what} applies volts, but the plant's drive is `{}` (its command is {} \
             [{}]): simulate it with `servo run --plant ... --command` (open loop) or `--ref` \
             (closed loop), and identify from that log",
            drive.kind.name(),
            drive.kind.input_signal(),
            drive.kind.command_unit()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use servo_core::EffectKind;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        plant: PlantArgs,
    }

    #[test]
    fn effects_and_sensor_flags_apply() {
        let cli = Cli::try_parse_from([
            "x",
            "--plant-effect",
            "backlash:gap=0.04",
            "--plant-effect",
            "coulomb:tau_sf=0.006",
            "--seed",
            "9",
            "--counts-per-rev",
            "1024",
            "--current-noise-a",
            "0",
        ])
        .unwrap();
        let (plant, sensors) = cli.plant.load().unwrap();
        assert_eq!(plant.effects.value(EffectKind::Backlash, "gap"), Some(0.04));
        assert_eq!(plant.tau_sf(), 0.006);
        assert_eq!(sensors.seed, 9);
        assert_eq!(sensors.counts_per_rev, 1024);
        assert_eq!(sensors.current_noise_a, 0.0);
    }

    #[test]
    fn plant_file_then_flags_override() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("truth.toml");
        let mut text = ModelFile::default().to_toml_commented();
        text.push_str("\n[effects.cogging]\namplitude = 1e-4\nharmonic = 12\n\n[sensors]\ncounts_per_rev = 2048\ncurrent_noise_a = 1e-3\ncurrent_offset_a = 0.01\nseed = 3\n");
        std::fs::write(&path, text).unwrap();
        let cli = Cli::try_parse_from([
            "x",
            "--plant",
            path.to_str().unwrap(),
            "--plant-effect",
            "cogging:amplitude=2e-4,harmonic=6",
            "--seed",
            "5",
        ])
        .unwrap();
        let (plant, sensors) = cli.plant.load().unwrap();
        assert_eq!(
            plant.effects.value(EffectKind::Cogging, "amplitude"),
            Some(2e-4)
        );
        assert_eq!(
            plant.effects.value(EffectKind::Cogging, "harmonic"),
            Some(6.0)
        );
        assert_eq!(sensors.counts_per_rev, 2048);
        assert_eq!(sensors.current_offset_a, 0.01);
        assert_eq!(sensors.seed, 5);
    }

    #[test]
    fn the_default_plant_is_the_lab_motor_and_table2_is_asked_for() {
        let (plant, _) = Cli::try_parse_from(["x"]).unwrap().plant.load().unwrap();
        // (Effects hold NaN in unused slots: compare what they mean.)
        let lab = Plant::lab();
        assert_eq!(plant.params, lab.params);
        assert_eq!((plant.b_eq(), plant.tau_sf()), (lab.b_eq(), lab.tau_sf()));
        assert_eq!(plant.effects.iter().count(), 2);
        assert!(plant.b_eq() > 0.0 && plant.tau_sf() > 0.0);
        let cli = Cli::try_parse_from(["x", "--plant-preset", "table2"]).unwrap();
        let (plant, _) = cli.plant.load().unwrap();
        assert_eq!(plant.params, Plant::nominal().params);
        assert_eq!((plant.b_eq(), plant.tau_sf()), (0.0, 0.0));
        assert!(
            Cli::try_parse_from(["x", "--plant-preset", "table2", "--plant", "f.toml"]).is_err()
        );
    }

    #[test]
    fn bad_input_names_the_flag() {
        let err = Cli::try_parse_from(["x", "--plant-effect", "backlash:gapp=1"])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("--plant-effect") && err.contains("gap [rad]"),
            "{err}"
        );
        let err = Cli::try_parse_from(["x", "--plant-effect", "cogging:amplitude=1e-3"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("harmonic"), "{err}");
        let cli = Cli::try_parse_from(["x", "--current-noise-a=-1"]).unwrap();
        let err = format!("{:#}", cli.plant.load().unwrap_err());
        assert!(err.contains("--current-noise-a"), "{err}");
        let cli = Cli::try_parse_from(["x", "--plant", "/nonexistent/truth.toml"]).unwrap();
        let err = format!("{:#}", cli.plant.load().unwrap_err());
        assert!(
            err.contains("--plant") && err.contains("/nonexistent/truth.toml"),
            "{err}"
        );
    }
}
