//! Helpers shared by the modules of this test binary that build logs with the core's types (the
//! `servo_e2e` library holds those that need only the `servo` binary and files).

use servo_cli::gains_file::{GainsFile, PidSection};
use servo_core::compare::quantum::quantize;
use servo_core::compare::Controller;
use servo_core::control::{Pid, PidConfig, PidGains};
use servo_core::sim::PlantSim;
use servo_core::Plant;
use std::fmt::Write as _;
use std::path::Path;

/// The PID of the compare and custom-effect tests (designed for the Table 2 plant, 1 kHz).
pub const PID: PidGains = PidGains {
    kp: 7.5244,
    ki: 94.0379,
    kd: 0.1505,
    tl_s: 0.004,
};
/// Their sample period [s].
pub const DT_S: f64 = 1e-3;

/// A closed-loop run of `truth` with [`PID`] over the reference `steps_deg` [deg], each held for
/// `hold` samples, a 4096-count encoder and a +/-10 V output limit, written to `path` as servo
/// CSV: `time_s,u_V,theta_l_rad,ref_rad`, plus `i_a_A` when `with_current`.
pub fn simulate_pid_steps(
    truth: &Plant,
    path: &Path,
    steps_deg: &[f64],
    hold: usize,
    with_current: bool,
) {
    let q = std::f64::consts::TAU / 4096.0;
    let mut sim = PlantSim::new(truth, DT_S).unwrap();
    let mut pid = Pid::new(PidConfig::new(PID, DT_S).with_symmetric_limit(10.0)).unwrap();
    let mut csv = String::from("time_s,u_V,theta_l_rad,ref_rad");
    csv.push_str(if with_current { ",i_a_A\n" } else { "\n" });
    for k in 0..steps_deg.len() * hold {
        let r = steps_deg[k / hold].to_radians();
        let y = quantize(sim.state().theta_l_rad, q);
        let i = sim.state().i_a_a;
        let u = Controller::update(&mut pid, r, y);
        write!(csv, "{:.6},{:.6},{:.10},{:.10}", k as f64 * DT_S, u, y, r).unwrap();
        if with_current {
            write!(csv, ",{i:.8}").unwrap();
        }
        csv.push('\n');
        sim.step(u);
    }
    std::fs::write(path, csv).unwrap();
}

/// A gains file of [`PID`] at [`DT_S`], with the +/-10 V limit of [`simulate_pid_steps`].
pub fn write_pid_gains(path: &Path) {
    GainsFile {
        pid: PidSection {
            kp: PID.kp,
            ki: PID.ki,
            kd: PID.kd,
            tl_s: PID.tl_s,
            ts_s: DT_S,
            kw: None,
            u_limit_v: Some(10.0),
            derivative_on: None,
        },
        design: None,
    }
    .save(path)
    .unwrap();
}

/// The compensation section of a `servo diagnose --report` page (`html`): its text after the
/// heading, and its ladder's rows as (label, RMS tracking error [rad]). Panics naming `tag`
/// when the page has no such section.
pub fn compensation_section(html: &str, tag: &str) -> (String, Vec<(String, f64)>) {
    let comp = html
        .split("<h2>Compensation</h2>")
        .nth(1)
        .unwrap_or_else(|| panic!("[{tag}] no compensation section"));
    let rows = comp
        .split("<tr><td>")
        .skip(1)
        .map(|r| {
            let cells: Vec<&str> = r.split("</td><td>").collect();
            (cells[0].to_string(), cells[1].parse::<f64>().unwrap())
        })
        .collect();
    (comp.to_string(), rows)
}
