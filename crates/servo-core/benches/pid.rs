//! PID update cost (target < 20 ns per step), plus the feedforward, the compensation of the
//! identified effects (issue #29) and the reference evaluation that run next to it every sample.
//!
//! `cargo bench -p servo-core --bench pid -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion};
use servo_core::control::{
    AntiWindup, DerivativeOn, Discretization, EffectSelect, Feedforward, FeedforwardConfig,
    FeedforwardParams, LoopCompensation, Pid, PidConfig, PidGains, RefSample, Reference,
};
use servo_core::effects::Effect;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let gains = PidGains {
        kp: 7.5244,
        ki: 94.0379,
        kd: 0.1505,
        tl_s: 0.0106,
    };
    let cfg = PidConfig {
        derivative_on: DerivativeOn::Measurement,
        discretization: Discretization::Tustin,
        anti_windup: AntiWindup::BackCalculation { kw: 50.0 },
        ..PidConfig::new(gains, 1e-3).with_symmetric_limit(10.0)
    };
    let mut pid = Pid::new(cfg).expect("valid config");
    let mut k = 0u32;
    c.bench_function("pid_update_tustin_backcalc", |b| {
        b.iter(|| {
            k = k.wrapping_add(1);
            // A measurement that changes every call, so saturation and both branches occur.
            let y = (k & 1023) as f64 * 1e-2;
            black_box(pid.update(black_box(5.0), black_box(y), black_box(0.1)))
        })
    });
    let mut pid = Pid::new(PidConfig::new(gains, 1e-3)).expect("valid config");
    c.bench_function("pid_update_backward_euler_unlimited", |b| {
        b.iter(|| {
            k = k.wrapping_add(1);
            let y = (k & 1023) as f64 * 1e-3;
            black_box(pid.update(black_box(1.0), black_box(y), black_box(0.0)))
        })
    });
    let ff = Feedforward::new(
        FeedforwardParams::from_params(&servo_core::PlantParams::TABLE2),
        FeedforwardConfig::FULL,
    )
    .expect("valid params");
    c.bench_function("feedforward_terms", |b| {
        b.iter(|| black_box(ff.terms(black_box(2.0), black_box(10.0))))
    });
    // One control step of `servo run --ff all` on a model with five identified effects (an
    // unbalanced load, cogging, a Stribeck hump, a direction asymmetry, a dead band): the
    // linear feedforward, the effects' torques, the friction curve and the dead-band inverse.
    let mut plant = servo_core::Plant::lab();
    for spec in [
        "imbalance:amplitude=0.01,phase=0.5",
        "cogging:amplitude=3e-4,harmonic=12,phase=0.3",
        "stribeck:tau_s=0.02,omega_s=1",
        "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.012",
        "deadzone:width=0.4",
    ] {
        plant
            .effects
            .insert(Effect::parse(spec).expect("valid effect"));
    }
    let comp = LoopCompensation::new(&plant, FeedforwardConfig::FULL, EffectSelect::All, 0.0)
        .expect("valid compensation");
    // One control step: the compensation of a sine reference sample, then the command.
    let step = |comp: &LoopCompensation, t: f64| {
        let r = RefSample {
            pos_rad: t.sin(),
            vel_rad_s: t.cos(),
            acc_rad_s2: -t.sin(),
        };
        let ff = comp.feedforward(black_box(&r), t, black_box(r.pos_rad - 1e-3), 0.9);
        comp.command_v(black_box(ff.total_v + 0.2), t, 10.0)
    };
    let linear = LoopCompensation::linear(ff);
    for (name, c_) in [
        ("compensation_step_five_effects", &comp),
        ("compensation_step_linear_only", &linear),
    ] {
        let mut t = 0.0f64;
        c.bench_function(name, |b| {
            b.iter(|| {
                t = if t > 20.0 { 0.0 } else { t + 1e-3 };
                black_box(step(c_, t))
            })
        });
    }
    for text in [
        "trap:distance=3,vmax=10,amax=100",
        "chirp:amp=0.2,f0=0.1,f1=20,duration=10,mode=log",
        "prbs:amp=0.5,bit=0.01,seed=1",
    ] {
        let r = Reference::parse(text).expect("valid reference");
        let mut t = 0.0f64;
        c.bench_function(
            &format!("reference_at_{}", text.split(':').next().unwrap_or("")),
            |b| {
                b.iter(|| {
                    t = if t > 20.0 { 0.0 } else { t + 1e-3 };
                    black_box(r.at(black_box(t)))
                })
            },
        );
    }
    c.bench_function("reference_parse", |b| {
        b.iter(|| {
            black_box(Reference::parse(black_box(
                "chirp:amp=0.2,f0=0.1,f1=20,duration=10,mode=log",
            )))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
