use servo_core::compare::*;
use servo_core::record::Record;
use servo_core::*;

fn main() {
    let path = std::env::args().nth(1).unwrap();
    let text = std::fs::read_to_string(path).unwrap();
    let mut rec = Record::default();
    let (mut t, mut th, mut r, mut u) = (vec![], vec![], vec![], vec![]);
    for l in text.lines().skip(1) {
        let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        t.push(v[0]);
        th.push(v[1].to_radians());
        r.push(v[2].to_radians());
        u.push(v[3]);
    }
    rec.time_s = t;
    rec.theta_l_rad = Some(th.clone());
    rec.ref_rad = Some(r);
    rec.u_v = Some(u.clone());
    let args: Vec<String> = std::env::args().collect();
    let b_eq: f64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(0.0);
    let tau_sf: f64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(0.0);
    let j_eq: Option<f64> = args.get(4).map(|s| s.parse().unwrap());
    let mut p = PlantParams::TABLE2;
    p.b_eq = Some(b_eq);
    if tau_sf > 0.0 {
        p.tau_sf = Some(tau_sf);
    }
    p.j_eq = j_eq;
    let plant = Plant::from_params(p).unwrap();
    let m = Measured::from_record(&rec, 14.0, 30.0).unwrap();
    use servo_core::control::*;
    let g: Vec<f64> = std::env::var("GAINS").unwrap_or("7.5244,94.0379,0.1505,0".into()).split(",").map(|x| x.parse().unwrap()).collect();
    let mut pid = Pid::new(PidConfig::new(PidGains { kp: g[0], ki: g[1], kd: g[2], tl_s: g[3] }, 1e-3).with_symmetric_limit(10.0)).unwrap();
    let q = quantum::encoder_quantum(&th);
    println!("quantum {:?}", q);
    let rp = replay(&plant, &m, ReplayMode::ClosedLoop, Some(ClosedLoop { controller: &mut pid, u_limit_v: Some(10.0), encoder_quantum_rad: q })).unwrap();
    let rep = compare(&m, &rp, 14.0, &CompareOptions::default());
    for s in &rep.signals {
        println!("{} fit {:.1} rmse {:.4} max {:.4}", s.kind.name(), s.figures.fit_percent, s.figures.rmse, s.figures.max_abs_error);
    }
    for f in &rep.findings { println!("- {f}"); }
    for s in &rep.regimes { println!("{:?}", s); }
    for w in &rep.worst_windows { println!("  {}", report::describe_window(w, &rep, &CompareOptions::default())); }
    println!("{:?}", rep.periodic);
    if let Ok(spec) = std::env::var("DUMP") {
        let v: Vec<usize> = spec.split(':').map(|x| x.parse().unwrap()).collect();
        let pos = &rep.signals[0];
        let us = rep.signals.iter().find(|s| s.kind == SignalKind::Voltage).unwrap();
        for k in (v[0]..v[1]).step_by(v[2]) {
            println!("{:.3} ref {:7.2} meas {:7.2} model {:7.2} | u {:6.2} model_u {:6.2} | w {:7.2} wm {:7.2}", rep.time_s[k], m.ref_rad.as_ref().unwrap()[k].to_degrees(), pos.measured[k].to_degrees(), pos.model[k].to_degrees(), us.measured[k], us.model[k], rep.signals[1].measured[k], rep.signals[1].model[k]);
        }
    }
}
#[allow(dead_code)]
fn unused() {}
