//! `servo diagnose`: the default text, the answer first. The verdict, the status and what to do
//! next on top, then a screen of why (the plant line, the residual per balance, the best
//! candidate's figures, the first rows of the candidates table), then where the rest is. The full
//! candidates table, the measured friction curve and the bars are the `--verbose` report
//! ([`super::report_text::text_report`]), the HTML report and the JSON.

use super::*;

/// Rows of the candidates table the default text shows.
const SHOWN_CANDIDATES: usize = 3;

/// What to do next, from the final diagnosis: the command that adds the winner, or why there is
/// nothing to add, or where an unexplained residual leads.
pub(super) fn next_step(last: &Diagnosis, logs: &[PathBuf], model: &std::path::Path) -> String {
    use servo_core::diagnose::Status;
    match (last.status, last.winner()) {
        (Status::Complete, _) => {
            "Next: nothing to add: the model explains these logs down to their noise.".into()
        }
        (Status::Missing, Some(c)) => {
            let name = c.effect.name();
            let stem = model
                .file_stem()
                .map_or("model".into(), |s| s.to_string_lossy().into_owned());
            let log = logs
                .first()
                .map_or("LOG".into(), |p| p.display().to_string());
            format!(
                "Next: add it and refit: `servo compare {log} --model {} --add {name} --save {stem}-{name}.toml` \
                 (the error should fall), then diagnose that model",
                model.display()
            )
        }
        (Status::Missing, None) => {
            "Next: add the user-defined effect named below (`--effects FILE`, `servo compare --add NAME`)."
                .into()
        }
        (Status::Unexplained, _) => "Next: no catalogue effect explains the residual: see its strongest shape below; \
             `--discover` searches physical terms for it, `--effects FILE` judges an effect of your own"
            .into(),
    }
}

/// The default text (see the module's doc).
pub(super) fn short_report(
    first: &Diagnosis,
    ladder: &[Rung],
    diags: &[Diagnosis],
    auto: bool,
    opts: &DiagnoseOptions,
    next: &str,
    plant_line: &str,
) -> String {
    let mut s = String::new();
    let Some(last) = diags.last() else {
        return s;
    };
    let _ = writeln!(s, "Verdict: {}", last.verdict);
    let _ = writeln!(s, "{}", headline(ladder, last));
    let _ = writeln!(s, "{next}");
    let _ = writeln!(s, "\nWhy:\n{plant_line}");
    let _ = writeln!(s, "Model residual (base parameters refitted):");
    s.push_str(&where_it_fails(first));
    s.push_str(&balances_text(first));
    if let Some(c) = &first.friction_curve {
        match &c.shape {
            Some(sh) => {
                let _ = writeln!(s, "  measured friction curve: {}.", sh.description);
            }
            None => {
                let _ = writeln!(
                    s,
                    "  measured friction curve: no shape beyond the model's Coulomb and viscous friction."
                );
            }
        }
    }
    if let Some(w) = last.ranking.first() {
        let _ = writeln!(s, "Best candidate: {}", w.evidence);
    }
    let shown = last.ranking.len().min(SHOWN_CANDIDATES);
    let _ = writeln!(
        s,
        "Candidates, best first ({shown} of {}):",
        last.ranking.len()
    );
    s.push_str(&candidates_table(&last.ranking[..shown], opts));
    if auto {
        let _ = writeln!(s, "Error ladder:");
        s.push_str(&ladder_text(ladder));
    }
    s
}
