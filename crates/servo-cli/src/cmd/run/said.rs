//! `servo run`: the one line saying which plant and which controller run, and the warnings when
//! they differ from what the gains file says the gains were designed and checked for.

use crate::gains_file::GainsFile;
use servo_core::control::PidConfig;

impl super::Run {
    /// Prints `plant: ...; controller: ...` (stdout) and a warning (stderr) per difference
    /// between the gains file's `[design]` assumptions and this run.
    pub(super) fn say_plant_and_controller(
        &self,
        gains: Option<&GainsFile>,
        pid: Option<&PidConfig>,
        description: Option<&str>,
    ) {
        let sim = self.backend == super::BackendKind::Sim;
        let plant = if sim {
            format!("simulated plant: {}", self.plant.words())
        } else {
            format!("board on {}", self.port)
        };
        let controller = match description {
            Some(d) => format!("controller: PID, {d}"),
            None => "open loop (no controller)".to_string(),
        };
        outln!("{plant}; {controller}");
        if let (Some(g), Some(p)) = (gains, pid) {
            let key = sim.then(|| self.plant.key());
            // the base plant, without the effects the run adds on purpose
            let params = sim.then(|| self.plant.base_params()).flatten();
            for w in g.design_mismatches(key.as_deref(), params.as_ref(), p.discretization) {
                eprintln!("warning: {w}");
            }
        }
    }
}
