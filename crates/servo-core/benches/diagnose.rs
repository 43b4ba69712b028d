//! Diagnosis on 10 minutes of 1 kHz data (open-loop steps, current logged) with every candidate.

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::diagnose::{self, DiagnoseOptions};
use servo_core::effects::Effect;
use servo_core::record::Record;
use servo_core::sim::excitation::{simulate_open_loop, RandomSteps};
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};

/// Random voltage steps of 0.8 to 6.8 V held 0.4 s, current logged.
fn log(plant: &Plant, seconds: f64) -> Record {
    let dt = 1e-3;
    let steps = RandomSteps {
        span_v: 6.0,
        ..RandomSteps::new(9)
    };
    let u = steps.voltages((seconds / dt) as usize, dt);
    simulate_open_loop(plant, SensorConfig::default(), dt, &u, "bench").expect("sim")
}

fn bench(c: &mut Criterion) {
    let params = PlantParams {
        j_eq: Some(7.0e-7),
        b_eq: Some(1.0e-6),
        tau_sf: Some(0.01),
        ..PlantParams::TABLE2
    };
    let mut truth = Plant::from_params(params).expect("plant");
    truth
        .effects
        .insert(Effect::parse("cogging:amplitude=3e-4,harmonic=12").expect("effect"));
    let rec = log(&truth, 600.0);
    let model = Plant::from_params(params).expect("plant");
    let opts = DiagnoseOptions::default();
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    g.bench_function("10 min at 1 kHz, all candidates", |b| {
        b.iter(|| diagnose::diagnose(std::slice::from_ref(&rec), &model, &opts).expect("diagnose"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
