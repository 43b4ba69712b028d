//! `servo demo`, last stages: compare the identified model with the logs, diagnose the missing
//! effect, add it, diagnose again.

use super::*;

/// The logs every model is judged on: the closed-loop run and the open-loop experiment.
pub(super) fn story_logs(ctx: &DemoContext) -> anyhow::Result<Vec<String>> {
    Ok(vec![
        path_arg(need(&ctx.run_log, "the run log")?),
        path_arg(need(&ctx.ident_log, "the identification log")?),
    ])
}

pub(super) fn stage_compare(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let model = need(&ctx.ident_model, "the identified model")?.clone();
    let plot = ctx.out.join("compare.svg");
    let mut args = vec!["compare".to_string()];
    args.extend(story_logs(ctx)?);
    args.extend([
        "--model".into(),
        path_arg(&model),
        "--plot".into(),
        path_arg(&plot),
    ]);
    let cmd: crate::cmd::compare::Compare = command(&args)?;
    let (ladder, cmp) = cmd.run_report()?;
    let (kind, f) = ladder
        .first()
        .and_then(|s| s.cmp_fit.first())
        .ok_or_else(|| anyhow!("compare gave no figures"))?;
    // Where it fails: the finding (of any log) that puts the largest share of the error in one
    // regime or pattern ("NN % of the squared error sits ...").
    let where_ = cmp
        .reports
        .iter()
        .flat_map(|r| r.findings.iter())
        .filter_map(|f| {
            let pct: f64 = f.split(" % ").next()?.trim().parse().ok()?;
            Some((pct, f))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, f)| format!("; where it fails: {f}"))
        .unwrap_or_default();
    Ok((
        format!(
            "fit {:.1} % on {} over both logs{where_}",
            f.fit_percent,
            kind.words()
        ),
        vec![plot],
    ))
}

/// Runs `servo diagnose` on the story's logs with `model`, writing the HTML `report`, and
/// returns the diagnosis of the first log set.
pub(super) fn run_diagnose(
    ctx: &DemoContext,
    model: &Path,
    report: &Path,
) -> anyhow::Result<servo_core::diagnose::Diagnosis> {
    let mut args = vec!["diagnose".to_string()];
    args.extend(story_logs(ctx)?);
    args.extend([
        "--model".into(),
        path_arg(model),
        "--report".into(),
        path_arg(report),
    ]);
    let cmd: crate::cmd::diagnose::Diagnose = command(&args)?;
    let (_, diags) = cmd.run_report()?;
    diags
        .into_iter()
        .next()
        .ok_or_else(|| anyhow!("diagnose gave no result"))
}

pub(super) fn stage_diagnose(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let model = need(&ctx.ident_model, "the identified model")?.clone();
    let report = ctx.out.join("diagnose.html");
    let d = &run_diagnose(ctx, &model, &report)?;
    let hidden = hidden_effect(&ctx.truth);
    let truth_words = hidden.map_or(String::from("none"), |e| e.to_string());
    let Some(w) = d.winner() else {
        ctx.winner = None;
        return Ok((
            format!(
                "nothing significant found (hidden: {truth_words}): {}",
                d.verdict
            ),
            vec![report],
        ));
    };
    ctx.winner = Some(w.effect);
    let main = main_param(w.effect)
        .and_then(|k| w.params.iter().find(|p| p.key == k))
        .map(|p| format!(", {} {:.4} {}", p.key, p.value, p.unit))
        .unwrap_or_default();
    let verdict = if hidden.map(|h| h.kind) == Some(w.effect) {
        "the hidden effect"
    } else {
        "NOT the hidden effect"
    };
    Ok((
        format!(
            "missing effect: {} (error -{:.1} %{main}); {verdict} ({truth_words})",
            w.effect.name(),
            w.error_reduction_pct
        ),
        vec![report],
    ))
}

pub(super) fn stage_add(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let model = need(&ctx.ident_model, "the identified model")?.clone();
    let Some(winner) = ctx.winner else {
        return Ok((
            String::from("nothing to add: the diagnosis found no missing effect"),
            vec![],
        ));
    };
    let saved = ctx.out.join(format!("model_plus_{}.toml", winner.name()));
    let plot = ctx.out.join(format!("compare_plus_{}.svg", winner.name()));
    let mut args = vec!["compare".to_string()];
    args.extend(story_logs(ctx)?);
    args.extend([
        "--model".into(),
        path_arg(&model),
        "--add".into(),
        winner.name().into(),
        "--save".into(),
        path_arg(&saved),
        "--plot".into(),
        path_arg(&plot),
    ]);
    let cmd: crate::cmd::compare::Compare = command(&args)?;
    let (ladder, cmp) = cmd.run_report()?;
    let fit = |i: usize| ladder.get(i).and_then(|s| s.cmp_fit.first()).map(|f| f.1);
    let (Some(before), Some(after)) = (fit(0), fit(ladder.len().saturating_sub(1))) else {
        return Err(anyhow!("compare --add gave no ladder"));
    };
    let param = main_param(winner)
        .and_then(|k| cmp.plant.effects.value(winner, k).map(|v| (k, v)))
        .map(|(k, v)| {
            let truth = ctx
                .truth
                .effects
                .value(winner, k)
                .map(|t| format!(", truth {t:.4}"))
                .unwrap_or_default();
            format!(" ({k} {v:.4} {}{truth})", main_unit(winner))
        })
        .unwrap_or_default();
    // compare writes the model only when it does not predict worse than the identified one.
    if !saved.exists() {
        return Ok((
            format!(
                "adding {} made the prediction worse: model not saved (compare's gate)",
                winner.name()
            ),
            vec![plot],
        ));
    }
    ctx.extended_model = Some(saved.clone());
    Ok((
        format!(
            "fit {:.1} % -> {:.1} % after adding {}{param}; RMSE {:.2e} -> {:.2e} ({:+.0} %)",
            before.fit_percent,
            after.fit_percent,
            winner.name(),
            before.rmse,
            after.rmse,
            100.0 * (after.rmse - before.rmse) / before.rmse
        ),
        vec![saved, plot],
    ))
}

pub(super) fn stage_rediagnose(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let Some(model) = ctx.extended_model.clone() else {
        return Ok((String::from("skipped: no effect was added"), vec![]));
    };
    let report = ctx.out.join("diagnose_after.html");
    let d = &run_diagnose(ctx, &model, &report)?;
    let headline = match d.winner() {
        None => String::from("nothing significant left: the model explains the data"),
        Some(w) => format!(
            "still missing: {} (error -{:.1} %)",
            w.effect.name(),
            w.error_reduction_pct
        ),
    };
    Ok((headline, vec![report]))
}

/// The story's end (issue #29): the extended model's effects compensated in the loop, on the
/// same motor and the same reference, against the handout's friction feedforward.
pub(super) fn stage_compensate(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    use servo_core::control::{EffectSelect, FeedforwardConfig, LoopCompensation};
    let Some(model) = ctx.extended_model.clone() else {
        return Ok((String::from("skipped: no effect was added"), vec![]));
    };
    let mf = ModelFile::load(&model)?;
    let plant = mf.plant()?;
    let choice = servo_io::compensation::CompensationChoice::parse("all", &mf, &plant, 0.0)?;
    let gains = ctx.gains.clone().unwrap_or_else(handout_gains);
    let src = PidSources {
        opts: &PidOptions::default(),
        logged: None,
        gains_file: Some((&gains, "the demo's gains")),
    };
    let pid = pid_config(&src, 1e-3, Some((10.0, "the demo's 10 V driver".into())))?.config;
    let exp = servo_io::reference_file::Experiment::standard_tracking()?;
    let program = Program::Segments(exp.segments);
    let duration_s = program.duration_s().unwrap_or(18.0);
    let run = |linear: FeedforwardConfig, select: EffectSelect| -> anyhow::Result<f64> {
        let comp = LoopCompensation::new(&plant, linear, select, 0.0)
            .map_err(|e| anyhow!("compensation: {e}"))?;
        let mut backend = SimBackend::new(&ctx.truth, ctx.sensors, 1e-3).context("simulator")?;
        let mut cfg = RunConfig::closed_loop(program.clone(), pid, duration_s);
        cfg.feedforward = Some(comp);
        cfg.keep_record = false;
        let out = servo_hw::run::run_loop(&mut backend, &cfg, None)?;
        out.summary
            .err_rms_rad
            .ok_or_else(|| anyhow!("the tracking run has no error"))
    };
    let friction = run(FeedforwardConfig::FRICTION, EffectSelect::None)?;
    let all = run(choice.linear, choice.select)?;
    let m = path_arg(&model);
    outln!(
        "   servo run --plant truth_hidden.toml --gains ... --experiment experiments/tracking.toml \
         --model {m} --ff friction   (then --ff all)"
    );
    for line in choice.lines() {
        outln!("   {line}");
    }
    Ok((
        format!(
            "tracking error RMS {} rad with the friction feedforward -> {} rad compensating {} \
             ({:+.0} %)",
            servo_core::math::sig(friction, 3),
            servo_core::math::sig(all, 3),
            choice.effect_names(),
            100.0 * (all / friction - 1.0)
        ),
        vec![],
    ))
}
