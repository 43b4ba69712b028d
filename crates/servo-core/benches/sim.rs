//! Simulator throughput: one 1 kHz control step (plant + a PID) with every effect on, and with the
//! linear plant. Target: a 1-hour 1 kHz closed-loop run in < 3 s, i.e. < 0.83 us per step.
//!
//! `cargo bench -p servo-core --bench sim -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use servo_core::effects::Effect;
use servo_core::sim::PlantSim;
use servo_core::Plant;

fn plant(specs: &[&str]) -> Plant {
    let mut p = Plant::nominal();
    p.effects
        .insert(Effect::parse("viscous:b_eq=1e-6").unwrap());
    for s in specs {
        p.effects.insert(Effect::parse(s).unwrap());
    }
    p
}

const ALL: [&str; 9] = [
    "coulomb:tau_sf=0.005",
    "stribeck:tau_s=0.008,omega_s=0.3",
    "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.006",
    "backlash:gap=0.03",
    "cogging:amplitude=2e-4,harmonic=12,phase=0.3",
    "imbalance:amplitude=0.01,phase=1",
    "saturation:limit=8",
    "deadzone:width=0.3",
    "delay:delay=0.0025",
];

/// Closed loop: 1000 steps (1 simulated second) of a PID (backward Euler, filtered derivative)
/// tracking a 1 rad square wave of period 2 s.
fn closed_loop_second(sim: &mut PlantSim, t0: u64) -> f64 {
    let (kp, ki, kd, tl, ts) = (7.0, 86.0, 0.144, 6.67e-3, 1e-3);
    let (mut integ, mut dstate, mut prev) = (0.0, 0.0, sim.state().theta_l_rad);
    let mut acc = 0.0;
    for k in 0..1000u64 {
        let r = if ((t0 + k) / 1000) & 1 == 0 {
            1.0
        } else {
            -1.0
        };
        let y = sim.state().theta_l_rad;
        let e = r - y;
        integ += ki * ts * e;
        dstate = (tl * dstate - kd * (y - prev)) / (tl + ts);
        prev = y;
        let u = (kp * e + integ + dstate).clamp(-10.0, 10.0);
        acc += sim.step(u).theta_l_rad;
    }
    acc
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("sim_closed_loop_1s_at_1kHz");
    g.throughput(Throughput::Elements(1000));
    for (name, specs) in [("linear", &[][..]), ("all_effects", &ALL[..])] {
        let mut sim = PlantSim::new(&plant(specs), 1e-3).unwrap();
        let mut t = 0u64;
        g.bench_function(name, |b| {
            b.iter(|| {
                let r = closed_loop_second(&mut sim, t);
                t += 1000;
                std::hint::black_box(r)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
