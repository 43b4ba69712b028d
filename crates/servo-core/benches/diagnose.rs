//! Diagnosis on 10 minutes of 1 kHz data (open-loop steps, current logged) with every candidate.

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::diagnose::{self, DiagnoseOptions};
use servo_core::effects::Effect;
use servo_core::record::Record;
use servo_core::sim::sensors::SplitMix64;
use servo_core::sim::{PlantSim, SensorConfig, Sensors};
use servo_core::{Plant, PlantParams};

fn log(plant: &Plant, seconds: f64) -> Record {
    let dt = 1e-3;
    let mut sim = PlantSim::new(plant, dt).expect("sim");
    let mut sensors = Sensors::new(SensorConfig::default());
    let mut rng = SplitMix64(9);
    let n = (seconds / dt) as usize;
    let (mut t, mut th, mut ia, mut uv) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let mut u = 0.0;
    for k in 0..n {
        if k % 400 == 0 {
            let mag = 0.8 + 6.0 * rng.uniform();
            u = if rng.uniform() < 0.5 { -mag } else { mag };
        }
        let m = sensors.measure(sim.state());
        t.push(k as f64 * dt);
        th.push(m.theta_l_rad);
        ia.push(m.i_a_a);
        uv.push(u);
        sim.step(u);
    }
    Record {
        source: "bench".into(),
        time_s: t,
        theta_l_rad: Some(th),
        i_a_a: Some(ia),
        u_v: Some(uv),
        ..Record::default()
    }
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
