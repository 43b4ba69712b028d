use servo_core::effects::Effect;
use servo_core::sim::PlantSim;
use servo_core::Plant;
fn cpu_s() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap();
    let rest = &s[s.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) / 100.0
}
fn main() {
    let sets: &[&[&str]] = &[
        &[],
        &["coulomb:tau_sf=0.005"],
        &["stribeck:tau_s=0.008,omega_s=0.3", "coulomb:tau_sf=0.005"],
        &["backlash:gap=0.03"],
        &["cogging:amplitude=2e-4,harmonic=12,phase=0.3"],
        &["imbalance:amplitude=0.01,phase=1"],
        &["delay:delay=0.0025"],
        &[
            "coulomb:tau_sf=0.005",
            "stribeck:tau_s=0.008,omega_s=0.3",
            "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.006",
            "backlash:gap=0.03",
            "cogging:amplitude=2e-4,harmonic=12,phase=0.3",
            "imbalance:amplitude=0.01,phase=1",
            "saturation:limit=8",
            "deadzone:width=0.3",
            "delay:delay=0.0025",
        ],
    ];
    for specs in sets {
        let mut p = Plant::nominal();
        p.effects
            .insert(Effect::parse("viscous:b_eq=1e-6").unwrap());
        for s in specs.iter() {
            p.effects.insert(Effect::parse(s).unwrap());
        }
        let mut sim = PlantSim::new(&p, 1e-3).unwrap();
        let (kp, ki, kd, tl, ts) = (7.0, 86.0, 0.144, 6.67e-3, 1e-3);
        let (mut integ, mut dstate, mut prev) = (0.0, 0.0, 0.0);
        let n = 1_000_000u64;
        let t = cpu_s();
        let mut stuck = 0;
        for k in 0..n {
            let r = if (k / 1000) % 2 == 0 { 1.0 } else { -1.0 };
            let y = sim.state().theta_l_rad;
            let e = r - y;
            integ += ki * ts * e;
            dstate = (tl * dstate - kd * (y - prev)) / (tl + ts);
            prev = y;
            let u: f64 = (kp * e + integ + dstate).clamp(-10.0, 10.0);
            if sim.step(u).stuck {
                stuck += 1;
            }
        }
        let el = cpu_s() - t;
        println!(
            "{:>8.1} ns/step stuck {:.2} {:?}",
            el / n as f64 * 1e9,
            stuck as f64 / n as f64,
            specs
        );
    }
}
