//! `servo run`: the program of `--ref`, `--voltage`, `--command` or `--experiment`, and the
//! drive whose command an open-loop program gives.

use super::BackendKind;
use crate::reference_file::load_experiment_on;
use anyhow::{anyhow, bail};
use servo_core::control::program::Program;
use servo_core::control::Reference;
use servo_core::drive::{Drive, DriveKind};

impl super::Run {
    /// The drive the run's commands go to: the `--plant` file's `[drive]` on the simulator (a
    /// voltage amplifier when it has none); a board takes volts.
    pub(super) fn drive(&self) -> anyhow::Result<Drive> {
        let drive = match self.backend {
            BackendKind::Sim => self.plant.drive()?,
            BackendKind::Serial => Drive::VOLTAGE,
        };
        if drive.kind == DriveKind::Duty && drive.v_supply_v.is_none() {
            bail!(
                "--plant: a duty drive is simulated with its supply voltage: give [drive] \
                 v_supply_v in the plant file (a log may carry it as a column; a simulation \
                 cannot)"
            );
        }
        Ok(drive)
    }

    /// The flag that gives the program, as the messages name it (`--ref `step:1``).
    pub(super) fn program_flag(&self) -> String {
        match (
            &self.reference,
            &self.voltage,
            &self.command,
            &self.experiment,
        ) {
            (Some(r), _, _, _) => format!("--ref `{r}`"),
            (_, Some(v), _, _) => format!("--voltage `{v}`"),
            (_, _, Some(c), _) => format!("--command `{c}`"),
            (_, _, _, Some(p)) => format!("--experiment {}", p.display()),
            _ => String::from("the program"),
        }
    }

    /// The program and the text describing it (for the log's metadata); positions in metres on
    /// a linear axis of travel `metres_per_rad` [m/rad]. An open-loop program is the command of
    /// `drive`: `--voltage` only on a voltage drive (a current reference or a duty read as volts
    /// would be silent garbage), `--command` on any drive in its unit.
    pub(super) fn program(
        &self,
        duration_s: Option<f64>,
        metres_per_rad: Option<f64>,
        drive: &Drive,
    ) -> anyhow::Result<(Program, String)> {
        let d = duration_s.unwrap_or(5.0);
        let open_loop = |flag: &str, text: &str| -> anyhow::Result<(Program, String)> {
            let r = Reference::parse(text).map_err(|e| anyhow!("{flag} `{text}`: {e}"))?;
            let command = drive.command_kind();
            let what = format!(
                "{} {text} [{}]",
                command.input_signal(),
                command.command_unit()
            );
            Ok((Program::open_loop(r, d)?, what))
        };
        match (
            &self.reference,
            &self.voltage,
            &self.command,
            &self.experiment,
        ) {
            (Some(r), None, None, None) => Ok((
                Program::Position(
                    Reference::parse_on(r, metres_per_rad)
                        .map_err(|e| anyhow!("--ref `{r}`: {e}"))?,
                ),
                r.clone(),
            )),
            (None, Some(v), None, None) => {
                if drive.command_kind() != DriveKind::Voltage {
                    bail!(
                        "--voltage `{v}`: the plant's drive is `{}`, whose command is {} [{}], \
                         not a voltage: give the open-loop command with --command",
                        drive.kind.name(),
                        drive.kind.input_signal(),
                        drive.kind.command_unit()
                    );
                }
                open_loop("--voltage", v)
            }
            (None, None, Some(c), None) => open_loop("--command", c),
            (None, None, None, Some(path)) => {
                let exp = load_experiment_on(path, metres_per_rad)?;
                let text = std::fs::read_to_string(path).unwrap_or_default();
                Ok((Program::Segments(exp.segments), text))
            }
            (None, None, None, None) => bail!(
                "give a position reference (--ref step:1.5), an open-loop voltage (--voltage \
                 step:3) or drive command (--command step:0.5) or an experiment file \
                 (--experiment experiments/steps.toml)"
            ),
            _ => bail!("--ref, --voltage, --command and --experiment exclude each other"),
        }
    }
}
