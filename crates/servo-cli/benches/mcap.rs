//! MCAP write rate of the `/servo/loop` log (messages/s), as `servo run` writes it: JSON encode,
//! zstd chunk, a chunk flush every 50 ms of run time (every 50 messages at 1 kHz).
//! Also the read-back rate.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use servo_cli::io::mcap_read::read_mcap;
use servo_cli::io::{LoopMsg, McapLog, McapLogOptions};
use std::collections::BTreeMap;

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
    }
}

fn write(path: &std::path::Path, compress: bool) {
    let opts = McapLogOptions {
        compress,
        ..McapLogOptions::default()
    };
    let mut log = McapLog::create(path, &BTreeMap::new(), opts).unwrap();
    for k in 0..N {
        log.write_loop(&msg(k)).unwrap();
    }
    log.finish().unwrap();
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.mcap");
    let mut g = c.benchmark_group("mcap");
    g.throughput(Throughput::Elements(N as u64));
    g.sample_size(10);
    g.bench_function("write_loop_zstd_20k_msgs", |b| {
        b.iter(|| write(&path, true))
    });
    g.bench_function("write_loop_uncompressed_20k_msgs", |b| {
        b.iter(|| write(&path, false))
    });
    write(&path, true);
    g.bench_function("read_back_20k_msgs", |b| {
        b.iter(|| read_mcap(&path).unwrap().loop_msgs.len())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
