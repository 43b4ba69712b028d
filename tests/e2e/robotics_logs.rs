//! Robotics logs in: ROS 2 bags (rosbag2, MCAP storage) and WPILib DataLogs (`.wpilog`), written
//! by the real Python packages (`rosbags`, `robotpy-wpiutil`; tests/e2e/robotics/write_logs.py)
//! from servo's simulated runs:
//!
//! * the identification experiments (`identify --ramp` on the simulator) as bags and DataLogs
//!   give the estimates of the runs' own MCAP logs within 1 %;
//! * four open-loop simulator runs as a SysIdRoutine log (quasistatic and dynamic, both ways)
//!   are read without a column map, and kS, kV, kG are SysId's terms of the simulated motor;
//! * `servo inspect` lists the topics, types, joints and rates, and the entries and tests.
//!
//! The Python interpreter with both packages is `SERVO_ROBOTICS_PYTHON` (CI's venv, .ci/run);
//! without it the tests skip with a message, unless `SERVO_REQUIRE_ROBOTICS` is set.

use servo_e2e::servo;
use std::path::{Path, PathBuf};

const WRITER: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/e2e/robotics/write_logs.py"
);

/// The Python with `rosbags` and `wpiutil`, or None (the test skips) when absent.
fn python() -> Option<PathBuf> {
    let py = std::env::var_os("SERVO_ROBOTICS_PYTHON").map(PathBuf::from);
    let ok = py.as_ref().is_some_and(|p| {
        std::process::Command::new(p)
            .args(["-c", "import rosbags.rosbag2, wpiutil.log"])
            .status()
            .is_ok_and(|s| s.success())
    });
    if ok {
        return py;
    }
    let why = "SERVO_ROBOTICS_PYTHON does not name a Python with the packages rosbags and \
               robotpy-wpiutil (pip install \"rosbags>=0.11,<0.12\" robotpy-wpiutil)";
    assert!(
        std::env::var_os("SERVO_REQUIRE_ROBOTICS").is_none(),
        "SERVO_REQUIRE_ROBOTICS is set but {why}"
    );
    eprintln!("SKIP: {why}");
    None
}

fn write_logs(py: &Path, args: &[&Path]) {
    let out = std::process::Command::new(py)
        .arg(WRITER)
        .args(args)
        .output()
        .expect("spawn python");
    assert!(
        out.status.success(),
        "write_logs.py {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn run(args: &[&str]) -> String {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed:\n{err}");
    out
}

fn json(args: &[&str]) -> serde_json::Value {
    serde_json::from_str(&run(args)).expect("JSON")
}

fn value(v: &serde_json::Value, key: &str) -> f64 {
    v[key]["value"]
        .as_f64()
        .unwrap_or_else(|| panic!("no {key} in {v}"))
}

/// servo's CSV of an MCAP log (the writer's input).
fn export_csv(mcap: &Path, dir: &Path, name: &str) -> PathBuf {
    let csv = dir.join(format!("{name}.csv"));
    run(&["export", &s(mcap), "-o", &s(&csv)]);
    csv
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

const BAG_MAP: &str = "theta_l=/joint_states/arm/position,omega_l=/joint_states/arm/velocity,u=/cmd_voltage/data:V,i_a=/current/data:A";
const WPILOG_MAP: &str =
    "u=voltage-arm:V,theta_l=position-arm:rot,omega_l=velocity-arm:rot/s,i_a=current-arm:A";

#[test]
fn bags_and_datalogs_of_a_simulated_run_identify_as_its_mcap() {
    let _machine = servo_e2e::shared();
    let Some(py) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    run(&["identify", "--ramp", "--log-dir", &s(dir), "--json"]);
    let mut mcaps = Vec::new();
    let (mut bags, mut wpilogs) = (Vec::new(), Vec::new());
    for name in ["friction", "inertia"] {
        let mcap = dir.join(format!("identify_{name}.mcap"));
        let csv = export_csv(&mcap, dir, name);
        let bag = dir.join(format!("bag_{name}"));
        let wpilog = dir.join(format!("{name}.wpilog"));
        write_logs(&py, &[&csv, &bag, &wpilog]);
        mcaps.push(s(&mcap));
        bags.push(s(&bag));
        wpilogs.push(s(&wpilog));
    }
    let reference = {
        let mut a = vec!["identify", "--json"];
        a.extend(mcaps.iter().map(String::as_str));
        json(&a)
    };
    // The bag: the folder of the first, the .mcap of the second (both are a bag).
    let bag_mcap = s(&Path::new(&bags[1]).join("bag_inertia.mcap"));
    for (logs, map) in [
        (vec![bags[0].as_str(), bag_mcap.as_str()], BAG_MAP),
        (vec![wpilogs[0].as_str(), wpilogs[1].as_str()], WPILOG_MAP),
    ] {
        let mut a = vec!["identify", "--json", "--columns", map];
        a.extend(logs.iter().copied());
        let got = json(&a);
        for key in ["j_eq_kg_m2", "b_eq_n_m_s_rad", "tau_sf_n_m"] {
            let (g, r) = (value(&got, key), value(&reference, key));
            eprintln!("{key}: {g:e} from {logs:?} vs {r:e} from the MCAP logs");
            assert!(
                ((g - r) / r).abs() < 0.01,
                "{key}: {g:e} from {logs:?} vs {r:e} from the MCAP logs"
            );
        }
        // SysId's gains are reported for a .wpilog only.
        let wpilog = map == WPILOG_MAP;
        assert_eq!(got["sysid"].is_array(), wpilog, "{}", got["sysid"]);
    }
    // Without a map, a one-joint bag is guessed (voltage and current topics by their names).
    let (ok, out, err) = servo(&["identify", &bags[0], &bag_mcap]);
    assert!(ok, "{err}");
    assert!(
        err.contains("guessed the column map --columns theta_l=/joint_states/arm/position"),
        "{err}"
    );
    assert!(out.contains("B_eq"), "{out}");

    // inspect: topics, types, joints, rates; entries, types, metadata.
    let bag = run(&["inspect", &bags[0]]);
    for want in [
        "ROS 2 bag",
        "topic /joint_states: sensor_msgs/msg/JointState",
        "joints arm",
        "topic /cmd_voltage: std_msgs/msg/Float64",
        "1000 Hz",
    ] {
        assert!(bag.contains(want), "{want} not in\n{bag}");
    }
    let log = run(&["inspect", &wpilogs[0]]);
    for want in [
        "WPILib DataLog",
        "entry voltage-arm: double",
        "metadata `Rotation`",
        "1000 Hz",
    ] {
        assert!(log.contains(want), "{want} not in\n{log}");
    }
}

#[test]
fn a_sysid_routine_log_is_read_without_a_map_with_its_gains() {
    let _machine = servo_e2e::shared();
    let Some(py) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut csvs = Vec::new();
    for (name, voltage) in [
        ("qf", "ramp:speed=1.0"),
        ("qr", "ramp:speed=-1.0"),
        ("df", "step:amp=6"),
        ("dr", "step:amp=-6"),
    ] {
        let mcap = dir.join(format!("{name}.mcap"));
        run(&[
            "run",
            "--voltage",
            voltage,
            "--duration",
            "3",
            "--log",
            &s(&mcap),
        ]);
        csvs.push(export_csv(&mcap, dir, name));
    }
    let log = dir.join("sysid.wpilog");
    let mut args: Vec<&Path> = vec![Path::new("--sysid"), &log];
    args.extend(csvs.iter().map(PathBuf::as_path));
    write_logs(&py, &args);

    let (ok, out, err) = servo(&["identify", &s(&log)]);
    assert!(ok, "{err}");
    assert!(err.contains("a SysIdRoutine log"), "{err}");
    assert!(
        err.contains("quasistatic-forward 0.000 .. 2.999 s"),
        "{err}"
    );
    for want in ["kS = ", "kV = ", "kA = ", "kG = "] {
        assert!(out.contains(want), "{want} not in\n{out}");
    }
    let v = json(&["identify", &s(&log), "--json"]);
    let g = &v["sysid"][0];
    assert_eq!(g["parts"], 4, "{g}");
    // SysId's terms of the simulated motor (the lab plant): with g = R_eq / (k_drv k_t),
    // kS = g tau_sf / N, kV = g (B_eq + k_t k_e / R_eq) N 2 pi, kA = g J_eq N 2 pi, kG = 0.
    let p = servo_core::PlantParams::LAB;
    let r_eq = p.r_eq();
    let gain = r_eq / (p.k_drv * p.k_t);
    let two_pi_n = 2.0 * std::f64::consts::PI * p.n;
    let (j, b, tau) = (
        p.j_eq.expect("the lab plant's J_eq"),
        p.b_eq.expect("the lab plant's B_eq"),
        p.tau_sf.expect("the lab plant's tau_sf"),
    );
    let truth = [
        ("k_s_v", gain * tau / p.n, 0.05),
        (
            "k_v_v_per_rot_s",
            gain * (b + p.k_t * p.k_e / r_eq) * two_pi_n,
            0.02,
        ),
        // The logged speed is a causal estimate that lags: SysId's OLS takes the lag for
        // inertia (it over-estimates kA); the bound says how much.
        ("k_a_v_per_rot_s2", gain * j * two_pi_n, 0.5),
    ];
    for (key, want, tol) in truth {
        let got = g[key].as_f64().unwrap_or_else(|| panic!("no {key} in {g}"));
        eprintln!("{key}: {got} vs the motor's {want}");
        assert!(((got - want) / want).abs() < tol, "{key}: {got} vs {want}");
    }
    let k_g = g["k_g_v"].as_f64().expect("kG");
    assert!(k_g.abs() < 0.02, "kG {k_g} V on a level axis");

    let text = run(&["inspect", &s(&log)]);
    for want in [
        "entry sysid-test-state-arm: string",
        "SysId test dynamic-reverse",
        "SysIdRoutine log: read as --columns u=voltage-arm:V,theta_l=position-arm:rot",
    ] {
        assert!(text.contains(want), "{want} not in\n{text}");
    }
}

/// A small ROS 2 bag file (MCAP, profile ros2, chunked): 40 JointState and Float64 messages.
fn bag_seed(compression: Option<mcap::Compression>) -> Vec<u8> {
    let mut cur = std::io::Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .compression(compression)
            .chunk_size(Some(512))
            .create(&mut cur)
            .unwrap();
        let js = w
            .add_schema("sensor_msgs/msg/JointState", "ros2msg", b"")
            .unwrap();
        let f64s = w
            .add_schema("std_msgs/msg/Float64", "ros2msg", b"float64 data")
            .unwrap();
        let none = Default::default();
        let a = w.add_channel(js, "/joint_states", "cdr", &none).unwrap();
        let b = w.add_channel(f64s, "/cmd_voltage", "cdr", &none).unwrap();
        for k in 0..40u32 {
            let t = 1_000_000 * u64::from(k);
            let mut m = vec![0, 1, 0, 0];
            m.extend_from_slice(&7i32.to_le_bytes());
            m.extend_from_slice(&(k * 1_000_000).to_le_bytes());
            m.extend_from_slice(&[1, 0, 0, 0, 0, 0, 0, 0]); // frame_id "" and padding
            m.extend_from_slice(&1u32.to_le_bytes());
            m.extend_from_slice(&[4, 0, 0, 0, b'a', b'r', b'm', 0]);
            m.extend_from_slice(&1u32.to_le_bytes());
            m.extend_from_slice(&(0.1 * f64::from(k)).to_le_bytes());
            m.extend_from_slice(&[0; 8]); // empty velocity and effort
            let h = |channel_id| mcap::records::MessageHeader {
                channel_id,
                sequence: k,
                log_time: t,
                publish_time: t,
            };
            w.write_to_known_channel(&h(a), &m).unwrap();
            let mut u = vec![0, 1, 0, 0];
            u.extend_from_slice(&(f64::from(k) * 0.5).to_le_bytes());
            w.write_to_known_channel(&h(b), &u).unwrap();
        }
        w.finish().unwrap();
    }
    cur.into_inner()
}

/// A small DataLog: a double, a float[] and a SysId test-state string entry.
fn wpilog_seed() -> Vec<u8> {
    let rec = |id: u8, ts: u32, p: &[u8]| {
        let mut v = vec![0x30, id, p.len() as u8];
        v.extend_from_slice(&ts.to_le_bytes());
        v.extend_from_slice(p);
        v
    };
    let start = |id: u32, name: &str, ty: &str| {
        let mut p = vec![0u8];
        p.extend_from_slice(&id.to_le_bytes());
        for s in [name, ty, ""] {
            p.extend_from_slice(&(s.len() as u32).to_le_bytes());
            p.extend_from_slice(s.as_bytes());
        }
        rec(0, 0, &p)
    };
    let mut b = b"WPILOG\x00\x01\x00\x00\x00\x00".to_vec();
    b.extend(start(1, "voltage-arm", "double"));
    b.extend(start(2, "position-arm", "float[]"));
    b.extend(start(3, "sysid-test-state-arm", "string"));
    for k in 0..30u32 {
        b.extend(rec(1, 1000 * k, &f64::from(k).to_le_bytes()));
        let mut a = (k as f32).to_le_bytes().to_vec();
        a.extend_from_slice(&(-(k as f32)).to_le_bytes());
        b.extend(rec(2, 1000 * k, &a));
        b.extend(rec(3, 1000 * k, b"dynamic-forward"));
    }
    b
}

fn fuzz<T, E: std::fmt::Display>(
    name: &str,
    seeds: &[Vec<u8>],
    reader: impl Fn(&[u8]) -> Result<T, E>,
) {
    use servo_cli::fuzz::{check_reader, FuzzConfig};
    let rep = check_reader(name, seeds, FuzzConfig::new(5000, 0x5e4f_0060), reader);
    eprintln!("{rep}");
    assert!(rep.failures.is_empty(), "{rep}");
    assert!(
        rep.refused > 0,
        "{rep}: the mutations never reached an error"
    );
}

#[test]
fn fuzz_ros_bag_reader() {
    let _machine = servo_e2e::shared();
    use servo_cli::io::ros_bag::{decode_into, Bag};
    let seeds = vec![bag_seed(None), bag_seed(Some(mcap::Compression::Zstd))];
    for s in &seeds {
        let mut bag = Bag::default();
        decode_into(&mut bag, s, "seed").unwrap();
        assert_eq!(
            bag.guess().unwrap(),
            "theta_l=/joint_states/arm/position,u=/cmd_voltage/data:V"
        );
        assert_eq!(bag.series[0].t_s.len(), 40);
    }
    fuzz("ROS 2 bag", &seeds, |b| {
        let mut bag = Bag::default();
        decode_into(&mut bag, b, "fuzz").map(|()| bag.series.len())
    });
}

#[test]
fn fuzz_wpilog_reader() {
    let _machine = servo_e2e::shared();
    use servo_cli::io::wpilog::decode;
    let seed = wpilog_seed();
    let log = decode(&seed).unwrap().unwrap();
    assert_eq!(log.series().len(), 4);
    fuzz("WPILib DataLog", &[seed], |b| {
        decode(b).map(|l| l.map(|l| (l.series().len(), l.sysid_map())))
    });
}
