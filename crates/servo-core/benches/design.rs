//! Benchmark: a full `servo design` (synthesis + verification on reduced, full and discrete loops:
//! margins, poles, step simulations), with and without `--exact`.

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::design::bode::DerivativeFilter;
use servo_core::design::controller::Discretization;
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
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
