//! Identification speed: a 10-minute record at 1 kHz (600 000 samples) identified by friction
//! (plateaus), inertia (phases) and the combined LS. Target: under 0.5 s in total.

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::ident::combined::{identify_combined, CombinedConfig};
use servo_core::ident::friction::{identify_friction, FrictionConfig};
use servo_core::ident::inertia::identify_inertia;
use servo_core::ident::phases::PhaseConfig;
use servo_core::ident::Experiment;
use servo_core::record::Record;
use servo_core::sim::sensors::SplitMix64;
use servo_core::PlantParams;

/// 10 minutes: repeated (staircase up, staircase down, ramps) with the torque of eq. 54 + noise.
fn record() -> Record {
    let (j, b, tsf, n, kt) = (7e-7, 1.1e-6, 9e-3, 14.0, 7.68e-3);
    let dt = 1e-3;
    let total = 600_000;
    let mut rng = SplitMix64(42);
    let mut t = Vec::with_capacity(total);
    let mut w = Vec::with_capacity(total);
    let mut ia = Vec::with_capacity(total);
    let period = 60.0; // 20 s staircase +, 20 s staircase -, 20 s ramps
    for k in 0..total {
        let tk = k as f64 * dt;
        let p = tk % period;
        let (wk, ak) = if p < 40.0 {
            let sgn = if p < 20.0 { 1.0 } else { -1.0 };
            let level = ((p % 20.0) / 2.0).floor() + 1.0;
            (sgn * 66.0 * level, 0.0)
        } else {
            let q = (p - 40.0) % 2.0;
            if q < 1.0 {
                (50.0 + 600.0 * q, 600.0)
            } else {
                (650.0 - 600.0 * (q - 1.0), -600.0)
            }
        };
        let tau = j * ak + b * wk + tsf / n * wk.signum();
        t.push(tk);
        w.push(wk + 2.0 * rng.normal());
        ia.push(tau / kt + 2e-3 * rng.normal());
    }
    Record {
        source: "bench".into(),
        time_s: t,
        omega_m_rad_s: Some(w),
        i_a_a: Some(ia),
        ..Record::default()
    }
}

fn bench(c: &mut Criterion) {
    let rec = record();
    let p = PlantParams {
        k_t: 7.68e-3,
        ..PlantParams::TABLE2
    };
    let mut g = c.benchmark_group("ident");
    g.sample_size(10);
    g.bench_function("10min_1kHz_friction+inertia+combined", |bch| {
        bch.iter(|| {
            let e = Experiment::from_record(&rec, &p).unwrap();
            let exps = std::slice::from_ref(&e);
            let f = identify_friction(exps, p.n, &FrictionConfig::default()).unwrap();
            let j = identify_inertia(exps, Some(&f), &PhaseConfig::default()).unwrap();
            let c = identify_combined(exps, p.n, &CombinedConfig::default()).unwrap();
            (f.b_eq.value, j.j_eq.value, c.j_eq.value)
        })
    });
    let e = Experiment::from_record(&rec, &p).unwrap();
    let exps = std::slice::from_ref(&e);
    let f = identify_friction(exps, p.n, &FrictionConfig::default()).unwrap();
    g.bench_function("part_prepare", |bch| {
        bch.iter(|| Experiment::from_record(&rec, &p).unwrap().time_s.len())
    });
    g.bench_function("part_friction", |bch| {
        bch.iter(|| {
            identify_friction(exps, p.n, &FrictionConfig::default())
                .unwrap()
                .b_eq
                .value
        })
    });
    g.bench_function("part_inertia", |bch| {
        bch.iter(|| {
            identify_inertia(exps, Some(&f), &PhaseConfig::default())
                .unwrap()
                .j_eq
                .value
        })
    });
    g.bench_function("part_combined", |bch| {
        bch.iter(|| {
            identify_combined(exps, p.n, &CombinedConfig::default())
                .unwrap()
                .j_eq
                .value
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
