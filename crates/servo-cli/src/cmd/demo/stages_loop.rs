//! `servo demo`, first stages: design the PID, run it on the simulated plant, excite the plant
//! open loop for identification, identify the base model.

use super::*;

pub(super) fn stage_design(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    use servo_core::design::controller::Discretization;
    use servo_core::design::verify::{design, DesignRequest};
    let req = DesignRequest::handout(&PlantParams::TABLE2, 1e-3, Discretization::Tustin);
    let r = design(&req).map_err(|e| anyhow!("design: {e}"))?;
    let g = r.gains;
    let mut d = toml::Table::new();
    d.insert(
        "method".into(),
        "Bode (handout eqs. 44-53), servo demo".into(),
    );
    d.insert("wgc_rad_s".into(), 30.0.into());
    d.insert("pm_deg".into(), 60.0.into());
    d.insert("alpha".into(), 4.0.into());
    d.insert("discretization".into(), "tustin".into());
    let gains = GainsFile {
        pid: PidSection::of(&g, 1e-3),
        design: Some(d),
    };
    let path = ctx.out.join("gains.toml");
    gains.save(&path)?;
    let pm = r.discrete.margins.phase_margin_deg;
    ctx.gains = Some(gains);
    Ok((
        format!(
            "K_P = {:.4} V/rad, K_I = {:.3} V/(rad s), K_D = {:.5} V s/rad, T_L = {:.4} s; discrete loop phase margin {pm:.1} deg",
            g.kp, g.ki, g.kd, g.tl_s
        ),
        vec![path],
    ))
}

/// The handout's reference-point gains, used when the design stage is skipped or fails.
pub fn handout_gains() -> GainsFile {
    GainsFile {
        pid: PidSection {
            kp: 7.0476,
            ki: 86.121,
            kd: 0.14418,
            tl_s: 1.0 / 150.0,
            ts_s: 1e-3,
            kw: None,
            u_limit_v: None,
            derivative_on: None,
        },
        design: None,
    }
}

pub(super) fn stage_run(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let gains = ctx.gains.clone().unwrap_or_else(handout_gains);
    let src = PidSources {
        opts: &PidOptions::default(),
        logged: None,
        gains_file: Some((&gains, "the demo's gains")),
    };
    let resolved = pid_config(&src, 1e-3, Some((10.0, "the demo's 10 V driver".into())))?;
    // the one line every simulating command prints: which plant, which controller
    let hidden: Vec<String> = ctx.truth.effects.iter().map(|e| e.to_string()).collect();
    outln!(
        "simulated plant: the demo's motor (truth_hidden.toml: {}); controller: PID, {}",
        hidden.join(" "),
        resolved.describe()
    );
    let pid = resolved.config;
    let program = demo_program()?;
    let duration_s = program.duration_s().unwrap_or(6.0);
    let mut backend = SimBackend::new(&ctx.truth, ctx.sensors, 1e-3).context("simulator")?;
    let truth_path = ctx.out.join("truth_hidden.toml");
    let mut mf = ModelFile::from_plant(&ctx.truth);
    mf.sensors = Some(ctx.sensors);
    mf.save(&truth_path)?;
    let cfg = RunConfig::closed_loop(program, pid, duration_s);
    let mut meta = BTreeMap::new();
    meta.insert(
        meta_keys::SERVO_VERSION.into(),
        env!("CARGO_PKG_VERSION").into(),
    );
    meta.insert(meta_keys::BACKEND.into(), "sim".into());
    meta.insert(meta_keys::SAMPLE_PERIOD_S.into(), "0.001".into());
    meta.insert(meta_keys::DURATION_S.into(), duration_s.to_string());
    meta.insert(
        meta_keys::REFERENCE.into(),
        "steps 10, 30, 90, -45 deg, 1.5 s each".into(),
    );
    meta.insert(meta_keys::GAINS_TOML.into(), gains.to_toml_commented());
    meta.insert(meta_keys::PLANT_TOML.into(), mf.to_toml()?);
    meta.insert(
        meta_keys::PLANT_EFFECTS.into(),
        ctx.truth
            .effects
            .iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join(" "),
    );
    meta.insert(meta_keys::SEED.into(), ctx.sensors.seed.to_string());
    meta.insert(meta_keys::FEEDFORWARD.into(), "none".into());
    meta.insert(
        meta_keys::CONTROLLER_TOML.into(),
        LoggedController::of(
            &servo_hw::run::effective_pid_config(
                &pid,
                cfg.u_limit_v.min(backend.info().voltage_limit_v),
                backend.info().sample_period_s,
            ),
            None,
        )
        .to_toml()?,
    );
    let log_path = ctx.out.join("run.mcap");
    let mut log = McapLog::create(&log_path, &meta, McapLogOptions::default())?;
    let out = live::run_loop(&mut backend, &cfg, Some(&mut log))?;
    let summary = out.summary();
    log.write_summary(&summary.to_map())?;
    log.finish()?;
    let csv_path = ctx.out.join("run.csv");
    write_csv(&csv_path, &out.record)?;
    let plot_path = ctx.out.join("run.svg");
    crate::cmd::run::plot_run(&plot_path, &out)?;
    let u_plot = ctx.out.join("run_u.svg");
    let headline = format!(
        "{} steps: overshoot up to {:.1} %, tracking error RMS {:.2} deg, {:.3} s at the 10 V limit",
        summary.steps.len(),
        summary.overshoot_pct().unwrap_or(0.0),
        summary.err_rms_rad.unwrap_or(0.0).to_degrees(),
        summary.saturation_time_s
    );
    outln!("{summary}");
    ctx.run = Some(out);
    ctx.run_log = Some(log_path.clone());
    ctx.run_csv = Some(csv_path.clone());
    Ok((
        headline,
        vec![truth_path, log_path, csv_path, plot_path, u_plot],
    ))
}

/// Open-loop identification experiment on the truth: every 0.4 s either a voltage step of random
/// size (0.8-7.8 V) and sign, or (one time in four) a ramp through zero from +/-(3-6) V to the
/// opposite value; seeded, so the log is the same on every run.
pub(super) fn stage_excite(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    use servo_core::record::Record;
    use servo_core::sim::sensors::SplitMix64;
    let dt = 1e-3;
    let sensors = SensorConfig {
        seed: ctx.sensors.seed.wrapping_add(1),
        ..ctx.sensors
    };
    let mut backend = SimBackend::new(&ctx.truth, sensors, dt).context("simulator")?;
    let mut rng = SplitMix64(ctx.sensors.seed ^ 0x5EED);
    let n = (EXCITE_S / dt).round() as usize;
    let per = (EXCITE_STEP_S / dt).round() as usize;
    let mut rec = Record {
        source: String::from("servo demo: open-loop identification experiment (sim)"),
        ..Record::default()
    };
    let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
    let (mut u, mut ramp): (f64, Option<(f64, f64)>) = (0.0, None);
    let (mut steps, mut ramps) = (0usize, 0usize);
    for k in 0..n {
        if k % per == 0 {
            if rng.uniform() < 0.25 {
                let a = 3.0 + 3.0 * rng.uniform();
                let a = if rng.uniform() < 0.5 { a } else { -a };
                ramp = Some((a, -2.0 * a / EXCITE_STEP_S));
                ramps += 1;
            } else {
                ramp = None;
                let mag = 0.8 + 7.0 * rng.uniform();
                u = if rng.uniform() < 0.5 { -mag } else { mag };
                steps += 1;
            }
        }
        if let Some((a, slope)) = ramp {
            u = a + slope * ((k % per) as f64 * dt);
        }
        let s = backend.sample()?;
        rec.time_s.push(s.time_s);
        th.push(s.theta_l_rad);
        ia.push(s.i_a_a);
        uv.push(u);
        backend.apply(u)?;
    }
    backend.stop()?;
    rec.theta_l_rad = Some(th);
    rec.i_a_a = Some(ia);
    rec.u_v = Some(uv);
    let path = ctx.out.join("identify_openloop.csv");
    write_csv(&path, &rec)?;
    let plot = ctx.out.join("identify_openloop.svg");
    {
        // volts and radians on separate axes: u above, theta_l below, one time axis
        use crate::plot::{line_chart_svg, Chart, Series};
        let t = &rec.time_s;
        let u = rec.u_v.as_deref().unwrap_or(&[]);
        let th = rec.theta_l_rad.as_deref().unwrap_or(&[]);
        let panel = |title, y_label, label, y| {
            line_chart_svg(
                &Chart {
                    title,
                    x_label: "time [s]",
                    y_label,
                    height: 300,
                    ..Chart::default()
                },
                &[Series { label, x: t, y }],
            )
        };
        let svg = crate::cmd::compare::stack_svg(&[
            panel(
                "open-loop identification experiment: driver input",
                "u [V]",
                "u [V]",
                u,
            )?,
            panel("load angle", "theta_l [rad]", "theta_l [rad]", th)?,
        ]);
        crate::io::output::write_file(&plot, "plot", svg)?;
    }
    ctx.ident_log = Some(path.clone());
    Ok((
        format!(
            "{EXCITE_S:.0} s at 1 kHz: {steps} voltage steps and {ramps} ramps through zero, u, theta_l and i_a logged"
        ),
        vec![path, plot],
    ))
}

pub(super) fn stage_identify(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let log = need(&ctx.ident_log, "the identification log")?;
    let model = ctx.out.join("model_identified.toml");
    let cmd: crate::cmd::identify::Identify = command(&[
        "identify".into(),
        path_arg(log),
        "-o".into(),
        path_arg(&model),
    ])?;
    cmd.run()?;
    // `servo identify -o` printed "wrote <model>" itself
    ctx.announced.push(model.clone());
    let id = ModelFile::load(&model)?.plant()?;
    let t = &ctx.truth;
    ctx.ident_model = Some(model.clone());
    Ok((
        format!(
            "J_eq = {:.3e} kg m^2 (truth {:.3e}), B_eq = {:.3e} N m s/rad (truth {:.3e}), tau_sf = {:.4} N m (truth {:.4}); no {} in the model",
            id.params.j_eq(),
            t.params.j_eq(),
            id.b_eq(),
            t.b_eq(),
            id.tau_sf(),
            t.tau_sf(),
            hidden_effect(t).map_or("hidden effect", |e| e.kind.name()),
        ),
        vec![model],
    ))
}
