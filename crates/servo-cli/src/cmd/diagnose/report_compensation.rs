//! The HTML report's compensation section (issue #29): what compensating the effects the
//! diagnosis found would do to the tracking error. The model with the found effects is the
//! plant; a PID designed on its linear part by the handout's Bode method (w_gc = 30 rad/s,
//! phi_m = 60 deg, the handout's example spec) runs the standard tracking reference through
//! `servo run`'s loop with no compensation, the linear feedforward, then each found effect's
//! compensation added in turn (servo_hw::run::compensation_check), through the model file's
//! drive as `servo run --plant` runs it (a current drive's limit, a bridge's supply).

use super::*;
use servo_core::control::FeedforwardConfig;
use servo_core::design::controller::Discretization;
use servo_core::design::verify::{design, DesignRequest};
use servo_core::drive::{Drive, DriveKind};
use servo_core::effects::Compensation;
use servo_hw::run::compensation_check::{tracking_ladder, TrackingRun};
use servo_io::gains_file::{GainsFile, PidSection};
use servo_io::markup;
use servo_io::markup::Markup;

/// Control period of the section's loop [s].
const TS_S: f64 = 1e-3;

/// The section (empty when the diagnosis found no effect beyond `base`), run through `drive`.
pub(super) fn compensation_html(
    base: &Plant,
    found: &Plant,
    drive: &Drive,
) -> anyhow::Result<Markup> {
    let new: Vec<EffectKind> = found
        .effects
        .iter()
        .map(|e| e.kind)
        .filter(|k| !base.effects.contains(*k))
        .collect();
    if new.is_empty() {
        return Ok(Markup::new());
    }
    let mut h = Markup::new();
    h.lit("<h2>Compensation</h2>");
    let (comp, not): (Vec<EffectKind>, Vec<EffectKind>) = new.iter().partition(|k| {
        !matches!(
            k.model().compensation(),
            Compensation::Not(_) | Compensation::Linear
        )
    });
    for k in &not {
        let why = match k.model().compensation() {
            Compensation::Not(why) => why.to_string(),
            _ => "the linear feedforward covers it".into(),
        };
        markup!(h, "<p>{}: not compensated ({}).</p>", k.name(), why);
    }
    if comp.is_empty() {
        return Ok(h);
    }
    let params = found.linear_params();
    let req = DesignRequest::handout(&params, TS_S, Discretization::BackwardEuler);
    let report = design(&req).map_err(|e| anyhow!("the section's PID design: {e}"))?;
    let g = report.gains;
    // The loop's range is the drive's where it has one (a current drive's limit, a bridge's
    // supply), as `servo run` takes it without a limit in the gains.
    let mut pid = PidSection::of(&g, TS_S);
    if let Some(range) = drive.input_range() {
        pid.u_limit_v = Some(range);
    }
    let gains = GainsFile { pid, design: None };
    let (pid, u_limit_v) = servo_hw::run::pid_from_gains(&gains, "the section's gains")?;
    let exp = servo_io::reference_file::Experiment::standard_tracking()?;
    let run = TrackingRun {
        truth: found,
        sensors: servo_core::sim::SensorConfig::default(),
        model: found,
        pid,
        u_limit_v,
        program: servo_core::control::Program::Segments(exp.segments.clone()),
        duration_s: exp.duration_s(),
        ramp_s: 0.0,
        // The section's PID is the handout's design on the linear part (the drive's equivalent
        // chain), its output sent through the drive.
        drive: *drive,
    };
    let ladder = tracking_ladder(&run, FeedforwardConfig::FULL, &comp, &[])
        .map_err(|e| anyhow!("the compensation section's tracking runs: {e}"))?;
    markup!(
        h,
        "<p>Predicted on the model with the effects found, a PID designed on its linear part \
         (Bode, w_gc = {} rad/s, phi_m = {} deg: K_P = {}, K_I = {}, K_D = \
         {}) and the standard tracking reference (<code>experiments/tracking.toml</code>, \
         {} s), each compensation added in turn, through the model's {}. To run it: <code>servo compare LOG --model M \
         --add EFFECT --save M2</code>, then <code>servo run --model M2 --ff all --experiment \
         experiments/tracking.toml</code>; <code>servo compare</code> on the two runs prints the \
         measured ladder.</p><table><tr><th>compensation</th><th>RMS tracking error [rad]</th>\
         <th>change</th><th>max error [rad]</th></tr>",
        format!("{:.0}", req.spec.omega_gc),
        format!("{:.0}", req.spec.phase_margin.to_degrees()),
        format!("{:.3}", g.kp),
        format!("{:.3}", g.ki),
        format!("{:.4}", g.kd),
        format!("{:.0}", exp.duration_s()),
        drive_words(drive)
    );
    let first = ladder.first().map_or(f64::NAN, |r| r.err_rms_rad);
    for r in &ladder {
        markup!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{} %</td><td>{}</td></tr>",
            r.label(),
            format!("{:.3e}", r.err_rms_rad),
            format!("{:+.0}", 100.0 * (r.err_rms_rad / first - 1.0)),
            format!("{:.3e}", r.err_max_rad)
        );
    }
    h.lit("</table>");
    Ok(h)
}

/// The drive in words, with the range the loop runs in: servo's own wording (a template, its
/// apostrophes as written), the range a number.
fn drive_words(drive: &Drive) -> Markup {
    let range = drive.input_range().map(|r| format!("{r:.3}"));
    let mut m = Markup::new();
    match (drive.kind, range) {
        (DriveKind::Voltage, _) => m.lit("voltage amplifier"),
        (DriveKind::Current, None) => m.lit("current drive (the PID's output in A)"),
        (DriveKind::Current, Some(r)) => markup!(
            m,
            "current drive (the PID's output in A, the loop's output within +-{} A)",
            r
        ),
        (DriveKind::Duty, None) => m.lit("PWM bridge (the duty is the PID's output over V_supply)"),
        (DriveKind::Duty, Some(r)) => markup!(
            m,
            "PWM bridge (the duty is the PID's output over V_supply, the loop's output within +-{} V)",
            r
        ),
    };
    m
}
