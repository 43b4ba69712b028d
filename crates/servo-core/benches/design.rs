//! Benchmark: a full `servo design` (synthesis + verification on reduced, full and discrete loops:
//! margins, poles, step simulations), with and without `--exact`; and `--meet-specs` for
//! (10 %, 0.15 s) on Table 2 over steps of 0.2..1 rad (issue 15: under 1 s).

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::control::DerivativeOn;
use servo_core::design::bode::DerivativeFilter;
use servo_core::design::controller::Discretization;
use servo_core::design::meet::{meet_specs, MeetRequest};
use servo_core::design::spec::{translate, DampingSpec, SpeedSpec};
use servo_core::design::step_range::{SpeedTarget, TimeSpecs};
use servo_core::design::verify::{design, DesignRequest};
use servo_core::design::{rad, ControllerKind, LoopSpec, PlantModel};
use servo_core::PlantParams;
use std::hint::black_box;

fn request(exact: bool) -> DesignRequest {
    let p = PlantParams::TABLE2;
    DesignRequest {
        kind: ControllerKind::Pid,
        spec: LoopSpec {
            omega_gc: 30.0,
            phase_margin: rad(60.0),
        },
        alpha: 4.0,
        filter: DerivativeFilter::Factor(5.0),
        ts_s: 1e-3,
        discretization: Discretization::Tustin,
        reduced: PlantModel::reduced(&p),
        full: Some(PlantModel::full(&p)),
        design_on_full: false,
        exact,
    }
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("design");
    g.sample_size(10);
    g.bench_function("pid_wc30_pm60_verify_all", |b| {
        b.iter(|| design(black_box(&request(false))).map(|r| r.gains.kp))
    });
    g.bench_function("pid_wc30_pm60_exact_verify_all", |b| {
        b.iter(|| design(black_box(&request(true))).map(|r| r.gains.kp))
    });
    let t = translate(DampingSpec::Overshoot(0.1), SpeedSpec::Settling5(0.15)).unwrap();
    let mut base = request(false);
    base.spec = t.spec;
    base.discretization = Discretization::BackwardEuler;
    let meet = MeetRequest {
        base,
        specs: TimeSpecs {
            overshoot_max: Some(0.1),
            speed: Some(SpeedTarget::Settling {
                band: 0.05,
                time_s: 0.15,
            }),
            step_min_rad: 0.2,
            step_max_rad: 1.0,
        },
        u_limit_v: 10.0,
        derivative_on: DerivativeOn::Error,
    };
    g.bench_function("meet_specs_10pct_0p15s_steps_0p2_1rad", |b| {
        b.iter(|| meet_specs(black_box(&meet)).map(|r| r.feasible))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
