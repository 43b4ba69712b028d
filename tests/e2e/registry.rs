//! The effect registry end to end: a test-only effect, defined here through the same trait as
//! the catalogue and registered at run time, is simulated, fitted (`compare --add`'s machinery)
//! and named by the diagnosis; and the README's effect table is the registry's.

use servo_core::diagnose::{self, DiagnoseOptions};
use servo_core::effects::{
    self, spec, ActsOn, CoefSign, EffectKind, EffectModel, GridContext, ParamSpec, Regime,
    RegistryError, Sample, Signals,
};
use servo_core::fit::{self, search, EffectToFit, FitOptions};
use servo_core::record::Record;
use servo_core::sim::excitation::{simulate_open_loop, RandomSteps};
use servo_core::sim::SensorConfig;
use servo_core::{Effect, Plant, PlantParams};
use std::sync::OnceLock;

/// A torsional spring at the load, k (theta_l - theta0): a cable or a return spring. Linear in
/// k (least squares), theta0 searched on a grid.
struct TestSpring;

const PARAMS: [ParamSpec; 2] = [
    spec("k", "N m/rad", "spring rate at the load", None, 0.0, false),
    spec(
        "theta0",
        "rad",
        "rest angle of the load",
        Some(0.0),
        f64::NEG_INFINITY,
        true,
    ),
];

impl EffectModel for TestSpring {
    fn name(&self) -> &str {
        "test_spring"
    }
    fn description(&self) -> &str {
        "a torsional spring at the load, k (theta_l - theta0)"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::LoadTorque
    }
    fn torque_nm(&self, v: &[f64], s: &Signals) -> f64 {
        v[0] * (s.theta_l_rad - v[1])
    }
    fn depends_on_angle_only(&self) -> bool {
        true
    }
    fn search_grid(&self, _key: &str, _ctx: &GridContext) -> Option<Vec<f64>> {
        Some(search::linspace(-1.0, 1.0, 21))
    }
    fn linear_coefs(&self) -> usize {
        1
    }
    fn coef_sign(&self, _j: usize) -> CoefSign {
        CoefSign::NonNegative
    }
    fn regressor(&self, v: &[f64], _j: usize, x: &Sample) -> f64 {
        (x.theta_m_rad / x.n - v[1]) / x.n
    }
    fn coef_from_values(&self, v: &[f64], _j: usize, _tau_sf: f64) -> f64 {
        v[0]
    }
    fn values_from_coefs(&self, c: &[f64], v: &mut [f64], _tau_sf: f64) {
        v[0] = c.first().copied().unwrap_or(0.0);
    }
    fn std_err(&self, key: &str, se: &[f64], _coefs: &[f64]) -> Option<f64> {
        (key == "k").then(|| se.first().copied()).flatten()
    }
    fn experiment(&self) -> &str {
        "hold the load at several angles and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Standstill]
    }
    fn compared(&self) -> &[&'static str] {
        &["k"]
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, v: &[f64], _j: usize, x: &Sample) -> f64 {
        x.theta_m_rad / x.n - v[1]
    }
}

fn spring() -> EffectKind {
    static KIND: OnceLock<EffectKind> = OnceLock::new();
    *KIND.get_or_init(|| effects::register(Box::new(TestSpring)).unwrap())
}

const DT: f64 = 1e-3;

fn truth(hidden: Effect) -> Plant {
    let mut p = Plant::from_params(PlantParams {
        j_eq: Some(7.0e-7),
        b_eq: Some(1.0e-6),
        tau_sf: Some(0.01),
        ..PlantParams::TABLE2
    })
    .unwrap();
    p.effects.insert(hidden);
    p
}

/// Voltage steps of random size and sign (an identification-like log), current logged.
fn open_loop(plant: &Plant, seconds: f64, seed: u64) -> Record {
    let u = RandomSteps::new(seed ^ 0x5EED).voltages((seconds / DT) as usize, DT);
    let sensors = SensorConfig {
        seed,
        ..SensorConfig::default()
    };
    simulate_open_loop(plant, sensors, DT, &u, "open-loop").unwrap()
}

#[test]
fn run_time_effect_is_registered_parsed_and_bounded() {
    let _machine = servo_e2e::shared();
    let k = spring();
    assert!(!k.is_catalogue());
    assert_eq!(EffectKind::from_name("test_spring"), Some(k));
    let e = Effect::parse("test_spring:k=0.003,theta0=0.2").unwrap();
    assert_eq!(e.kind, k);
    assert_eq!(e.get("k"), Some(0.003));
    assert_eq!(Effect::parse(&e.to_string()).unwrap(), e);
    // Registering again keeps its kind; catalogue names and bad names are refused.
    assert_eq!(effects::register(Box::new(TestSpring)).unwrap(), k);
    struct Named(&'static str);
    impl EffectModel for Named {
        fn name(&self) -> &str {
            self.0
        }
        fn description(&self) -> &str {
            "test"
        }
        fn params(&self) -> &[ParamSpec] {
            &PARAMS
        }
        fn acts_on(&self) -> ActsOn {
            ActsOn::MotorTorque
        }
    }
    assert!(matches!(
        effects::register(Box::new(Named("coulomb"))),
        Err(RegistryError::CatalogueName(_))
    ));
    assert!(matches!(
        effects::register(Box::new(Named("Bad Name"))),
        Err(RegistryError::BadName(_))
    ));
    // Its slot exists in every effect set (sized from the registry).
    let mut set = servo_core::effects::Effects::NONE;
    set.insert(e);
    assert_eq!(set.value(k, "theta0"), Some(0.2));
    assert!(effects::ParamsSummary.to_string().contains("test_spring"));
}

/// The test-only effect hidden in a simulated motor: `compare --add` recovers its spring rate
/// and lowers the residual, and the diagnosis (catalogue + the run-time effect as candidates)
/// names it.
#[test]
fn run_time_effect_is_simulated_fitted_and_diagnosed() {
    let _machine = servo_e2e::shared();
    let k = spring();
    let hidden = Effect::new(k, &[0.003, 0.3]).unwrap();
    let plant = truth(hidden);
    let logs = vec![open_loop(&plant, 14.0, 5)];
    // The simulator sees it: the same excitation without it ends elsewhere.
    let without = open_loop(&truth(Effect::new(k, &[0.0, 0.3]).unwrap()), 14.0, 5);
    let (a, b) = (
        logs[0].theta_l_rad.as_ref().unwrap(),
        without.theta_l_rad.as_ref().unwrap(),
    );
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(
        diff > 0.1,
        "the spring changes the motion by {diff} rad only"
    );

    let start = Plant::from_params(PlantParams {
        tau_sf: Some(0.005),
        ..PlantParams::TABLE2
    })
    .unwrap();
    let model = fit::fit_model(&logs, &start, &[], &FitOptions::default())
        .unwrap()
        .plant;
    let r = fit::fit_model(
        &logs,
        &model,
        &[EffectToFit::all(k)],
        &FitOptions::default(),
    )
    .unwrap();
    let got = r.plant.effects.value(k, "k").unwrap();
    let theta0 = r.plant.effects.value(k, "theta0").unwrap();
    eprintln!("fitted k = {got} N m/rad, theta0 = {theta0} rad");
    assert!(
        (got / 0.003 - 1.0).abs() < 0.15,
        "k fitted {got}, true 0.003"
    );
    assert!(
        (theta0 - 0.3).abs() < 0.1,
        "theta0 fitted {theta0}, true 0.3"
    );
    assert!(r.equations[0].rms_after < 0.8 * r.equations[0].rms_before);

    let opts = DiagnoseOptions {
        extra_candidates: vec![k],
        ..DiagnoseOptions::default()
    };
    let d = diagnose::diagnose(&logs, &model, &opts).unwrap();
    for c in d.ranking.iter().take(4) {
        eprintln!(
            "{} significant {} error -{:.1} % : {}",
            c.effect, c.significant, c.error_reduction_pct, c.evidence
        );
    }
    let w = d
        .winner()
        .unwrap_or_else(|| panic!("nothing significant: {}", d.verdict));
    assert_eq!(w.effect, k, "wrong winner: {}", d.verdict);
    assert!(d.verdict.contains("test_spring"), "{}", d.verdict);
}

/// The guide's effect table (docs/guide/src/effects.md, once README.md's) is the registry's
/// ([`effects::CatalogueTable`]).
#[test]
fn guide_table_is_the_registry() {
    let _machine = servo_e2e::shared();
    let readme = include_str!("../../docs/guide/src/effects.md");
    let want = effects::CatalogueTable.to_string();
    let catalogue_only: String = want
        .lines()
        .filter(|l| !l.contains("`test_spring`"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(
        readme.contains(&catalogue_only),
        "docs/guide/src/effects.md's effect table differs from the registry; it should read:\n{catalogue_only}"
    );
}
