//! Benchmark: the closed-loop frequency-response estimate (T, u/r, joint input-output plant) and
//! the achieved margins of 10 minutes of data at 1 kHz (600 000 samples; target < 0.5 s).

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::design::{Complex, PidGains};
use servo_core::frf::{achieved_margins, closed_loop, ClosedLoopRecord, WelchOptions};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    // A multisine-like reference and a noisy first-order response: the estimator's cost does not
    // depend on the plant, only on the number of samples and segments.
    let n = 600_000;
    let r: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * 1e-3;
            (1..40)
                .map(|h| (std::f64::consts::TAU * 0.1 * h as f64 * t + h as f64).sin())
                .sum::<f64>()
                * 0.01
        })
        .collect();
    let mut y = vec![0.0; n];
    for k in 1..n {
        y[k] = 0.97 * y[k - 1] + 0.03 * r[k - 1] + 1e-4 * ((k * 7919 % 1000) as f64 / 1000.0 - 0.5);
    }
    let u: Vec<f64> = r.iter().zip(&y).map(|(a, b)| 7.0 * (a - b)).collect();
    let g = PidGains {
        kp: 7.0,
        ki: 86.0,
        kd: 0.14,
        tl_s: 0.0067,
    };
    let mut grp = c.benchmark_group("frf");
    grp.sample_size(10);
    grp.bench_function("closed_loop_10min_1khz", |b| {
        b.iter(|| {
            let est = closed_loop(
                &[ClosedLoopRecord {
                    ref_rad: &r,
                    u_v: &u,
                    theta_l_rad: &y,
                }],
                1e-3,
                &WelchOptions::default(),
            )
            .map(|e| {
                let l = e.plant.times(|w| g.response(w) * Complex::new(1.0, 0.0));
                achieved_margins(&l, 0.8, -180.0)
                    .phase_margin_deg
                    .map(|p| p.value)
            });
            black_box(est)
        })
    });
    grp.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
