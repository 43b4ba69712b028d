//! End-to-end checks of the diagnosis: every catalogue effect hidden in simulated data (an
//! open-loop identification-like log and a closed-loop PID log, with encoder quantisation and
//! current noise) is named first and significant, its main parameter recovered within 15 %, and
//! the fit improves; a complete model yields nothing significant; two hidden effects are found one
//! after the other.

use servo_core::diagnose::{self, DiagnoseOptions};
use servo_core::effects::{Effect, EffectKind};
use servo_core::fit::{self, oe, Dataset, EffectToFit, FitOptions};
use servo_core::record::Record;
use servo_core::sim::sensors::SplitMix64;
use servo_core::sim::{PlantSim, SensorConfig, Sensors};
use servo_core::{Plant, PlantParams};

pub(crate) const DT: f64 = 1e-3;

fn truth(hidden: &[Effect]) -> Plant {
    let params = PlantParams {
        j_eq: Some(7.0e-7),
        b_eq: Some(1.0e-6),
        tau_sf: Some(0.01),
        ..PlantParams::TABLE2
    };
    let mut p = Plant::from_params(params).unwrap();
    for e in hidden {
        p.effects.insert(*e);
    }
    p
}

pub(crate) fn record(
    t: Vec<f64>,
    th: Vec<f64>,
    ia: Vec<f64>,
    u: Vec<f64>,
    r: Option<Vec<f64>>,
    src: &str,
) -> Record {
    Record {
        source: src.into(),
        time_s: t,
        theta_l_rad: Some(th),
        i_a_a: Some(ia),
        u_v: Some(u),
        ref_rad: r,
        ..Record::default()
    }
}

/// Open-loop identification-like excitation: voltage steps of random size and sign, some slow
/// ramps (this log's own generator rather than `servo_core::sim::excitation::RandomSteps`: its
/// ramps keep a historical slope of -2|a| per hold, so the negative ones run away from zero
/// instead of through it, and every seed these tests were checked on keeps its data; new tests
/// should use the library's generator).
fn open_loop(plant: &Plant, seconds: f64, seed: u64) -> Record {
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut sensors = Sensors::new(SensorConfig {
        seed,
        ..SensorConfig::default()
    });
    let mut rng = SplitMix64(seed ^ 0x5EED);
    let n = (seconds / DT) as usize;
    let (mut t, mut th, mut ia, mut uv) = (vec![], vec![], vec![], vec![]);
    let mut u = 0.0;
    let mut ramp: Option<(f64, f64)> = None;
    for k in 0..n {
        if k % 400 == 0 {
            if rng.uniform() < 0.25 {
                let a = 3.0 + 3.0 * rng.uniform();
                ramp = Some((if rng.uniform() < 0.5 { a } else { -a }, -2.0 * a / 0.4));
            } else {
                ramp = None;
                let mag = 0.8 + 7.0 * rng.uniform();
                u = if rng.uniform() < 0.5 { -mag } else { mag };
            }
        }
        if let Some((a, slope)) = ramp {
            u = a + slope * ((k % 400) as f64 * DT);
        }
        let m = sensors.measure(sim.state());
        t.push(k as f64 * DT);
        th.push(m.theta_l_rad);
        ia.push(m.i_a_a);
        uv.push(u);
        sim.step(u);
    }
    record(t, th, ia, uv, None, "open-loop")
}

/// Closed-loop PID (Bode gains of the handout's lab) following position steps of random size
/// (drawn from `rng`), on any plant: `measure(rng)` gives the (load angle [rad], current [A]) the
/// controller sees, `step(u)` advances the plant one period with input u [V].
pub(crate) fn pid_log(
    n: usize,
    rng: &mut SplitMix64,
    mut measure: impl FnMut(&mut SplitMix64) -> (f64, f64),
    mut step: impl FnMut(f64),
    src: &str,
) -> Record {
    let (kp, ki, kd, tl) = (7.5244, 94.0379, 0.1505, 0.003);
    let (mut t, mut th, mut ia, mut uv, mut rv) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut integ, mut d_state, mut prev_y, mut r) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        if k % 800 == 0 {
            r += (if rng.uniform() < 0.5 { -1.0 } else { 1.0 }) * (0.2 + 1.4 * rng.uniform());
        }
        let (y, i) = measure(rng);
        let e = r - y;
        // Derivative on the measurement, first-order filtered (time constant tl).
        let dy = (y - prev_y) / DT;
        d_state += DT / (tl + DT) * (dy - d_state);
        prev_y = y;
        let raw = kp * e + ki * integ - kd * d_state;
        let u = raw.clamp(-10.0, 10.0);
        if raw == u {
            integ += e * DT;
        }
        t.push(k as f64 * DT);
        th.push(y);
        ia.push(i);
        uv.push(u);
        rv.push(r);
        step(u);
    }
    record(t, th, ia, uv, Some(rv), src)
}

/// [`pid_log`] on servo's simulator with its sensors.
fn closed_loop(plant: &Plant, seconds: f64, seed: u64) -> Record {
    let sim = core::cell::RefCell::new(PlantSim::new(plant, DT).unwrap());
    let mut sensors = Sensors::new(SensorConfig {
        seed: seed + 7,
        ..SensorConfig::default()
    });
    let mut rng = SplitMix64(seed ^ 0xC105ED);
    pid_log(
        (seconds / DT) as usize,
        &mut rng,
        |_| {
            let m = sensors.measure(sim.borrow().state());
            (m.theta_l_rad, m.i_a_a)
        },
        |u| {
            sim.borrow_mut().step(u);
        },
        "closed-loop",
    )
}

fn logs(plant: &Plant, seed: u64) -> Vec<Record> {
    vec![open_loop(plant, 16.0, seed), closed_loop(plant, 12.0, seed)]
}

/// The identified base model (viscous + Coulomb) from the open-loop log.
pub(crate) fn identified(logs: &[Record]) -> Plant {
    let start = Plant::from_params(PlantParams {
        tau_sf: Some(0.005),
        ..PlantParams::TABLE2
    })
    .unwrap();
    fit::fit_model(&logs[..1], &start, &[], &FitOptions::default())
        .unwrap()
        .plant
}

/// For an effect judged on the simulation alone (a gear play: no balance of its own shows it),
/// the held-out simulation drop [%] the *true* plant achieves against the diagnosis's simulation
/// reference, when it is below twice the bar a candidate must clear
/// (`min_simulation_oe_drop_pct`); `None` otherwise (the effect must be found). The simulation of
/// a play is chaotic at reversals (a sub-step earlier or later at a breakaway changes the
/// bounces that follow): on seed 2 of the weak play the true plant's own drop is 10-12 %
/// against the 8 % bar, and numerically equivalent simulators (sub-stepped or stepped whole
/// where nothing happens) put the fitted play at 6.7 % and 13.6 %: whether it clears the bar is
/// then the arithmetic's last bits, not the method.
fn unresolved_on_simulation(
    logs: &[Record],
    truth: &Plant,
    d: &diagnose::Diagnosis,
    opts: &DiagnoseOptions,
) -> Option<f64> {
    let on_simulation = truth
        .effects
        .iter()
        .any(|e| e.kind.sim_role() == servo_core::effects::SimRole::Contact);
    if !on_simulation {
        return None;
    }
    let reference = d.base.oe_cost_rad?;
    let ds = Dataset::new(logs, &d.base.plant.params, &opts.fit).ok()?;
    let cost = oe::prediction_cost(&ds, truth, oe::Part::Holdout)?;
    let drop_pct = 100.0 * (1.0 - cost / reference);
    (drop_pct < 2.0 * opts.thresholds.min_simulation_oe_drop_pct).then_some(drop_pct)
}

fn main_param(kind: EffectKind) -> &'static [&'static str] {
    match kind {
        EffectKind::Stribeck => &["tau_s"],
        EffectKind::Asymmetry => &["tau_sf_pos", "tau_sf_neg"],
        EffectKind::Backlash => &["gap"],
        EffectKind::Cogging | EffectKind::Imbalance => &["amplitude"],
        EffectKind::Saturation => &["limit"],
        EffectKind::Deadzone => &["width"],
        EffectKind::Delay => &["delay"],
        _ => &[],
    }
}

/// Prints the first `take` candidates of a diagnosis, tagged (shown when a test fails).
pub(crate) fn print_ranking(tag: &str, d: &diagnose::Diagnosis, take: usize) {
    for c in d.ranking.iter().take(take) {
        eprintln!(
            "[{tag}] {:<10} sig={} red={:.1}% oe={:?} bic={:.1}",
            c.effect.name(),
            c.significant,
            c.error_reduction_pct,
            c.oe_reduction_pct.map(|v| (v * 10.0).round() / 10.0),
            c.bic_gain
        );
        for k in &c.checks {
            eprintln!(
                "[{tag}]    check {} passed={} {}",
                k.name, k.passed, k.detail
            );
        }
    }
}

fn check_hidden(spec: &str, seed: u64) {
    let hidden = Effect::parse(spec).unwrap();
    let plant = truth(&[hidden]);
    let logs = logs(&plant, seed);
    let model = identified(&logs);
    let opts = DiagnoseOptions::default();
    let d = diagnose::diagnose(&logs, &model, &opts).unwrap();
    print_ranking(&format!("{spec} seed {seed}"), &d, usize::MAX);
    if let Some(truth_drop_pct) = unresolved_on_simulation(&logs, &plant, &d, &opts) {
        // The true plant itself barely beats the base model on the held-out simulation: the
        // data cannot show this effect clearly, and nothing else may be named for it.
        eprintln!(
            "[{spec} seed {seed}] the true plant cuts the held-out simulation error by only \
             {truth_drop_pct:.1} %: not required to be found"
        );
        if let Some(w) = d.winner() {
            assert_eq!(
                w.effect, hidden.kind,
                "[{spec} seed {seed}] wrong winner: {}",
                d.verdict
            );
        }
        return;
    }
    let w = d
        .winner()
        .unwrap_or_else(|| panic!("[{spec} seed {seed}] nothing significant: {}", d.verdict));
    assert_eq!(
        w.effect, hidden.kind,
        "[{spec} seed {seed}] wrong winner: {}",
        d.verdict
    );
    // compare --add: fit the effect with base refit on all data; main parameter within 15 %.
    let r = fit::fit_model(
        &logs,
        &model,
        &[EffectToFit::all(hidden.kind)],
        &FitOptions::default(),
    )
    .unwrap();
    for key in main_param(hidden.kind) {
        let got = r.plant.effects.value(hidden.kind, key).unwrap();
        let want = hidden.get(key).unwrap();
        assert!(
            (got / want - 1.0).abs() < 0.15,
            "[{spec} seed {seed}] {key}: fitted {got}, true {want}"
        );
    }
    let eq = r
        .equations
        .iter()
        .find(|e| e.equation == w.equation)
        .unwrap();
    assert!(
        eq.rms_after < eq.rms_before,
        "[{spec} seed {seed}] the fit did not improve: {eq:?}"
    );
    // ... and so does the simulation: the prediction error of the model with the effect added
    // is below that of the base model refitted alone, on the same data.
    let ds = Dataset::new(&logs, &model.params, &FitOptions::default()).unwrap();
    let base = fit::fit_model(&logs, &model, &[], &FitOptions::default()).unwrap();
    let before = oe::prediction_cost(&ds, &base.plant, oe::Part::All).unwrap();
    let after = oe::prediction_cost(&ds, &r.plant, oe::Part::All).unwrap();
    eprintln!("[{spec} seed {seed}] simulation error {before:.4e} -> {after:.4e} rad");
    assert!(
        after < 0.95 * before,
        "[{spec} seed {seed}] the simulation error did not fall: {before:.4e} -> {after:.4e} rad"
    );
}

/// Runs `check` on every seed and fails with every seed's message, not only the first.
fn every_seed(seeds: impl IntoIterator<Item = u64>, check: impl Fn(u64)) {
    let failures: Vec<String> = seeds
        .into_iter()
        .filter_map(|seed| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(seed)))
                .err()
                .map(|e| {
                    e.downcast_ref::<String>()
                        .cloned()
                        .unwrap_or_else(|| format!("seed {seed} failed"))
                })
        })
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

macro_rules! hidden_tests {
    ($($name:ident: $spec:expr, $seeds:expr;)*) => {$(
        #[test]
        fn $name() {
            let _machine = servo_e2e::shared();
            every_seed($seeds, |seed| check_hidden($spec, seed));
        }
    )*};
}

/// Every effect is checked on the same seeds (not chosen per effect): three independent noise
/// and excitation draws per strength.
const SEEDS: [u64; 3] = [1, 2, 3];

hidden_tests! {
    hidden_stribeck: "stribeck:tau_s=0.02,omega_s=0.5", SEEDS;
    hidden_stribeck_weak: "stribeck:tau_s=0.015,omega_s=0.5", SEEDS;
    hidden_asymmetry: "asymmetry:tau_sf_pos=0.013,tau_sf_neg=0.008", SEEDS;
    hidden_asymmetry_weak: "asymmetry:tau_sf_pos=0.0115,tau_sf_neg=0.009", SEEDS;
    hidden_backlash: "backlash:gap=0.03", SEEDS;
    hidden_backlash_weak: "backlash:gap=0.015", SEEDS;
    hidden_cogging: "cogging:amplitude=3e-4,harmonic=12,phase=0.3", SEEDS;
    hidden_cogging_weak: "cogging:amplitude=1.5e-4,harmonic=18,phase=1.0", SEEDS;
    hidden_imbalance: "imbalance:amplitude=0.01,phase=0.5", SEEDS;
    hidden_imbalance_weak: "imbalance:amplitude=0.004,phase=-1.0", SEEDS;
    hidden_saturation: "saturation:limit=4.0", SEEDS;
    hidden_saturation_weak: "saturation:limit=6.5", SEEDS;
    hidden_deadzone: "deadzone:width=0.4", SEEDS;
    hidden_deadzone_weak: "deadzone:width=0.15", SEEDS;
    hidden_delay: "delay:delay=0.003", SEEDS;
    hidden_delay_weak: "delay:delay=0.0012", SEEDS;
}

#[test]
fn complete_model_has_nothing_significant() {
    let _machine = servo_e2e::shared();
    for seed in [11, 12, 13, 14, 15] {
        let plant = truth(&[]);
        let logs = logs(&plant, seed);
        let model = identified(&logs);
        let d = diagnose::diagnose(&logs, &model, &DiagnoseOptions::default()).unwrap();
        print_ranking(&format!("none seed {seed}"), &d, usize::MAX);
        eprintln!("[none seed {seed}] not resolvable: {:?}", d.unresolvable);
        assert!(
            d.winner().is_none(),
            "[seed {seed}] false positive: {}",
            d.verdict
        );
        assert!(d.verdict.contains("No missing effect"));
        assert_no_resonance(&format!("none seed {seed}"), &d);
    }
}

/// No balance of `d` names a resonance: the plant behind these logs has none (a rigid shaft),
/// so a resonance named would be the diagnosis's own making (e.g. the corner of the filter every
/// regressor goes through, 25 Hz by default).
pub(crate) fn assert_no_resonance(tag: &str, d: &diagnose::Diagnosis) {
    for b in &d.balances {
        let named: Vec<&str> = b
            .signatures
            .iter()
            .filter(|s| s.kind == "resonance")
            .map(|s| s.description.as_str())
            .collect();
        assert!(
            named.is_empty() && b.resonance.is_none(),
            "[{tag}] the {} balance names a resonance the plant does not have: {named:?} {:?}",
            b.balance.name(),
            b.resonance
        );
    }
}

/// Two hidden effects found one after the other by `diagnose_loop`: both added, nothing left
/// to name, the simulation error falling along the ladder. Returns the last rung's model.
fn check_two_hidden(specs: [&str; 2], seed: u64) -> Plant {
    let hidden = specs.map(|s| Effect::parse(s).unwrap());
    let plant = truth(&hidden);
    let logs = logs(&plant, seed);
    let model = identified(&logs);
    let (ladder, diags) =
        diagnose::diagnose_loop(&logs, &model, &DiagnoseOptions::default(), 3).unwrap();
    let added: Vec<EffectKind> = ladder.iter().filter_map(|r| r.added).collect();
    for d in &diags {
        eprintln!("[{specs:?} seed {seed}] {}", d.verdict);
        print_ranking(&format!("{specs:?} seed {seed}"), d, 3);
    }
    assert_eq!(added.len(), 2, "[{specs:?} seed {seed}] added {added:?}");
    assert!(
        hidden.iter().all(|h| added.contains(&h.kind)),
        "[{specs:?} seed {seed}] added {added:?}"
    );
    assert!(diags.last().unwrap().winner().is_none());
    // The error falls along the ladder.
    let oe: Vec<f64> = ladder.iter().map(|r| r.oe_cost_rad.unwrap()).collect();
    assert!(
        oe.windows(2).all(|w| w[1] < w[0]),
        "[{specs:?} seed {seed}] ladder {oe:?}"
    );
    ladder.last().unwrap().plant
}

#[test]
fn two_hidden_effects_are_found_one_after_the_other() {
    let _machine = servo_e2e::shared();
    for seed in [21, 22] {
        check_two_hidden(
            ["deadzone:width=0.4", "imbalance:amplitude=0.01,phase=0.5"],
            seed,
        );
    }
}

#[test]
fn two_hidden_friction_and_drive_effects_are_found_one_after_the_other() {
    let _machine = servo_e2e::shared();
    for seed in [21, 22] {
        check_two_hidden(
            ["stribeck:tau_s=0.02,omega_s=0.5", "delay:delay=0.003"],
            seed,
        );
    }
}

#[test]
fn two_hidden_mechanical_effects_are_found_one_after_the_other() {
    let _machine = servo_e2e::shared();
    for seed in [21, 22] {
        check_two_hidden(
            ["backlash:gap=0.03", "imbalance:amplitude=0.01,phase=0.5"],
            seed,
        );
    }
}

/// A gear play and an input delay (two at once, both acting at every reversal): the delay is
/// named first, sized in the electrical balance, where the play biases it (the balance infers
/// the motor speed from the load angle; 3.9-4.4 ms for 3.0 ms); the play is named next, and with
/// it in the model the delay is sized again (`Dataset::fit_config` also fits a play entering
/// from the input effects re-searched with it, then refines the delay with the gap on the
/// simulation, and keeps the start that predicts the fit blocks better). Both are added,
/// with their main parameters within 25 %, and the simulation error falls along the ladder.
fn check_play_and_delay(seed: u64) {
    let specs = ["backlash:gap=0.03", "delay:delay=0.003"];
    let last = check_two_hidden(specs, seed);
    for h in specs.map(|s| Effect::parse(s).unwrap()) {
        for key in main_param(h.kind) {
            let got = last.effects.value(h.kind, key).unwrap();
            let want = h.get(key).unwrap();
            eprintln!(
                "[play+delay seed {seed}] {} {key}: {got} (true {want})",
                h.kind
            );
            assert!(
                (got / want - 1.0).abs() < 0.25,
                "[seed {seed}] {} {key}: fitted {got}, true {want}",
                h.kind
            );
        }
    }
}

#[test]
fn a_gear_play_and_an_input_delay_are_found_with_their_parameters() {
    let _machine = servo_e2e::shared();
    every_seed([21, 22, 23, 24, 25], check_play_and_delay);
}

/// Real closed-loop PID steps of the Padova 2021 SRV-02 (u logged, no current) against the
/// nominal datasheet model: the missing friction is named.
#[test]
fn real_pid_steps_name_the_missing_friction() {
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    let path = dir.join("padova2021-jacopisky/csv/pid_bode_steps.csv");
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("SKIP: cannot read {}: {e}", path.display());
            return;
        }
    };
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ct, cth, cu) = (col("t_s"), col("thl_meas_deg"), col("u_V"));
    let (mut t, mut th, mut u) = (vec![], vec![], vec![]);
    for l in lines {
        let f: Vec<f64> = l.split(',').map(|v| v.trim().parse().unwrap()).collect();
        t.push(f[ct]);
        th.push(f[cth].to_radians());
        u.push(f[cu]);
    }
    let rec = Record {
        source: path.display().to_string(),
        time_s: t,
        theta_l_rad: Some(th),
        u_v: Some(u),
        ..Record::default()
    };
    let nominal = Plant::from_params(PlantParams::TABLE2).unwrap();
    let d = diagnose::diagnose(
        std::slice::from_ref(&rec),
        &nominal,
        &DiagnoseOptions::default(),
    )
    .unwrap();
    for c in &d.ranking {
        eprintln!(
            "[real] {:<10} sig={} red={:.1}% oe={:?} bic={:.1} params={:?}",
            c.effect.name(),
            c.significant,
            c.error_reduction_pct,
            c.oe_reduction_pct,
            c.bic_gain,
            c.params
                .iter()
                .map(|p| (p.key, p.value))
                .collect::<Vec<_>>()
        );
    }
    eprintln!(
        "[real] base: {:?}",
        d.base
            .equations
            .iter()
            .map(|e| (e.0.name(), e.1))
            .collect::<Vec<_>>()
    );
    eprintln!(
        "[real] base J_eq {:.3e} B_eq {:.3e}; OE {:?}",
        d.base.plant.params.j_eq(),
        d.base.plant.b_eq(),
        d.base.oe_cost_rad
    );
    eprintln!("[real] verdict: {}", d.verdict);
    let w = d
        .winner()
        .expect("a significant candidate on the real data");
    assert!(
        matches!(w.effect, EffectKind::Coulomb),
        "expected the missing Coulomb friction first, got {}",
        w.effect
    );
    let r = fit::fit_model(
        std::slice::from_ref(&rec),
        &nominal,
        &[EffectToFit::all(EffectKind::Coulomb)],
        &FitOptions::default(),
    )
    .unwrap();
    eprintln!(
        "[real] fitted: tau_sf {:.4e} N m, J_eq {:.3e}, B_eq {:.3e}; {:?}",
        r.plant.tau_sf(),
        r.plant.params.j_eq(),
        r.plant.b_eq(),
        r.equations
    );
    // Published estimates for this motor: tau_sf 9.5-9.9e-3 N m. Closed-loop steps without current
    // constrain it less tightly: accept a factor 2.
    assert!(
        r.plant.tau_sf() > 0.005 && r.plant.tau_sf() < 0.02,
        "tau_sf {}",
        r.plant.tau_sf()
    );
    assert!(r.equations[0].rms_after < r.equations[0].rms_before);
}

/// Real logs without the input voltage (padova2022-mustacchi: speed-controlled friction
/// staircases and acceleration phases, motor speed and current only) against the nominal
/// model: the torque balance alone names the missing Coulomb friction, at the published level,
/// and the verdict says that no simulation check was possible.
#[test]
fn real_logs_without_voltage_name_the_missing_friction() {
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    let d = dir.join("padova2022-mustacchi/csv");
    if !d.join("friction_pos.csv").exists() {
        eprintln!("SKIP: {} is absent", d.display());
        return;
    }
    let tmp = std::env::temp_dir().join(format!("servo-diag-nou-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let model = tmp.join("nominal.toml");
    let (ok, out, err) = servo_e2e::servo(&["params", "--preset", "table2"]);
    assert!(ok, "{err}");
    std::fs::write(&model, out).unwrap();
    let logs: Vec<String> = ["friction_pos.csv", "friction_neg.csv", "inertia.csv"]
        .iter()
        .map(|f| d.join(f).display().to_string())
        .collect();
    let mut args: Vec<&str> = vec!["diagnose"];
    args.extend(logs.iter().map(String::as_str));
    let model_s = model.display().to_string();
    args.extend([
        "--model",
        &model_s,
        "--columns",
        "time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A",
        "--json",
    ]);
    let (ok, out, err) = servo_e2e::servo(&args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let first = &v["ranking"][0];
    assert_eq!(first["effect"], "coulomb", "{out}");
    assert_eq!(first["significant"], true, "{out}");
    let tau = first["params"]["tau_sf"]["value"].as_f64().unwrap();
    // Published for this motor: tau_sf = 0.01064 N m (steady-state LS on the staircases).
    assert!((tau / 0.01064 - 1.0).abs() < 0.15, "tau_sf {tau}");
    let verdict = v["verdict"].as_str().unwrap();
    assert!(
        verdict.contains("No log records the input voltage u"),
        "{verdict}"
    );
    let names: Vec<&str> = v["ranking"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["effect"].as_str().unwrap())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| ["saturation", "deadzone", "delay", "backlash"].contains(n)),
        "input-side candidates tried without u: {names:?}"
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

/// A simulator that is not servo's: the handout's equations (driver lag, armature, rigid
/// mechanics) integrated with classic RK4 at 20 us, Coulomb friction smoothed as
/// tau_sf tanh(omega_l / 0.05 rad/s) (the shaft creeps instead of sticking, as in many
/// simulators), an optional imbalance, the same sensors. Returns (open-loop, closed-loop) logs.
fn other_simulator_logs(imbalance: Option<(f64, f64)>, seed: u64) -> Vec<Record> {
    // The imbalance is a load torque a sin(theta_l + phase), seen at the motor divided by N.
    let extra = move |th_m: f64, _w_m: f64| {
        imbalance.map_or(0.0, |(a, ph)| a * (th_m / 14.0 + ph).sin() / 14.0)
    };
    other_simulator_with(
        &Mechanism {
            motor_torque: &extra,
            ..Mechanism::NONE
        },
        seed,
    )
}

/// A mechanism outside the catalogue, added to the other simulator: an extra load torque seen
/// at the motor [N m] as a function of (motor angle [rad], motor speed [rad/s]), an offset of the
/// current sensor [A], an error of the load-angle sensor [rad] as a function of the load angle,
/// and an optional compliant shaft (stiffness [N m/rad] at the load, damping [N m s/rad], share
/// of J_eq on the load side).
struct Mechanism<'a> {
    motor_torque: &'a dyn Fn(f64, f64) -> f64,
    current_offset_a: f64,
    angle_error: &'a dyn Fn(f64) -> f64,
    shaft: Option<(f64, f64, f64)>,
    /// A friction that grows with the torque the gears transmit: this share of |k_t i_a|
    /// opposes the load's motion (a gear mesh's load-dependent loss) [1].
    torque_friction: f64,
}

impl Mechanism<'_> {
    const NONE: Mechanism<'static> = Mechanism {
        motor_torque: &|_, _| 0.0,
        current_offset_a: 0.0,
        angle_error: &|_| 0.0,
        shaft: None,
        torque_friction: 0.0,
    };
}

fn other_simulator_with(m: &Mechanism, seed: u64) -> Vec<Record> {
    let p = PlantParams {
        j_eq: Some(7.0e-7),
        b_eq: Some(1.0e-6),
        tau_sf: Some(0.01),
        ..PlantParams::TABLE2
    };
    let (n, j, b, r, l) = (p.n, p.j_eq(), p.b_eq(), p.r_eq(), p.l_a);
    let t_drv = p.t_drv();
    // x = [u_drv, i_a, omega_m, theta_m, omega_l N, theta_l N] (the last two: the load's motion
    // seen at the motor side, only with a compliant shaft).
    let f = |x: [f64; 6], u: f64| -> [f64; 6] {
        let tau_m = p.k_t * x[1];
        let (load_w, load_th) = if m.shaft.is_some() {
            (x[4], x[5])
        } else {
            (x[2], x[3])
        };
        let w_l = load_w / n;
        let tau_l = 0.01 * (w_l / 0.05).tanh() / n
            + (m.motor_torque)(load_th, load_w)
            + m.torque_friction * tau_m.abs() * (w_l / 0.05).tanh();
        let mut d = [0.0; 6];
        d[0] = (p.k_drv * u - x[0]) / t_drv;
        d[1] = (x[0] - r * x[1] - p.k_e * x[2]) / l;
        match m.shaft {
            None => {
                d[2] = (tau_m - b * x[2] - tau_l) / j;
                d[3] = x[2];
            }
            Some((k, c, frac)) => {
                // Spring between motor and load, referred to the motor side.
                let (km, cm) = (k / (n * n), c / (n * n));
                let spring = km * (x[3] - x[5]) + cm * (x[2] - x[4]);
                d[2] = (tau_m - b * x[2] - spring) / (j * (1.0 - frac));
                d[3] = x[2];
                d[4] = (spring - tau_l) / (j * frac);
                d[5] = x[4];
            }
        }
        d
    };
    let step = |x: &mut [f64; 6], u: f64| {
        let h = 20e-6;
        for _ in 0..50 {
            let k1 = f(*x, u);
            let a = |k: &[f64; 6], s: f64| core::array::from_fn(|i| x[i] + s * k[i]);
            let k2 = f(a(&k1, h / 2.0), u);
            let k3 = f(a(&k2, h / 2.0), u);
            let k4 = f(a(&k3, h), u);
            for i in 0..6 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    };
    let cpr = 4096.0;
    let shaft = m.shaft.is_some();
    let read = |x: &[f64; 6]| {
        let th_l = if shaft { x[5] } else { x[3] } / n;
        let th = th_l + (m.angle_error)(th_l);
        (th / std::f64::consts::TAU * cpr).floor() * std::f64::consts::TAU / cpr
    };
    let mut rng = SplitMix64(seed ^ 0xA11CE);
    let mut out = Vec::new();
    // Open loop: voltage steps of random size and sign every 0.4 s.
    {
        let mut x = [0.0; 6];
        let (mut t, mut th, mut ia, mut uv) = (vec![], vec![], vec![], vec![]);
        let mut u = 0.0;
        for k in 0..16_000 {
            if k % 400 == 0 {
                let mag = 0.8 + 7.0 * rng.uniform();
                u = if rng.uniform() < 0.5 { -mag } else { mag };
            }
            t.push(k as f64 * DT);
            th.push(read(&x));
            ia.push(x[1] + m.current_offset_a + 2e-3 * rng.normal());
            uv.push(u);
            step(&mut x, u);
        }
        out.push(record(t, th, ia, uv, None, "other-sim open-loop"));
    }
    // Closed loop: the same PID as `closed_loop`.
    let x = core::cell::RefCell::new([0.0; 6]);
    out.push(pid_log(
        12_000,
        &mut rng,
        |rng| {
            let x = x.borrow();
            (read(&x), x[1] + m.current_offset_a + 2e-3 * rng.normal())
        },
        |u| step(&mut x.borrow_mut(), u),
        "other-sim closed-loop",
    ));
    out
}

/// Data from another simulator (RK4, smooth Coulomb friction that creeps): the identified
/// viscous + Coulomb model leaves nothing significant, and a hidden imbalance is named first
/// and sized within 15 %. Guards against fitting servo's own simulator rather than the physics.
#[test]
fn another_simulators_data_are_diagnosed_on_the_physics() {
    let _machine = servo_e2e::shared();
    for seed in [31, 32] {
        let logs = other_simulator_logs(None, seed);
        let model = identified(&logs);
        let d = diagnose::diagnose(&logs, &model, &DiagnoseOptions::default()).unwrap();
        print_ranking(&format!("other none {seed}"), &d, 3);
        assert_no_resonance(&format!("other none {seed}"), &d);
        assert!(
            d.winner().is_none(),
            "[seed {seed}] false positive: {}",
            d.verdict
        );

        let logs = other_simulator_logs(Some((0.006, 0.4)), seed);
        let model = identified(&logs);
        let d = diagnose::diagnose(&logs, &model, &DiagnoseOptions::default()).unwrap();
        let w = d
            .winner()
            .unwrap_or_else(|| panic!("[seed {seed}] nothing found: {}", d.verdict));
        assert_eq!(
            w.effect,
            EffectKind::Imbalance,
            "[seed {seed}] {}",
            d.verdict
        );
        let a = w
            .params
            .iter()
            .find(|p| p.key == "amplitude")
            .unwrap()
            .value;
        assert!(
            (a / 0.006 - 1.0).abs() < 0.15,
            "[seed {seed}] amplitude {a}"
        );
    }
}

/// The other simulator with mechanism `m` (seed `seed`), its base model identified and diagnosed;
/// the ranking and every balance printed, tagged.
fn diagnose_other(m: &Mechanism, tag: &str, seed: u64) -> diagnose::Diagnosis {
    let logs = other_simulator_with(m, seed);
    let model = identified(&logs);
    let d = diagnose::diagnose(&logs, &model, &DiagnoseOptions::default()).unwrap();
    print_ranking(tag, &d, 4);
    print_balances(tag, &d);
    d
}

/// Prints every balance of `d`, tagged: its ratio to the noise floor, whether it is above it,
/// and its signatures (kind, share of the held-out residual [%], description).
pub(crate) fn print_balances(tag: &str, d: &diagnose::Diagnosis) {
    for b in &d.balances {
        eprintln!(
            "[{tag}] {} ratio {:.2} above={} sigs {:?}",
            b.balance.name(),
            b.ratio_to_noise,
            b.above_noise,
            b.signatures
                .iter()
                .map(|s| (s.kind, (100.0 * s.share).round(), s.description.clone()))
                .collect::<Vec<_>>()
        );
    }
}

/// `d` is "unexplained" with no catalogue effect named (`tag` in the messages).
fn assert_unexplained_nothing_named(tag: &str, d: &diagnose::Diagnosis) {
    assert!(
        d.winner().is_none(),
        "[{tag}] a catalogue effect was named: {}",
        d.verdict
    );
    assert_eq!(
        d.status,
        diagnose::Status::Unexplained,
        "[{tag}] {}",
        d.verdict
    );
}

/// Mechanisms outside the catalogue, in the other simulator: the verdict is "unexplained", no
/// catalogue effect is named, and the balance and the shape that carry the error are named.
fn check_outside(tag: &str, m: &Mechanism, balance: &str, signature: &str, seeds: &[u64]) {
    for &seed in seeds {
        let d = diagnose_other(m, &format!("{tag} {seed}"), seed);
        assert_no_resonance(&format!("{tag} {seed}"), &d);
        assert_unexplained_nothing_named(&format!("{tag} seed {seed}"), &d);
        let hit = d.unexplained.iter().any(|b| {
            b.balance.name() == balance && b.signatures.first().is_some_and(|s| s.kind == signature)
        });
        assert!(
            hit,
            "[{tag} seed {seed}] expected the {balance} balance with a {signature} signature: {}",
            d.verdict
        );
    }
}

/// A friction outside the catalogue in the other simulator: the verdict is "unexplained", the
/// torque balance's first signature is the measured friction curve's shape `shape`, and
/// `--discover` proposes the library term `key` within 25 % of `truth` (its coefficient at the
/// load side, as the library's terms are load torques).
fn check_friction_shape(tag: &str, m: &Mechanism, shape: &str, key: &str, truth: f64, seed: u64) {
    let tag = format!("{tag} {seed}");
    let logs = other_simulator_with(m, seed);
    let model = identified(&logs);
    let opts = DiagnoseOptions::default();
    let d = diagnose::diagnose(&logs, &model, &opts).unwrap();
    print_ranking(&tag, &d, 4);
    if let Some(c) = &d.friction_curve {
        for b in &c.bins {
            eprintln!(
                "[{tag}] bin dir {:+} {:.3} rad/s: {:.4e} +/- {:.1e} N m (model {:.4e}, {} rows)",
                b.direction, b.speed_rad_s, b.torque_nm, b.ci_nm, b.model_nm, b.rows
            );
        }
        eprintln!("[{tag}] shape {:?}", c.shape);
    }
    print_balances(&tag, &d);
    assert_no_resonance(&tag, &d);
    assert_unexplained_nothing_named(&tag, &d);
    let first = d
        .unexplained
        .iter()
        .find(|b| b.balance.name() == "torque")
        .and_then(|b| b.signatures.first());
    assert_eq!(
        first.map(|s| s.kind),
        Some(diagnose::friction_curve::KIND),
        "[{tag}] the torque balance's first signature: {}",
        d.verdict
    );
    let named = d
        .friction_curve
        .as_ref()
        .and_then(|c| c.shape.as_ref())
        .map(|s| s.shape.name());
    assert_eq!(named, Some(shape), "[{tag}] {}", d.verdict);
    if shape == "direction_slopes" {
        let steeper = if key == "b_bwd" {
            "backwards"
        } else {
            "forwards"
        };
        let words = first.map_or("", |s| s.description.as_str());
        assert!(
            words.contains(&format!("steeper {steeper}")),
            "[{tag}] the shape names the wrong direction: {words}"
        );
    }
    let found =
        diagnose::user_effects::judge_user_effects(&logs, &model, &opts, &[], &d, Some("found"))
            .unwrap();
    let disc = found.discovery.unwrap_or_else(|| {
        panic!(
            "[{tag}] discovery did not run: {:?}",
            found.discovery_skipped
        )
    });
    eprintln!(
        "[{tag}] discovery: {} rejected {:?}",
        disc.words(),
        disc.rejected
    );
    let (_, judged) = disc
        .proposal
        .as_ref()
        .unwrap_or_else(|| panic!("[{tag}] nothing proposed: {:?}", disc.rejected));
    let v = judged
        .params
        .iter()
        .find(|p| p.0 == key)
        .unwrap_or_else(|| panic!("[{tag}] no `{key}` term proposed: {}", disc.words()))
        .2;
    assert!(
        (v / truth - 1.0).abs() <= 0.25,
        "[{tag}] {key} = {v:.4e}, truth {truth:.4e}: {}",
        disc.words()
    );
}

/// Load friction growing with the square of speed (a fluid drag), 5e-5 N m s^2/rad^2 at the
/// load (0.005 N m at 10 rad/s): no catalogue friction fits it (a breakaway friction bent to it
/// has no hump to show in the measured curve); the curve rises faster than linearly, and
/// `--discover` proposes c_drag w_l |w_l| within 25 %.
#[test]
fn friction_rising_faster_than_linear_is_unexplained() {
    let _machine = servo_e2e::shared();
    let drag = |_th: f64, w_m: f64| {
        let w_l = w_m / 14.0;
        5e-5 * w_l * w_l.abs() / 14.0
    };
    for seed in [41, 42] {
        check_friction_shape(
            "quadratic drag",
            &Mechanism {
                motor_torque: &drag,
                ..Mechanism::NONE
            },
            "faster_than_linear",
            "c_drag",
            5e-5,
            seed,
        );
    }
}

/// A friction that grows with the transmitted torque (25 % of |k_t i_a| opposing the motion,
/// a load-dependent gear loss; outside the catalogue) in the other simulator, on a rigid shaft:
/// no balance names a resonance (before the filter's response was divided out of the residual's
/// spectrum, the torque balance of this plant "rang" near 25.9 Hz: the corner of servo's own
/// 25 Hz filter); the verdict is "unexplained" with the friction curve's shape "grows with the
/// transmitted torque" first, and `--discover` proposes mu_i |i_a| sign(w) within 25 % of
/// 0.25 k_t N (load side: the simulator's motor-side 0.25 k_t |i_a| times N = 14).
#[test]
fn friction_growing_with_transmitted_torque_names_no_resonance() {
    let _machine = servo_e2e::shared();
    let k_t = PlantParams::TABLE2.k_t;
    for seed in [55, 56] {
        check_friction_shape(
            "torque friction",
            &Mechanism {
                torque_friction: 0.25,
                ..Mechanism::NONE
            },
            "transmitted_torque",
            "mu_i",
            0.25 * k_t * 14.0,
            seed,
        );
    }
}

/// The lab model (`servo params`) as `model.toml` in `dir`, the truth `truth.toml` (the lab model
/// with the user-effect section `section`) and gains designed at 30 rad/s, 60 deg
/// (`gains.toml`).
fn user_effect_rig(dir: &std::path::Path, section: &str) {
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (ok, params, err) = servo_e2e::servo(&["params"]);
    assert!(ok, "servo params failed: {err}");
    std::fs::write(p("model.toml"), &params).unwrap();
    std::fs::write(p("truth.toml"), format!("{params}\n{section}")).unwrap();
    let (ok, _, err) =
        servo_e2e::servo(&["design", "--wc", "30", "--pm", "60", "-o", &p("gains.toml")]);
    assert!(ok, "design failed: {err}");
}

/// One minute of logs of the rig in `dir` ([`user_effect_rig`]) as the benchmark takes them (a
/// PRBS of `amp` V, a square wave; seed `seed`), diagnosed through `servo diagnose --json` against
/// its lab model; `tag` in the messages.
fn diagnose_rig_json(dir: &std::path::Path, amp: &str, seed: u64, tag: &str) -> serde_json::Value {
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (open, closed) = (
        p(&format!("open{seed}.mcap")),
        p(&format!("closed{seed}.mcap")),
    );
    servo_e2e::prbs_and_square_logs(
        &["--plant", &p("truth.toml")],
        &p("gains.toml"),
        amp,
        seed,
        (&open, &closed),
    );
    let (ok, out, err) = servo_e2e::servo(&[
        "diagnose",
        &open,
        &closed,
        "--model",
        &p("model.toml"),
        "--json",
    ]);
    assert!(ok, "[{tag}] diagnose failed: {err}");
    serde_json::from_str(&out).unwrap()
}

/// servo's own simulator with a fluid drag c w_l |w_l| (a user effect of the plant file, outside
/// the catalogue; the benchmark's plant), open loop on a PRBS voltage and closed loop on a square
/// reference, diagnosed through `servo diagnose --json` against the lab model. The PRBS holds the
/// shaft at the drag's terminal speed, where the encoder's quantisation ripple, aliased by the
/// 1 kHz sampling, puts a peak in the electrical balance (28.5 Hz at 5 V, 34.5 Hz at 4.5 V: it
/// moves with the speed) while that balance stays below its noise floor: it was named "rings as a
/// resonance". No balance names a resonance; the status is "unexplained" with the torque
/// balance's friction-curve shape first.
#[test]
fn a_drag_at_terminal_speed_names_no_resonance() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    user_effect_rig(
        dir.path(),
        "[custom.drag]\nacts_on = \"load_torque\"\nexpr = \"c * omega_l * abs(omega_l)\"\n\
         description = \"a fluid drag\"\n[custom.drag.params]\nc = { value = 5e-5, unit = \"N m s^2/rad^2\" }\n",
    );
    for (amp, seed) in [("5", 3u64), ("4.5", 5)] {
        let tag = format!("drag PRBS {amp} V seed {seed}");
        let v = diagnose_rig_json(dir.path(), amp, seed, &tag);
        for b in v["balances"].as_array().unwrap() {
            let kinds: Vec<&str> = b["signatures"]
                .as_array()
                .unwrap()
                .iter()
                .map(|s| s["kind"].as_str().unwrap())
                .collect();
            eprintln!(
                "[{tag}] {} ratio {} {kinds:?}",
                b["balance"], b["ratio_to_noise"]
            );
            assert!(
                !kinds.contains(&"resonance"),
                "[{tag}] the {} balance names a resonance the plant does not have: {}",
                b["balance"],
                b["signatures"]
            );
        }
        assert_unexplained_by_a_friction_shape(&v, &tag);
    }
}

/// A friction growing with the transmitted torque on servo's own simulator (a user effect
/// mu |i_a| sign(w_l), mu = 0.025 N m/A at the load: 23 % of |k_t i_a| N), one minute of logs as
/// the benchmark takes them (a PRBS and a square wave), diagnosed through `servo diagnose --json`
/// against the lab model: "unexplained", the torque balance's first signature the friction
/// curve's `transmitted_torque` shape with its coefficient within 25 %. Found at stop 51 by the
/// benchmark: the shape was measured within 1 % (|t| = 27.6) and not named, as its share was
/// taken of the base's residual on the sliding rows, most of which other Coulomb, viscous and
/// inertia levels take there (the base was fitted on every row, the reversals where |i_a|
/// peaks included); "a step with the sign of u" led instead.
#[test]
fn a_friction_growing_with_the_current_on_servos_simulator_is_shaped() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    user_effect_rig(
        dir.path(),
        "[custom.tf]\nacts_on = \"load_torque\"\nexpr = \"mu * abs(i_a) * sign(omega_l)\"\n\
         description = \"a friction growing with the transmitted torque\"\n[custom.tf.params]\nmu = { value = 0.025, unit = \"N m/A\" }\n",
    );
    let v = diagnose_rig_json(dir.path(), "5", 1, "torque friction");
    assert_unexplained_by_a_friction_shape(&v, "torque friction");
    let shape = &v["friction_curve"]["shape"];
    assert_eq!(shape["shape"], "transmitted_torque", "{shape}");
    let k_t = PlantParams::TABLE2.k_t;
    let truth = 0.025 / (k_t * PlantParams::TABLE2.n);
    let got = shape["coefficient"].as_f64().unwrap();
    assert!((got / truth - 1.0).abs() < 0.25, "{got} for {truth}");
}

/// `servo diagnose --json` output `v` is "unexplained", the torque balance's first signature the
/// measured friction curve's shape (`tag` in the messages).
fn assert_unexplained_by_a_friction_shape(v: &serde_json::Value, tag: &str) {
    assert_eq!(v["status"], "unexplained", "[{tag}] {}", v["verdict"]);
    let torque = v["balances"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["balance"] == "torque")
        .unwrap();
    assert_eq!(
        torque["signatures"][0]["kind"], "friction_curve",
        "[{tag}] {}",
        torque["signatures"]
    );
}

/// A driver dead band of 0.3 V (half width) on servo's simulator, one minute of logs as the
/// benchmark takes them (a PRBS of +-5 V and a square wave), through `servo diagnose --json`:
/// "missing deadzone" with its width within 25 %. Found at stop 51 by running the catalogue on
/// the benchmark's excitation: the fit was exact (0.3005 V, 98.9 % of the electrical residual)
/// and refused as narrower than twice a 10 V "u resolution", the spacing of the PRBS's two
/// levels (`MIN_U_LEVELS`).
#[test]
fn a_dead_band_under_a_two_level_prbs_is_named() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    user_effect_rig(dir.path(), "[effects.deadzone]\nwidth = 0.3\n");
    let v = diagnose_rig_json(dir.path(), "5", 21, "dead band");
    assert_eq!(v["status"], "missing", "{}", v["verdict"]);
    let w = &v["ranking"][0];
    assert_eq!(w["effect"], "deadzone", "{}", v["verdict"]);
    let width = w["params"]["width"]["value"].as_f64().unwrap();
    assert!((width / 0.3 - 1.0).abs() < 0.25, "width {width} V");
}

/// The benchmark's torque ripple of 7.5 cycles per motor revolution (a user effect of the plant
/// file, servo's own simulator, one minute of logs) through `servo diagnose --json`:
/// "unexplained", the torque balance led by the ripple with its order in `periodic` (7.5 per
/// motor revolution, 105 per load revolution, independent of speed), and the verdict says no set
/// of catalogue effects was searched for it, as no catalogue torque locked to an angle takes
/// that order (the joint search had fitted a cogging of 7 or 8 cycles that half matched it).
#[test]
fn a_ripple_at_no_catalogue_order_is_unexplained_without_the_joint_search() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    user_effect_rig(
        dir.path(),
        "[custom.ripple]\nacts_on = \"motor_torque\"\nexpr = \"a * sin(7.5 * theta_m + 0.3)\"\n\
         description = \"a torque ripple of 7.5 cycles per motor revolution\"\n\
         [custom.ripple.params]\na = { value = 4e-4, unit = \"N m\" }\n",
    );
    let v = diagnose_rig_json(dir.path(), "5", 1, "ripple 7.5/rev");
    assert_eq!(v["status"], "unexplained", "{}", v["verdict"]);
    let torque = v["balances"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["equation"] == "torque balance")
        .unwrap_or_else(|| panic!("no torque balance: {}", v["balances"]));
    let lead = &torque["signatures"][0];
    assert_eq!(lead["kind"], "load_angle", "{lead}");
    let per_motor = lead["periodic"]["cycles_per_motor_rev"].as_f64().unwrap();
    assert!((per_motor - 7.5).abs() < 0.1, "{lead}");
    assert_eq!(lead["periodic"]["speed_independent"], true, "{lead}");
    let verdict = v["verdict"].as_str().unwrap();
    assert!(
        verdict.contains(
            "No set of catalogue effects was searched jointly: a shape periodic in angle"
        ),
        "{verdict}"
    );
    assert!(verdict.contains("none of theirs"), "{verdict}");
}

/// A viscous friction whose slope differs between the directions: 5e-4 N m s/rad more at the
/// load when turning forwards (2.5 times the base B_eq N^2): "unexplained" with the friction
/// curve's "direction slopes" shape first, and `--discover` proposes b_fwd max(w_l, 0) within
/// 25 % (load side). Steeper backwards (seed 163, found at stop 51 on a seed and a direction no
/// test had): the shape and the proposal name the backward slope, positive (both read
/// "-5.0e-4 forwards": the same model beside B_eq, the wrong friction to look for).
#[test]
fn direction_dependent_viscous_friction_is_unexplained() {
    let _machine = servo_e2e::shared();
    let fwd = |_th: f64, w_m: f64| 5e-4 * (w_m / 14.0).max(0.0) / 14.0;
    for seed in [57, 58] {
        check_friction_shape(
            "direction viscous",
            &Mechanism {
                motor_torque: &fwd,
                ..Mechanism::NONE
            },
            "direction_slopes",
            "b_fwd",
            5e-4,
            seed,
        );
    }
    let bwd = |_th: f64, w_m: f64| 5e-4 * (w_m / 14.0).min(0.0) / 14.0;
    check_friction_shape(
        "direction viscous backwards",
        &Mechanism {
            motor_torque: &bwd,
            ..Mechanism::NONE
        },
        "direction_slopes",
        "b_bwd",
        5e-4,
        163,
    );
}

#[test]
fn torque_ripple_at_a_non_harmonic_is_unexplained() {
    let _machine = servo_e2e::shared();
    // 7.5 cycles per motor revolution: no harmonic of the motor (cogging) nor the load.
    let ripple = |th_m: f64, _w: f64| 4e-4 * (7.5 * th_m + 0.3).sin();
    check_outside(
        "ripple 7.5/rev",
        &Mechanism {
            motor_torque: &ripple,
            ..Mechanism::NONE
        },
        "torque",
        "load_angle",
        &[43, 44],
    );
}

#[test]
fn current_sensor_offset_is_unexplained() {
    let _machine = servo_e2e::shared();
    check_outside(
        "current offset",
        &Mechanism {
            current_offset_a: 0.02,
            ..Mechanism::NONE
        },
        "electrical",
        "offset",
        &[45, 46],
    );
}

#[test]
fn periodic_angle_sensor_error_is_unexplained() {
    let _machine = servo_e2e::shared();
    // The load encoder reads 0.01 rad too far at twice per revolution (an eccentric disc).
    let err = |th_l: f64| 0.01 * (2.0 * th_l).sin();
    check_outside(
        "angle sensor",
        &Mechanism {
            angle_error: &err,
            ..Mechanism::NONE
        },
        "sensor",
        "load_angle",
        &[47, 48],
    );
}

/// Reference (closed loop) or input (open loop) shape of a long log.
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// Random steps (closed loop: position steps every 0.8 s; open loop: voltage steps and
    /// ramps every 0.4 s).
    Steps,
    /// Square wave (closed loop: +/- 1 rad, period 2 s; open loop: +/- 4 V, period 1 s).
    Square,
    /// Closed loop: a 0.5 rad chirp from 0.2 to 3 Hz over 10 s, repeated; open loop: a 5 V sine
    /// at 1.3 Hz.
    Chirp,
}

/// A long log of `plant` on servo's simulator with its sensors: closed loop (the PID of
/// [`pid_log`]) or open loop.
fn long_log(plant: &Plant, shape: Shape, closed: bool, seconds: f64, seed: u64) -> Record {
    let n = (seconds / DT) as usize;
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut sensors = Sensors::new(SensorConfig {
        seed: seed + 101,
        ..SensorConfig::default()
    });
    let mut rng = SplitMix64(seed ^ 0x10_0C);
    let (kp, ki, kd, tl) = (7.5244, 94.0379, 0.1505, 0.003);
    let (mut t, mut th, mut ia, mut uv, mut rv) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let (mut integ, mut d_state, mut prev_y, mut r, mut u_ol) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let tau = std::f64::consts::TAU;
    for k in 0..n {
        let tk = k as f64 * DT;
        let m = sensors.measure(sim.state());
        let u = if closed {
            r = match shape {
                Shape::Steps => {
                    if k % 800 == 0 {
                        r + (if rng.uniform() < 0.5 { -1.0 } else { 1.0 })
                            * (0.2 + 1.4 * rng.uniform())
                    } else {
                        r
                    }
                }
                Shape::Square => {
                    if (tk / 1.0).floor() as i64 % 2 == 0 {
                        1.0
                    } else {
                        -1.0
                    }
                }
                Shape::Chirp => {
                    let tc = tk % 10.0;
                    0.5 * (tau * (0.2 * tc + 0.5 * (3.0 - 0.2) / 10.0 * tc * tc)).sin()
                }
            };
            let y = m.theta_l_rad;
            let e = r - y;
            let dy = (y - prev_y) / DT;
            d_state += DT / (tl + DT) * (dy - d_state);
            prev_y = y;
            let raw = kp * e + ki * integ - kd * d_state;
            let u = raw.clamp(-10.0, 10.0);
            if raw == u {
                integ += e * DT;
            }
            u
        } else {
            u_ol = match shape {
                Shape::Steps => {
                    if k % 400 == 0 {
                        let mag = 0.8 + 7.0 * rng.uniform();
                        if rng.uniform() < 0.5 {
                            -mag
                        } else {
                            mag
                        }
                    } else {
                        u_ol
                    }
                }
                Shape::Square => {
                    if (tk / 0.5).floor() as i64 % 2 == 0 {
                        4.0
                    } else {
                        -4.0
                    }
                }
                Shape::Chirp => 5.0 * (tau * 1.3 * tk).sin(),
            };
            u_ol
        };
        t.push(tk);
        th.push(m.theta_l_rad);
        ia.push(m.i_a_a);
        uv.push(u);
        rv.push(r);
        sim.step(u);
    }
    let src = format!(
        "{shape:?} {} seed {seed}",
        if closed { "closed" } else { "open" }
    );
    record(t, th, ia, uv, closed.then_some(rv), &src)
}

/// Complete models on long logs: 10 minutes of servo's simulator, closed and open loop, five
/// seeds, diagnosed against the very plant that produced them: status "complete", nothing named.
fn check_long_complete(shape: Shape) {
    let plant = truth(&[]);
    let mut failures = Vec::new();
    // Five seeds per shape, closed loop on the odd seeds and open loop on the even ones (15
    // ten-minute logs over the three shapes; CI time in check).
    for seed in 1..=5 {
        for closed in [seed % 2 == 1] {
            let log = long_log(&plant, shape, closed, 600.0, seed);
            let tag = log.source.clone();
            let d = diagnose::diagnose(&[log], &plant, &DiagnoseOptions::default()).unwrap();
            print_ranking(&tag, &d, 2);
            for b in &d.balances {
                eprintln!(
                    "[{tag}] {} ratio {:.2}",
                    b.equation.name(),
                    b.ratio_to_noise
                );
            }
            if d.status != diagnose::Status::Complete {
                failures.push(format!("[{tag}] {:?}: {}", d.status, d.verdict));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn ten_minute_logs_of_complete_models_are_complete_steps() {
    let _machine = servo_e2e::shared();
    check_long_complete(Shape::Steps);
}

#[test]
fn ten_minute_logs_of_complete_models_are_complete_square() {
    let _machine = servo_e2e::shared();
    check_long_complete(Shape::Square);
}

#[test]
fn ten_minute_logs_of_complete_models_are_complete_chirp() {
    let _machine = servo_e2e::shared();
    check_long_complete(Shape::Chirp);
}

/// One hour of closed-loop square waves (the case, six times longer): complete.
#[test]
fn hour_long_log_of_a_complete_model_is_complete() {
    let _machine = servo_e2e::shared();
    let plant = truth(&[]);
    let log = long_log(&plant, Shape::Square, true, 3600.0, 7);
    let d = diagnose::diagnose(&[log], &plant, &DiagnoseOptions::default()).unwrap();
    print_ranking("hour", &d, 3);
    assert_eq!(d.status, diagnose::Status::Complete, "{}", d.verdict);
    assert!(d.winner().is_none());
}

/// Logs of u and angle only (no current sensor): identify estimates J_eq, B_eq and tau_sf from
/// the u-driven balance within 10 % and widens their intervals by the drive-constant tolerance;
/// diagnose names a hidden imbalance in such logs; identify, compare and diagnose run end to end
/// on a CSV without a current column.
#[test]
fn logs_without_current_are_identified_and_diagnosed() {
    let _machine = servo_e2e::shared();
    let strip = |logs: Vec<Record>| -> Vec<Record> {
        logs.into_iter()
            .map(|r| Record { i_a_a: None, ..r })
            .collect()
    };
    let plant = truth(&[]);
    let no_i = strip(logs(&plant, 51));
    let est =
        fit::identify_without_current(&no_i, &PlantParams::TABLE2, &FitOptions::default()).unwrap();
    for (key, want) in [("j_eq", 7.0e-7), ("b_eq", 1.0e-6), ("tau_sf", 0.01)] {
        let e = est.iter().find(|e| e.key == key).unwrap();
        eprintln!(
            "{key}: {:.4e} (true {want:.4e}) +/- {:.2e} -> {:.2e}",
            e.value, e.std_err, e.std_err_total
        );
        assert!(e.std_err_total >= e.std_err, "{key}: interval narrowed");
        if key != "b_eq" {
            assert!(
                (e.value / want - 1.0).abs() < 0.10,
                "{key}: {} vs {want}",
                e.value
            );
        } else {
            // B_eq is a small difference of large terms (B_eq + k_t k_e / R_eq): within 10 % of
            // the total viscous damping the u-driven balance sees, and inside its interval.
            let p = PlantParams::TABLE2;
            let total = want + p.k_t * p.k_e / p.r_eq();
            assert!((e.value - want).abs() < 0.10 * total, "b_eq {}", e.value);
        }
    }
    // A hidden imbalance is named in logs without current.
    let hidden = Effect::parse("imbalance:amplitude=0.01,phase=0.5").unwrap();
    let with_imb = strip(logs(&truth(&[hidden]), 52));
    let est =
        fit::identify_without_current(&with_imb[..1], &PlantParams::TABLE2, &FitOptions::default())
            .unwrap();
    let get = |k: &str| est.iter().find(|e| e.key == k).map(|e| e.value);
    let model = Plant::from_params(PlantParams {
        j_eq: get("j_eq"),
        b_eq: get("b_eq").map(|b| b.max(0.0)),
        tau_sf: get("tau_sf"),
        ..PlantParams::TABLE2
    })
    .unwrap();
    let d = diagnose::diagnose(&with_imb, &model, &DiagnoseOptions::default()).unwrap();
    print_ranking("no current, imbalance", &d, 3);
    let w = d
        .winner()
        .unwrap_or_else(|| panic!("nothing named: {}", d.verdict));
    assert_eq!(w.effect, EffectKind::Imbalance, "{}", d.verdict);
    assert_eq!(d.status, diagnose::Status::Missing);

    // End to end through the commands, on a CSV without a current column.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("no_current.csv");
    write_csv(&csv, &no_i[1]);
    let model = dir.path().join("model.toml");
    let (ok, out, err) = servo_e2e::servo(&[
        "identify",
        csv.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
    ]);
    assert!(ok, "identify failed: {err}");
    assert!(out.contains("no log records the armature current"), "{out}");
    assert!(out.contains("wider"), "{out}");
    let (ok, out, err) = servo_e2e::servo(&[
        "compare",
        csv.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
    ]);
    assert!(ok, "compare failed: {err}\n{out}");
    let (ok, out, err) = servo_e2e::servo(&[
        "diagnose",
        csv.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "diagnose failed: {err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["status"].is_string(), "{out}");
}

/// Three hidden effects at once (Stribeck + imbalance + delay): the loop adds all three, one at a
/// time, and their main parameters come out within 25 %. (Stribeck + backlash + delay: see
/// `three_hidden_effects_with_backlash_are_found_with_their_parameters`.)
#[test]
fn three_hidden_effects_are_found_with_their_parameters() {
    let _machine = servo_e2e::shared();
    let specs = [
        "stribeck:tau_s=0.02,omega_s=0.5",
        "imbalance:amplitude=0.01,phase=0.5",
        "delay:delay=0.003",
    ];
    let hidden: Vec<Effect> = specs.iter().map(|s| Effect::parse(s).unwrap()).collect();
    let plant = truth(&hidden);
    let logs = logs(&plant, 23);
    let model = identified(&logs);
    let (ladder, diags) =
        diagnose::diagnose_loop(&logs, &model, &DiagnoseOptions::default(), 4).unwrap();
    for d in &diags {
        eprintln!("[three] {:?}: {}", d.status, d.verdict);
        print_ranking("three", d, 3);
    }
    let added: Vec<EffectKind> = ladder.iter().filter_map(|r| r.added).collect();
    assert!(
        hidden.iter().all(|h| added.contains(&h.kind)),
        "added {added:?}"
    );
    let last = &ladder.last().unwrap().plant;
    for h in &hidden {
        for key in main_param(h.kind) {
            let got = last.effects.value(h.kind, key).unwrap();
            let want = h.get(key).unwrap();
            eprintln!("[three] {} {key}: {got} (true {want})", h.kind);
            assert!(
                (got / want - 1.0).abs() < 0.25,
                "{} {key}: fitted {got}, true {want}",
                h.kind
            );
        }
    }
}

/// Three hidden effects at once, one of them a gear play (Stribeck + backlash + delay), with the
/// default options: the loop adds all three, ends "missing" on each step until the last, and
/// their main parameters (breakaway torque, gap, delay) come out within 25 %. The play and the
/// stiction hide each other (neither passes alone: the play's impacts at reversals pollute the
/// torque balance the stiction is judged in, and without the stiction the play's simulation drop
/// is small), so they are found together by the joint search (`diagnose::backward`), each member
/// passing every check given the others. The breakaway's speed scale omega_s is printed, not
/// held to 25 %: beside a play the motion pins it loosely (0.35-1.14 rad/s for 0.5 over seeds
/// 23-29).
fn check_three_with_backlash(seed: u64) {
    let specs = [
        "stribeck:tau_s=0.02,omega_s=0.5",
        "backlash:gap=0.03",
        "delay:delay=0.003",
    ];
    let hidden: Vec<Effect> = specs.iter().map(|s| Effect::parse(s).unwrap()).collect();
    let plant = truth(&hidden);
    let logs = logs(&plant, seed);
    let model = identified(&logs);
    let (ladder, diags) =
        diagnose::diagnose_loop(&logs, &model, &DiagnoseOptions::default(), 4).unwrap();
    for d in &diags {
        eprintln!("[three-bl {seed}] {:?}: {}", d.status, d.verdict);
        print_ranking(&format!("three-bl {seed}"), d, 5);
    }
    // Effects found together are added at one rung.
    let added: Vec<EffectKind> = ladder
        .iter()
        .flat_map(|r| {
            r.added
                .into_iter()
                .chain(r.added_with)
                .chain(r.added_also.iter().copied())
        })
        .collect();
    let steps = ladder.iter().filter(|r| r.added.is_some()).count();
    let last = &ladder.last().unwrap().plant;
    let omega_s = last.effects.value(EffectKind::Stribeck, "omega_s");
    eprintln!("[three-bl {seed}] stribeck omega_s: {omega_s:?} (true 0.5, not checked)");
    let mut errs = Vec::new();
    for h in &hidden {
        for key in main_param(h.kind) {
            let got = last.effects.value(h.kind, key);
            let want = h.get(key).unwrap();
            eprintln!("[three-bl {seed}] {} {key}: {got:?} (true {want})", h.kind);
            if !got.is_some_and(|g| (g / want - 1.0).abs() < 0.25) {
                errs.push(format!("{} {key}: fitted {got:?}, true {want}", h.kind));
            }
        }
    }
    assert!(
        hidden.iter().all(|h| added.contains(&h.kind)),
        "[seed {seed}] added {added:?}; {errs:?}"
    );
    assert!(
        diags[..steps]
            .iter()
            .all(|d| d.status == diagnose::Status::Missing),
        "[seed {seed}] a step did not end \"missing\""
    );
    assert!(errs.is_empty(), "[seed {seed}] {errs:?}");
}

#[test]
fn three_hidden_effects_with_backlash_are_found_with_their_parameters() {
    let _machine = servo_e2e::shared();
    every_seed([23, 24, 25], check_three_with_backlash);
}

/// A compliant shaft between motor and load (outside the catalogue: a two-mass resonance, not a
/// gear play), in the other simulator: light damping (damping ratio ~0.05) and half the inertia
/// on each side, a resonance that the position loop excites at every step. A gear play fits it
/// well (the contact is a spring too) but is refused: the same contact without play (a linear
/// spring-damper) predicts the held-out motion better, or the play leaves the ringing in the
/// torque balance. On every case: status "unexplained", nothing named, the torque balance named
/// far above its noise floor.
///
/// Stiffnesses 0.6 and 1.2 N m/rad (modes at 21.0 and 29.8 Hz) lie inside the band the torque
/// balance's rows resolve (up to 45 Hz: 100 Hz rows after the 25 Hz filter): there the
/// resonance is named first, at the shaft's frequency within 10 %, damping ratio below 0.25,
/// with a chirp / `servo frf` experiment. Seed 51 at 1.2 N m/rad named a gear play before the
/// resonance's threshold became a stated false-alarm rate (its peak is 20 times its local
/// background). At 3 N m/rad (47.1 Hz) the mode lies above that band: the verdict must still be
/// "unexplained" with nothing named, any resonance it names must be at the shaft's frequency,
/// and otherwise it says which band it searched and names, first, a compliance fitted on the
/// simulation (the gear play's contact without play: a two-mass model) at the shaft's frequency
/// within 10 %. Any compliance reported on a case must lie within 20 % of the shaft's mode, or
/// say that it is away from the resonance the balance rings at
/// (`lead_resonance_max_gap_pct`).
#[test]
fn compliant_shaft_is_unexplained_and_not_a_gear_play() {
    let _machine = servo_e2e::shared();
    let frac = 0.5;
    let (n, j) = (PlantParams::TABLE2.n, 7.0e-7);
    // k 0.8 seed 182 (stop 51, a seed no test had): the resonance at the mode, 24.3 Hz, and an
    // overdamped compliance lead at 17.7 Hz beside it that did not say it was off.
    let cases: [(f64, u64); 8] = [
        (1.2, 49),
        (1.2, 50),
        (1.2, 51),
        (1.2, 54),
        (0.6, 52),
        (3.0, 49),
        (3.0, 53),
        (0.8, 182),
    ];
    let failures: Vec<String> = cases
        .iter()
        .filter_map(|&(k, seed)| {
            std::panic::catch_unwind(|| check_compliant_shaft(k, frac, n, j, seed))
                .err()
                .map(|e| {
                    e.downcast_ref::<String>()
                        .cloned()
                        .unwrap_or_else(|| format!("k {k} seed {seed} failed"))
                })
        })
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// One compliant-shaft case of [`compliant_shaft_is_unexplained_and_not_a_gear_play`]: stiffness
/// `k` [N m/rad] at the load, damping ratio ~0.047 on the two-body reduced inertia, `frac` of
/// J_eq `j` on the load side, gear ratio `n`.
fn check_compliant_shaft(k: f64, frac: f64, n: f64, j: f64, seed: u64) {
    let tag = format!("k {k} N m/rad seed {seed}");
    // Damping c = 6e-4 N m s/rad at 1.2 N m/rad, scaled to keep the damping ratio.
    let shaft = Mechanism {
        shaft: Some((k, 6e-4 * (k / 1.2).sqrt(), frac)),
        ..Mechanism::NONE
    };
    // The two-mass mode: k / N^2 between J_eq (1 - frac) and J_eq frac (motor side).
    let f_hz = ((k / (n * n)) * (1.0 / (j * (1.0 - frac)) + 1.0 / (j * frac))).sqrt()
        / std::f64::consts::TAU;
    let d = diagnose_other(&shaft, &format!("compliant shaft {tag}"), seed);
    assert_unexplained_nothing_named(&tag, &d);
    let torque = d
        .unexplained
        .iter()
        .find(|b| b.balance.name() == "torque")
        .unwrap_or_else(|| panic!("[{tag}] torque balance not named: {}", d.verdict));
    assert!(
        torque.ratio_to_noise > 10.0,
        "[{tag}] {}",
        torque.ratio_to_noise
    );
    assert!(d.verdict.contains("torque balance"), "{}", d.verdict);
    // The compliance fitted on the simulation, when reported: near the shaft's frequency.
    let lead_hz = d
        .neighbours
        .iter()
        .find(|n| n.kind == "compliance")
        .and_then(|n| n.params.iter().find(|p| p.0 == "frequency"))
        .map(|p| p.2);
    eprintln!("[{tag}] shaft mode {f_hz:.1} Hz, compliance lead {lead_hz:?} Hz");
    if let Some(lead) = lead_hz {
        // Within 20 %, or the lead says it is away from the resonance the balance rings at
        // (then the resonance, checked below, gives the frequency).
        let says = torque
            .signatures
            .iter()
            .any(|s| s.kind == "compliance" && s.description.contains("away from the resonance"));
        assert!(
            (lead / f_hz - 1.0).abs() < 0.2 || (says && torque.resonance.is_some()),
            "[{tag}] compliance at {lead:.1} Hz, shaft mode {f_hz:.1} Hz: {:?}",
            torque.signatures
        );
    }
    let band = torque
        .resonance_band_hz
        .unwrap_or_else(|| panic!("[{tag}] no band searched: {}", d.verdict));
    match torque.resonance.as_ref() {
        // The resonance, named first, at the shaft's frequency, lightly damped.
        Some(res) => {
            assert_eq!(
                torque.signatures.first().map(|s| s.kind),
                Some("resonance"),
                "[{tag}] {:?}",
                torque.signatures
            );
            assert!(
                (res.freq_hz / f_hz - 1.0).abs() < 0.1,
                "[{tag}] resonance at {:.1} Hz, shaft mode {f_hz:.1} Hz",
                res.freq_hz
            );
            assert!(res.damping_ratio < 0.25, "[{tag}] {res:?}");
            assert!(
                torque.experiment.contains("chirp") && torque.experiment.contains("servo frf"),
                "[{tag}] {}",
                torque.experiment
            );
        }
        // Only a mode beyond the band searched may go unnamed by the balance, and the verdict
        // says so; the motion then names the compliance (a two-mass model fitted on the
        // simulation) first, at the shaft's frequency.
        None => {
            let first = torque.signatures.first();
            assert!(
                first.is_some_and(|s| s.kind == "compliance" && s.on_simulation),
                "[{tag}] {:?}",
                torque.signatures
            );
            let lead = lead_hz.unwrap_or_else(|| panic!("[{tag}] no compliance lead"));
            assert!(
                (lead / f_hz - 1.0).abs() < 0.1,
                "[{tag}] compliance at {lead:.1} Hz, shaft mode {f_hz:.1} Hz"
            );
            assert!(
                f_hz > 0.9 * band.1,
                "[{tag}] no resonance found at {f_hz:.1} Hz inside {band:?} Hz: {}",
                d.verdict
            );
            assert!(
                d.verdict.contains("the band these rows resolve"),
                "[{tag}] {}",
                d.verdict
            );
        }
    }
    // The gear play, when it passes the statistics, is refused as a compliance, as a play the
    // motor does not cross (a shaft winds up by less than the gap), or as a play that leaves
    // the ringing.
    if let Some(b) = d
        .ranking
        .iter()
        .find(|c| c.effect == EffectKind::Backlash && !c.checks.is_empty())
    {
        let refused = b.checks.iter().any(|k| {
            !k.passed
                && (k.name == "play, not a compliance"
                    || k.name == "the motor crosses the gap"
                    || k.name == "explains the resonance"
                    || k.name == "gap > 0")
        });
        assert!(
            refused,
            "[{tag}] backlash not refused as a compliance: {:?}",
            b.checks
        );
    }
}

/// Writes `r` as a servo CSV: time, u and the load angle, and the current when it has one.
pub(crate) fn write_csv(path: &std::path::Path, r: &Record) {
    let i = r.i_a_a.as_ref();
    let mut text = String::from(if i.is_some() {
        "time_s,u_V,theta_l_rad,i_a_A\n"
    } else {
        "time_s,u_V,theta_l_rad\n"
    });
    for k in 0..r.len() {
        text.push_str(&format!(
            "{:.6},{:.6},{:.10}",
            r.time_s[k],
            r.u_v.as_ref().unwrap()[k],
            r.theta_l_rad.as_ref().unwrap()[k]
        ));
        if let Some(i) = i {
            text.push_str(&format!(",{:.6}", i[k]));
        }
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
}

/// `servo identify` on a log of u and angle only (no current column): J_eq, B_eq and tau_sf each
/// within 10 % of the truth. B_eq alone is checked (not the total damping B_eq + k_t k_e / R_eq,
/// of which it is 4 % here).
#[test]
fn identify_without_current_gets_b_eq_alone_within_10_percent() {
    let _machine = servo_e2e::shared();
    let plant = truth(&[]);
    let dir = tempfile::tempdir().unwrap();
    for seed in [53u64, 54] {
        let r = open_loop(&plant, 16.0, seed);
        let csv = dir.path().join(format!("u_angle_{seed}.csv"));
        write_csv(&csv, &Record { i_a_a: None, ..r });
        let (ok, out, err) = servo_e2e::servo(&["identify", csv.to_str().unwrap(), "--json"]);
        assert!(ok, "identify failed: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        for (key, want) in [
            ("j_eq_kg_m2", 7.0e-7),
            ("b_eq_n_m_s_rad", 1.0e-6),
            ("tau_sf_n_m", 0.01),
        ] {
            let got = v[key]["value"].as_f64().unwrap();
            eprintln!("[seed {seed}] {key}: {got:.4e} (true {want:.4e})");
            assert!(
                (got / want - 1.0).abs() < 0.10,
                "[seed {seed}] {key}: {got:.4e}, true {want:.4e}"
            );
        }
    }
}

/// A gear train stiffer than the contact stiffness the diagnosis assumes (60 N m/rad for 20): the
/// backlash is named, and its report either estimates the stiffness with the gap (both within
/// 25 %) or gives the gap as conditional on the assumed stiffness, with a range of gaps over the
/// plausible stiffnesses that contains the true gap. The same figures reach `--json`.
#[test]
fn backlash_gap_with_an_unknown_contact_stiffness() {
    let _machine = servo_e2e::shared();
    let hidden = Effect::parse("backlash:gap=0.03,stiffness=60").unwrap();
    let plant = truth(&[hidden]);
    let logs = logs(&plant, 61);
    let model = identified(&logs);
    let d = diagnose::diagnose(&logs, &model, &DiagnoseOptions::default()).unwrap();
    print_ranking("stiff gear train", &d, 2);
    let w = d
        .winner()
        .unwrap_or_else(|| panic!("nothing named: {}", d.verdict));
    assert_eq!(w.effect, EffectKind::Backlash, "{}", d.verdict);
    let c = w.conditional.as_ref().expect("the gap's stiffness study");
    eprintln!("{c:?}\n{}", w.evidence);
    assert_eq!((c.key, c.on), ("gap", "stiffness"));
    let (lo, hi) = c.range();
    match c.estimated {
        Some((k, gap)) => {
            assert!((k / 60.0 - 1.0).abs() < 0.25, "stiffness estimated {k}");
            assert!((gap / 0.03 - 1.0).abs() < 0.25, "gap estimated {gap}");
            assert!(w.evidence.contains("estimated"), "{}", w.evidence);
        }
        None => {
            assert!(
                lo <= 0.03 && 0.03 <= hi,
                "gap range {lo}-{hi} misses the true 0.03 rad"
            );
            assert!(c.rows.first().unwrap().0 <= 60.0 && 60.0 <= c.rows.last().unwrap().0);
            assert!(w.evidence.contains("conditional"), "{}", w.evidence);
        }
    }
    // The same study through `servo diagnose --json` (validated against its schema) and text.
    let dir = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (i, r) in logs.iter().enumerate() {
        let path = dir.path().join(format!("log{i}.csv"));
        write_csv(&path, r);
        paths.push(path.to_str().unwrap().to_string());
    }
    let model_file = dir.path().join("model.toml");
    let (ok, _, err) =
        servo_e2e::servo(&["identify", &paths[0], "-o", model_file.to_str().unwrap()]);
    assert!(ok, "identify failed: {err}");
    let mut args = vec![
        "diagnose",
        &paths[0],
        &paths[1],
        "--model",
        model_file.to_str().unwrap(),
    ];
    let (ok, text, err) = servo_e2e::servo(&args);
    assert!(ok, "diagnose failed: {err}");
    assert!(text.contains("ontact stiffness"), "{text}");
    args.push("--json");
    let (ok, out, err) = servo_e2e::servo(&args);
    assert!(ok, "diagnose --json failed: {err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let first = &v["ranking"][0];
    assert_eq!(first["effect"], "backlash", "{out}");
    let cond = &first["conditional"];
    assert_eq!(cond["on"], "stiffness", "{out}");
    let range: Vec<f64> = cond["range"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    eprintln!("--json conditional: {cond}");
    assert!(
        cond["estimated"].is_object() || (range[0] <= 0.03 && 0.03 <= range[1]),
        "{cond}"
    );
}

/// A cogging too weak for these logs (4.5e-5 N m, a third of the weakest one the catalogue names,
/// [`hidden_cogging_weak`]): its balance shows it (information criterion, held-out residual
/// drop) but what it explains stays below the torque balance's noise floor. The status is
/// "complete", saying so with each balance's floor, and the verdict lists cogging as "not
/// resolvable with these logs" with its fitted size, what it explains against the floor and the
/// experiment that would resolve it.
#[test]
fn cogging_below_the_noise_floor_is_complete_and_not_resolvable() {
    let _machine = servo_e2e::shared();
    let amp = 4.5e-5;
    every_seed([1, 2], |seed| {
        let tag = format!("weak cogging seed {seed}");
        let hidden =
            Effect::parse(&format!("cogging:amplitude={amp},harmonic=12,phase=0.3")).unwrap();
        let plant = truth(&[hidden]);
        let logs = logs(&plant, seed);
        let model = identified(&logs);
        let d = diagnose::diagnose(&logs, &model, &DiagnoseOptions::default()).unwrap();
        print_ranking(&tag, &d, 3);
        eprintln!("[{tag}] {:?} {:?}\n{}", d.status, d.unresolvable, d.verdict);
        assert_eq!(
            d.status,
            diagnose::Status::Complete,
            "[{tag}] {}",
            d.verdict
        );
        assert!(
            d.verdict.contains("times its floor"),
            "[{tag}] the floors are not stated: {}",
            d.verdict
        );
        let u = d
            .unresolvable
            .iter()
            .find(|u| u.effect == EffectKind::Cogging)
            .unwrap_or_else(|| panic!("[{tag}] cogging not listed: {}", d.verdict));
        let (key, _, size) = u.size.unwrap_or_else(|| panic!("[{tag}] no size: {u:?}"));
        assert_eq!(key, "amplitude");
        assert!(
            (size / amp - 1.0).abs() < 0.3,
            "[{tag}] amplitude {size}, true {amp}"
        );
        assert!(u.explained_rms < u.floor, "[{tag}] {u:?}");
        let line = format!(
            "Not resolvable with these logs: cogging ({}; amplitude = ",
            EffectKind::Cogging.description()
        );
        assert!(d.verdict.contains(&line), "[{tag}] {}", d.verdict);
        assert!(
            d.verdict
                .contains(&format!("below its noise floor {:.2e}", u.floor)),
            "[{tag}] {}",
            d.verdict
        );
    });
}

/// Writes the other simulator's logs of the benchmark's cases (`crates/servo-cli/benches/
/// diagnose_other_sim.sh`) to `$OTHER_OUT/CASE_SEED_{open,closed}.csv`: `ripple` (a torque ripple
/// of 7.5 cycles per motor revolution, 4e-4 N m), `encoder` (an eccentric load encoder, 0.01 rad
/// at twice per revolution), `offset` (a current sensor offset of 0.02 A), `shaft` (a compliant
/// shaft of 1.2 N m/rad between two halves of the inertia) and `none`, for the seeds of
/// [`bench_out_and_seeds`].
#[test]
#[ignore = "writes the other simulator's logs to $OTHER_OUT for the diagnose benchmark"]
fn write_other_simulator_logs() {
    let _machine = servo_e2e::shared();
    let (out, seeds) = bench_out_and_seeds();
    let ripple = |th_m: f64, _w: f64| 4e-4 * (7.5 * th_m + 0.3).sin();
    let eccentric = |th_l: f64| 0.01 * (2.0 * th_l).sin();
    let cases: [(&str, Mechanism); 5] = [
        (
            "ripple",
            Mechanism {
                motor_torque: &ripple,
                ..Mechanism::NONE
            },
        ),
        (
            "encoder",
            Mechanism {
                angle_error: &eccentric,
                ..Mechanism::NONE
            },
        ),
        (
            "offset",
            Mechanism {
                current_offset_a: 0.02,
                ..Mechanism::NONE
            },
        ),
        (
            "shaft",
            Mechanism {
                shaft: Some((1.2, 6e-4, 0.5)),
                ..Mechanism::NONE
            },
        ),
        ("none", Mechanism::NONE),
    ];
    for (name, m) in &cases {
        for &seed in &seeds {
            let logs = other_simulator_with(m, seed);
            for (log, part) in logs.iter().zip(["open", "closed"]) {
                write_csv(&out.join(format!("{name}_{seed}_{part}.csv")), log);
            }
        }
    }
}

/// Where the benchmark's log writers write (`$OTHER_OUT`, default /tmp/other-sim, created) and
/// for which seeds (`$OTHER_SEEDS`, whitespace-separated, default 44 45).
pub(crate) fn bench_out_and_seeds() -> (std::path::PathBuf, Vec<u64>) {
    let out = std::path::PathBuf::from(
        std::env::var("OTHER_OUT").unwrap_or_else(|_| "/tmp/other-sim".into()),
    );
    std::fs::create_dir_all(&out).unwrap();
    let seeds = std::env::var("OTHER_SEEDS")
        .unwrap_or_else(|_| "44 45".into())
        .split_whitespace()
        .map(|s| s.parse().expect("OTHER_SEEDS: whole numbers"))
        .collect();
    (out, seeds)
}
