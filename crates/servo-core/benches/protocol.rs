//! Codec throughput: frames encoded and decoded per second (Sample, the message of every period).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use servo_core::protocol::{encode_frame, Decoder, Message, Sample, MAX_FRAME};
use std::hint::black_box;

fn sample(i: u32) -> Message {
    Message::Sample(Sample {
        seq: i,
        time_us: i.wrapping_mul(1000),
        encoder_count: (i as i32).wrapping_mul(3) - 5000,
        current_raw: (i % 2000) as i16 - 1000,
        u_applied_v: (i % 200) as f32 * 0.05 - 5.0,
        rtt_us: 80,
        flags: 0,
    })
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("protocol");
    g.throughput(Throughput::Elements(1));
    g.bench_function("encode Sample frame", |b| {
        let mut buf = [0u8; MAX_FRAME];
        let mut i = 0u32;
        b.iter(|| {
            i = i.wrapping_add(1);
            black_box(encode_frame(&sample(i), &mut buf))
        })
    });
    // 1000 frames back to back, decoded byte by byte.
    let mut stream = Vec::new();
    for i in 0..1000 {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_frame(&sample(i), &mut buf).unwrap_or(0);
        stream.extend_from_slice(&buf[..n]);
    }
    g.throughput(Throughput::Elements(1000));
    g.bench_function("decode 1000 Sample frames", |b| {
        let mut d = Decoder::new();
        b.iter(|| {
            let mut n = 0u32;
            d.feed(black_box(&stream), |r| n += r.is_ok() as u32);
            assert_eq!(n, 1000);
            n
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
