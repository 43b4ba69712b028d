//! Sustained loop rate over a pseudo-terminal: the virtual board (thread) paces Samples at the
//! shortest period it accepts (50 us, 20 kHz); the host answers each with SetVoltage through
//! SerialBackend. The time per iteration (sample + apply) is the achievable loop period: at or
//! above 50 us when the pty, the two threads and the machine keep up, more when they do not.
//! The link statistics (jitter, round trip, missed deadlines) of the last batch are printed.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use servo_core::sim::SensorConfig;
use servo_core::Plant;
use servo_hw::board::{BoardConfig, VirtualBoard};
use servo_hw::{Backend, SerialBackend, SerialConfig};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn loop_over_pty(period_s: f64, iters: u64) -> (Duration, String) {
    let (mut master, slave) = serialport::TTYPort::pair().expect("pty pair");
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let cfg = BoardConfig {
        sample_period_s: period_s,
        physics_substeps: 1,
        ..BoardConfig::default()
    };
    let board = std::thread::spawn(move || {
        let mut b =
            VirtualBoard::new(&Plant::nominal(), SensorConfig::default(), cfg).expect("board");
        b.serve(&mut master, &s2).expect("serve")
    });
    let mut be =
        SerialBackend::from_port(Box::new(slave), SerialConfig::default()).expect("handshake");
    let t = Instant::now();
    for _ in 0..iters {
        let s = be.sample().expect("sample");
        be.apply(2.0 * (0.5 - s.theta_l_rad)).expect("apply");
    }
    let el = t.elapsed();
    let _ = be.stop();
    let stats = be.stats().to_string();
    drop(be);
    stop.store(true, Ordering::Relaxed);
    let _ = board.join();
    (el, stats)
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("serial_loop");
    g.sample_size(10);
    g.throughput(Throughput::Elements(1));
    for period_us in [50.0, 1000.0] {
        let mut last = String::new();
        g.bench_function(
            format!("sample+apply over pty, board period {period_us} us"),
            |b| {
                b.iter_custom(|iters| {
                    let (d, s) = loop_over_pty(period_us * 1e-6, iters.max(2));
                    last = s;
                    d * (iters as u32) / (iters.max(2) as u32)
                })
            },
        );
        eprintln!("{last}");
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
