//! `servo compare`: the text report.

use super::*;

#[allow(clippy::too_many_arguments)]
pub(super) fn print_text(
    logs: &[LogData],
    modes: &[ModeChoice],
    c: &ModelComparison,
    ladder: &[LadderStep],
    opts: &CompareOptions,
    refitted: Option<&str>,
    save: &[String],
    plot: Option<&Path>,
    axis: Option<&crate::axis::Axis>,
    model: &Path,
) {
    let lin = opts.metres_per_rad;
    if let Some(a) = axis {
        outln!(
            "{} (positions in m, speeds in m/s, forces in N)",
            a.describe()
        );
    }
    for ((log, r), mc) in logs.iter().zip(&c.reports).zip(modes) {
        outln!(
            "== {} ({} samples, {:.3} s, dt = {:.4} s)",
            log.path.display(),
            r.time_s.len(),
            r.time_s.len() as f64 * r.dt_s,
            r.dt_s
        );
        outln!("mode: {} -- {}", r.mode.name(), mc.reason);
        outln!("{}", plant_and_controller(model, &c.plant, &r.mode, log));
        if let Some(line) = controller_words(log) {
            outln!("{line}");
        }
        if log.measured.speed_derived {
            let model_side = if matches!(r.mode, ReplayMode::ClosedLoop | ReplayMode::Speed) {
                "the model's speed is derived from its position the same way"
            } else {
                "the model's speed is its state at the end of each prediction"
            };
            let why = log
                .measured
                .logged_speed_lag_samples
                .map(|lag| {
                    format!(
                        " (the logged speed lags the angle's derivative by {lag:.1} samples, more than {} samples: a causal estimate, whose lag would count as model error)",
                        servo_core::signal::lag::MAX_SPEED_LAG_SAMPLES
                    )
                })
                .unwrap_or_default();
            outln!(
                "speed: derived from position (zero-phase {:.0} Hz low-pass + central differences){why}; {model_side}",
                opts.speed_filter_hz
            );
        }
        outln!(
            "{:<10} {:>9} {:>14} {:>14} {:>14}",
            "signal",
            "fit [%]",
            "RMSE",
            "max error",
            "mean error"
        );
        for s in &r.signals {
            let f = &s.figures;
            let k = s.kind.scale_on(lin);
            outln!(
                "{:<10} {:>9.2} {:>14} {:>14} {:>14}",
                format!("{} [{}]", s.kind.name_on(lin), s.kind.unit_on(lin)),
                f.fit_percent,
                format!("{:.4e}", f.rmse * k),
                format!("{:.4e}", f.max_abs_error * k),
                format!("{:.3e}", f.mean_error * k)
            );
        }
        let hk = r.headline_signal().kind;
        outln!("where the {} error sits:", r.headline_signal().kind.words());
        outln!(
            "  {:<16} {:>8} {:>9} {:>12}",
            "regime",
            "time %",
            "error %",
            format!("rms [{}]", hk.unit_on(lin))
        );
        for s in r.regimes.iter().filter(|s| s.samples > 0) {
            outln!(
                "  {:<16} {:>8.1} {:>9.1} {:>12.4e}",
                s.regime.name(),
                s.time_share_pct,
                s.error_share_pct,
                s.rms * hk.scale_on(lin)
            );
        }
        outln!("findings:");
        for f in &r.findings {
            outln!("  - {f}");
        }
        if !r.worst_windows.is_empty() {
            outln!("worst windows:");
            for (i, w) in r.worst_windows.iter().enumerate() {
                outln!("  {}. {}", i + 1, describe_window(w, r, opts));
            }
        }
        outln!();
    }
    if ladder.len() > 1 || logs.len() > 1 {
        let k = ladder[0].cmp_fit[0].0;
        outln!("error ladder ({} over all logs):", k.words());
        let mut prev: Option<f64> = None;
        for s in ladder {
            let f = s.cmp_fit[0].1;
            let change = prev
                .map(|p| format!(" ({:+.1} % RMSE)", 100.0 * (f.rmse - p) / p))
                .unwrap_or_default();
            outln!(
                "  {:<24} fit {:>7.2} %   RMSE {}{}",
                s.label,
                f.fit_percent,
                with_unit_on(f.rmse, k, lin),
                change
            );
            prev = Some(f.rmse);
        }
    }
    if ladder.len() > 1 {
        outln!("model after the added effects:");
        for e in c.plant.effects.iter() {
            let kv: Vec<String> = e
                .iter()
                .map(|(p, v)| format!("{} = {:.4e} {}", p.key, v, p.unit))
                .collect();
            outln!("  {:<11} {}", e.kind.name(), kv.join(", "));
            if let Some(a) = axis {
                let linear = a.effect_text(e);
                if linear != kv.join(", ") {
                    outln!("  {:<11} {linear}", "");
                }
            }
        }
        for e in c.plant.custom.iter() {
            let kv: Vec<String> = e
                .def
                .params()
                .iter()
                .zip(e.values())
                .map(|(p, v)| format!("{} = {:.4e} {}", p.key, v, p.unit))
                .collect();
            outln!(
                "  {:<11} {} = {}: {} (user-defined, {})",
                e.name(),
                e.def.acts_on().name(),
                e.def.expr(),
                kv.join(", "),
                e.def.acts_on().unit()
            );
        }
        outln!("  base        {}", base_words(model, &c.plant.params));
        if let Some(a) = axis {
            out!(
                "  base      {}",
                a.base_text(c.plant.params.j_eq(), c.plant.b_eq(), c.plant.tau_sf())
            );
        }
    }
    if let Some(r) = refitted {
        outln!("{r}");
    }
    for line in save {
        outln!("{line}");
    }
    if let Some(p) = plot {
        outln!("figures written to {}", p.display());
    }
}

/// The controller check in words (None without a controller).
pub fn controller_words(log: &LogData) -> Option<String> {
    let c = log.check.as_ref()?;
    let mut s = format!(
        "controller check: this controller reproduces the logged u with fit {:.2} % (RMS {:.3e} V over {} samples inside the output limit)",
        c.fit_percent, c.rms_v, c.samples
    );
    // The logged u carries the encoder's quantisation through K_D, which no PID reproduces: judge
    // the given gains against the best PID on the same samples, not against 100 %.
    if c.fit_percent < c.ls_fit_percent - 10.0 {
        if let Some([kp, ki, kd]) = c.ls_gains {
            s.push_str(&format!(
                "\nWARNING: these gains do not reproduce the logged u, so the replay will differ for reasons unrelated to the plant. The PID that best reproduces it is kp = {kp:.4} V/rad, ki = {ki:.4} V/(rad s), kd = {kd:.4} V s/rad (fit {:.1} %): try --gains-from-log.",
                c.ls_fit_percent
            ));
        }
    }
    Some(s)
}

/// The one line every simulating command prints: which plant (the model file and its effects)
/// and which controller structure the replay of `log` in `mode` ran.
pub fn plant_and_controller(
    model: &Path,
    plant: &servo_core::plant::Plant,
    mode: &ReplayMode,
    log: &LogData,
) -> String {
    let mut effects: Vec<String> = plant
        .effects
        .iter()
        .map(|e| e.kind.name().to_string())
        .collect();
    effects.extend(
        plant
            .custom
            .iter()
            .map(|e| format!("{} (user-defined)", e.name())),
    );
    let effects = if effects.is_empty() {
        String::from("no effects beyond the base model")
    } else {
        format!("effects: {}", effects.join(", "))
    };
    let logged = log
        .controller
        .as_ref()
        .map(|c| format!("; the log's controller: PID, {}", c.describe()))
        .unwrap_or_default();
    let controller = match (mode, &log.controller) {
        (ReplayMode::ClosedLoop, Some(c)) => format!("controller: PID, {}", c.describe()),
        (ReplayMode::ClosedLoop, None) => String::from("controller: unknown"),
        (ReplayMode::Speed, _) => format!(
            "controller: none in the replay (open loop: the logged u drives the model from the first measured state){logged}"
        ),
        (ReplayMode::KStep { k }, _) => format!(
            "controller: none in the replay (the logged u drives the model {k} samples ahead of each measured state){logged}"
        ),
        (ReplayMode::Segments { len }, _) => format!(
            "controller: none in the replay (the logged u drives the model, restarted from the measured state every {len} samples){logged}"
        ),
    };
    format!(
        "simulated plant: the model of {} ({effects}); {controller}",
        model.display()
    )
}

/// The controller of the replay in words: every part with where it came from.
pub fn controller_description(log: &LogData) -> Option<String> {
    log.controller
        .as_ref()
        .map(|c| format!("controller: {}", c.describe()))
}

/// The refitted base in the drive's own terms (the drive of the model file `model`): a current
/// drive has no electrical constants (the model's R_eq and k_drv are its internal current
/// source), a duty drive no driver gain (its R_eq is the bridge's: R_a + R_s + the supply's).
fn base_words(model: &Path, p: &servo_core::PlantParams) -> String {
    use servo_core::drive::DriveKind;
    let sig = crate::cmd::design::sig6;
    let j = format!("J_eq = {:.4e} kg m^2", p.j_eq());
    let kind =
        crate::model_file::ModelFile::load(model).map_or(DriveKind::Voltage, |m| m.drive.kind);
    match kind {
        DriveKind::Current => format!(
            "{j}, k_t = {} N m/A (a current drive: nothing electrical is fitted)",
            sig(p.k_t)
        ),
        DriveKind::Duty => format!(
            "{j}, R_eq = {} ohm (the bridge's R_a + R_s + supply)",
            sig(p.r_eq())
        ),
        _ => format!("{j}, R_eq = {:.4} ohm, k_drv = {:.4}", p.r_eq(), p.k_drv),
    }
}

/// The check of each effect a run compensated against its log: the suspect first, in words.
pub(super) fn compensation_lines(
    logs: &[LogData],
    checks: &[servo_core::compare::suspects::CompensationCheck],
    model: &Path,
) -> Vec<String> {
    use servo_core::compare::suspects::SUSPECT_MIN_DROP;
    let mut out = Vec::new();
    if checks.is_empty() {
        return out;
    }
    out.push(format!(
        "== compensated effects (the run's log says which), each replayed without it (suspect when \
         the error falls by >= {} %: suspect_min_drop)",
        servo_core::math::sig(SUSPECT_MIN_DROP * 100.0, 2)
    ));
    for c in checks {
        let Some(log) = logs.get(c.log) else { continue };
        let name = c.effect.name();
        let figures = format!(
            "{} RMSE {} {} with it, {} {} without ({:+.1} %)",
            log.name,
            servo_core::math::sig(c.rmse_with, 3),
            c.unit,
            servo_core::math::sig(c.rmse_without, 3),
            c.unit,
            100.0 * c.change()
        );
        if c.suspect {
            out.push(format!(
                "SUSPECT: the compensated {name} -- the model without it predicts this log better \
                 ({figures}): the motor does not have the {name} the compensation cancelled (wrong \
                 sign, size or phase); refit it: servo compare {} --model {} --add {name} --save \
                 refit.toml",
                log.name,
                model.display()
            ));
        } else {
            out.push(format!(
                "compensated {name}: consistent with this log ({figures})"
            ));
        }
    }
    out
}
