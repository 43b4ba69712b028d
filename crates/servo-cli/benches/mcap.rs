//! The cost of the MCAP log (issue #14: "10 minutes of closed loop with the MCAP log under
//! 0.6 s"; issue #16: reading it back).
//!
//! * `closed_loop_10min/*`: 10 minutes of 1 kHz closed-loop simulation (Table 2 plant, the
//!   handout PID, a PRBS reference) exactly as `servo run` runs it, without a log and with the
//!   MCAP log in both encodings (protobuf, the default, and JSON), chunks flushed on the wall
//!   clock with LZ4 (`servo run`'s options on the simulator). Target: with the log < 0.6 s.
//! * `mcap/*`: the write rate of 20 000 `/servo/loop` messages per encoding and compression
//!   (a chunk every 50 ms of run time, as a real-time run writes), and the read-back rate of a
//!   log (all messages, and only the signals `servo frf` reads).
//!
//! `cargo bench -p servo-cli --bench mcap` (about a minute).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use servo_cli::io::mcap_read::{read_mcap, read_mcap_signals};
use servo_cli::io::{LogEncoding, LoopMsg, McapLog, McapLogOptions, Signal};
use servo_cli::live;
use servo_core::control::program::Program;
use servo_core::control::Reference;
use servo_core::control::{PidConfig, PidGains};
use servo_hw::run::{LogSink, RunConfig};
use std::collections::BTreeMap;
use std::time::Duration;

const N: usize = 20_000;

fn msg(k: usize) -> LoopMsg {
    let t = k as f64 * 1e-3;
    LoopMsg {
        time_s: t,
        ref_rad: 1.5,
        theta_l_rad: 1.5 * (1.0 - (-t * 20.0).exp()),
        omega_l_rad_s: 30.0 * (-t * 20.0).exp(),
        err_rad: 1.5 * (-t * 20.0).exp(),
        u_v: 10.0 * (-t * 20.0).exp() + 0.3 * (t * 50.0).sin(),
        ff_v: 0.0,
        p_v: 7.0 * (-t * 20.0).exp(),
        i_v: 0.1 * t,
        d_v: -0.01 * (t * 3.0).cos(),
        i_a_a: 0.2 * (t * 7.0).sin(),
        saturated: k < 10,
        ref_omega_l_rad_s: f64::NAN,
        i_ref_a: f64::NAN,
        duty: f64::NAN,
    }
}

fn write(path: &std::path::Path, compress: bool, encoding: LogEncoding) {
    let opts = McapLogOptions {
        compress,
        encoding,
        ..McapLogOptions::default()
    };
    let mut log = McapLog::create(path, &BTreeMap::new(), opts).unwrap();
    for k in 0..N {
        log.write_loop(&msg(k)).unwrap();
    }
    log.finish().unwrap();
}

/// 10 minutes of closed loop at 1 kHz, logged to `log` when given, as `servo run` does.
fn closed_loop_10min(log: Option<(&std::path::Path, LogEncoding)>) -> usize {
    let plant = servo_core::Plant::from_params(servo_core::PlantParams::TABLE2).unwrap();
    let mut backend = servo_hw::SimBackend::new(&plant, Default::default(), 1e-3).unwrap();
    let pid = PidConfig::new(
        PidGains {
            kp: 7.0476,
            ki: 86.121,
            kd: 0.14418,
            tl_s: 1.0 / 150.0,
        },
        1e-3,
    );
    let program = Program::Position(Reference::parse("prbs:amp=0.3,bit=0.02").unwrap());
    let cfg = RunConfig {
        keep_record: false,
        ..RunConfig::closed_loop(program, pid, 600.0)
    };
    let mut mcap = log.map(|(path, encoding)| {
        McapLog::create(
            path,
            &BTreeMap::new(),
            McapLogOptions {
                flush_on_wall_clock: true,
                fast_compression: true,
                encoding,
                ..McapLogOptions::default()
            },
        )
        .unwrap()
    });
    let out = live::run_loop(
        &mut backend,
        &cfg,
        mcap.as_mut().map(|l| l as &mut dyn LogSink),
    )
    .unwrap();
    if let Some(mut l) = mcap {
        l.finish().unwrap();
    }
    out.samples
}

fn bench_closed_loop(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let mut g = c.benchmark_group("closed_loop_10min");
    g.sample_size(10);
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(8));
    g.bench_function("no_log", |b| b.iter(|| closed_loop_10min(None)));
    g.bench_function("mcap_protobuf", |b| {
        b.iter(|| closed_loop_10min(Some((&path, LogEncoding::Protobuf))))
    });
    g.bench_function("mcap_json", |b| {
        b.iter(|| closed_loop_10min(Some((&path, LogEncoding::Json))))
    });
    g.finish();
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.mcap");
    let mut g = c.benchmark_group("mcap");
    g.throughput(Throughput::Elements(N as u64));
    g.sample_size(10);
    for (name, compress, encoding) in [
        ("json_zstd", true, LogEncoding::Json),
        ("json_uncompressed", false, LogEncoding::Json),
        ("protobuf_zstd", true, LogEncoding::Protobuf),
    ] {
        g.bench_function(format!("write_{name}_20k_msgs"), |b| {
            b.iter(|| write(&path, compress, encoding))
        });
    }
    for (name, encoding) in [
        ("json", LogEncoding::Json),
        ("protobuf", LogEncoding::Protobuf),
    ] {
        write(&path, true, encoding);
        g.bench_function(format!("read_back_{name}_20k_msgs"), |b| {
            b.iter(|| read_mcap(&path).unwrap().loop_msgs.len())
        });
        g.bench_function(format!("read_frf_signals_{name}_20k_msgs"), |b| {
            b.iter(|| {
                read_mcap_signals(&path, Some(&[Signal::U, Signal::ThetaL, Signal::Ref]))
                    .unwrap()
                    .record
                    .len()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_closed_loop, bench);
criterion_main!(benches);
