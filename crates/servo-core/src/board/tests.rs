//! The board core against a scripted HAL: every transition of the state machine.

use super::*;
use crate::protocol::{fixed_text, Decoder};
use std::vec::Vec;

#[derive(Default)]
struct MockHal {
    now_us: u32,
    count: i32,
    current_raw: i16,
    u_v: f32,
    restarts: u32,
    out: Vec<u8>,
    faults: Vec<FaultCode>,
}

impl BoardHal for MockHal {
    fn now_us(&mut self) -> u32 {
        self.now_us
    }
    fn encoder_count(&mut self) -> i32 {
        self.count
    }
    fn current_raw(&mut self) -> i16 {
        self.current_raw
    }
    fn set_voltage(&mut self, u_v: f32) {
        self.u_v = u_v;
    }
    fn restart_tick(&mut self) {
        self.restarts += 1;
    }
    fn write(&mut self, bytes: &[u8]) {
        self.out.extend_from_slice(bytes);
    }
    fn on_fault(&mut self, code: FaultCode, _text: &str) {
        self.faults.push(code);
    }
}

impl MockHal {
    fn sent(&mut self) -> Vec<Message> {
        let mut d = Decoder::new();
        let mut v = Vec::new();
        d.feed(&self.out, |r| v.push(r.unwrap()));
        self.out.clear();
        v
    }
}

fn cfg() -> BoardConfig {
    BoardConfig {
        firmware: fixed_text("test"),
        sample_period_us: 1000,
        watchdog_ms: 50,
        limits: SafetyLimits::default(),
        counts_per_rev: 4096,
        current_scale_a_per_lsb: 1e-3,
    }
}

fn send(core: &mut BoardCore, hal: &mut MockHal, m: Message) {
    core.receive(hal, Frame::new(&m).as_bytes());
}

fn samples(v: &[Message]) -> Vec<Sample> {
    v.iter()
        .filter_map(|m| match m {
            Message::Sample(s) => Some(*s),
            _ => None,
        })
        .collect()
}

#[test]
fn handshake_and_version_mismatch() {
    let mut hal = MockHal::default();
    let mut core = BoardCore::new(cfg()).unwrap();
    hal.out.push(0);
    send(
        &mut core,
        &mut hal,
        Message::Hello {
            protocol_version: 1,
        },
    );
    assert_eq!(hal.sent(), [Message::HelloAck(cfg().hello_ack())]);
    send(
        &mut core,
        &mut hal,
        Message::Hello {
            protocol_version: 2,
        },
    );
    assert!(matches!(hal.sent()[..], [Message::Fault(f)] if f.code == FaultCode::Version));
}

#[test]
fn host_driven_run_samples_applies_clips_and_stops() {
    let mut hal = MockHal {
        count: 100,
        ..MockHal::default()
    };
    let mut core = BoardCore::new(cfg()).unwrap();
    send(&mut core, &mut hal, Message::Start);
    assert_eq!(hal.restarts, 1);
    let s = samples(&hal.sent());
    assert_eq!((s.len(), s[0].seq, s[0].encoder_count), (1, 0, 0));
    hal.now_us = 300;
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 0, u_v: 12.0 },
    );
    assert_eq!(
        hal.u_v, 10.0,
        "clipped to the voltage limit, applied at once"
    );
    hal.now_us = 1000;
    hal.count = 141;
    core.tick(&mut hal);
    let s = samples(&hal.sent())[0];
    assert_eq!((s.seq, s.time_us, s.encoder_count), (1, 1000, 41));
    assert_eq!(s.rtt_us, 300);
    assert_eq!(s.flags, flags::VOLTAGE_CLIPPED);
    assert_eq!(s.u_applied_v, 10.0);
    // No answer to sample 1: sample 2 says so and the voltage is held.
    hal.now_us = 2000;
    core.tick(&mut hal);
    let s = samples(&hal.sent())[0];
    assert_eq!(s.flags & flags::MISSED_DEADLINE, flags::MISSED_DEADLINE);
    assert_eq!(s.rtt_us, 0xFFFF);
    assert_eq!(hal.u_v, 10.0);
    // An old command is ignored.
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 2, u_v: 1.0 },
    );
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 1, u_v: 5.0 },
    );
    assert_eq!(hal.u_v, 1.0);
    send(&mut core, &mut hal, Message::Stop);
    assert_eq!(hal.u_v, 0.0);
    assert_eq!(hal.sent(), [Message::Stopped]);
    core.tick(&mut hal);
    assert!(hal.sent().is_empty(), "no samples after Stop");
    assert_eq!(core.stats().missed_deadlines, 1);
}

#[test]
fn watchdog_trips_to_zero_volts() {
    let mut hal = MockHal::default();
    let mut core = BoardCore::new(cfg()).unwrap();
    send(&mut core, &mut hal, Message::Start);
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 0, u_v: 3.0 },
    );
    for k in 1..=50 {
        hal.now_us = k * 1000;
        core.tick(&mut hal);
    }
    assert!(
        core.is_running(),
        "50 ms without command is still within the watchdog"
    );
    hal.now_us = 51_000;
    core.tick(&mut hal);
    assert!(!core.is_running());
    assert_eq!(hal.u_v, 0.0);
    assert_eq!(hal.faults, [FaultCode::Watchdog]);
    let v = hal.sent();
    assert!(
        matches!(v.last(), Some(Message::Fault(f)) if f.text_str() == "watchdog: no command in 50 ms")
    );
    // The next Start begins cleanly.
    send(&mut core, &mut hal, Message::Start);
    assert!(core.is_running());
    assert_eq!(samples(&hal.sent())[0].seq, 0);
}

#[test]
fn over_current_and_position_limits_trip() {
    let mut hal = MockHal::default();
    let mut core = BoardCore::new(cfg()).unwrap();
    send(&mut core, &mut hal, Message::Start);
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 0, u_v: 3.0 },
    );
    hal.current_raw = 2600; // 2.6 A > 2.5 A
    hal.now_us = 1000;
    core.tick(&mut hal);
    assert_eq!((core.is_running(), hal.u_v), (false, 0.0));
    assert_eq!(hal.faults, [FaultCode::OverCurrent]);
    hal.current_raw = 0;
    hal.count = 1000;
    send(&mut core, &mut hal, Message::Start);
    hal.count = 1000 + 3 * 4096; // 3 rev from Start > 2 rev
    hal.now_us = 2000;
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 0, u_v: 3.0 },
    );
    core.tick(&mut hal);
    assert_eq!(
        hal.faults,
        [FaultCode::OverCurrent, FaultCode::PositionLimit]
    );
    assert_eq!(hal.u_v, 0.0);
}

#[test]
fn bad_commands_are_faults() {
    let mut hal = MockHal::default();
    let mut core = BoardCore::new(cfg()).unwrap();
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 0, u_v: 1.0 },
    );
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 1, u_v: 1.0 },
    );
    assert_eq!(
        hal.faults,
        [FaultCode::BadCommand, FaultCode::BadCommand],
        "every SetVoltage before Start is answered"
    );
    assert_eq!(hal.u_v, 0.0);
    hal.faults.clear();
    send(&mut core, &mut hal, Message::Start);
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage {
            seq: 0,
            u_v: f32::NAN,
        },
    );
    assert!(!core.is_running());
    assert_eq!(hal.faults.len(), 1);
    send(
        &mut core,
        &mut hal,
        Message::LoopReference {
            seq: 0,
            ref_rad: 1.0,
        },
    );
    assert!(!core.is_running(), "no gains: no on-board loop");
}

#[test]
fn onboard_loop_runs_the_pid_each_tick() {
    let mut hal = MockHal::default();
    let mut core = BoardCore::new(cfg()).unwrap();
    let g = LoopGains {
        kp: 2.0,
        ki: 0.0,
        kd: 0.0,
        tau_f_s: 0.0,
    };
    send(&mut core, &mut hal, Message::LoopGains(g));
    assert_eq!(hal.sent(), [Message::GainsAck]);
    send(
        &mut core,
        &mut hal,
        Message::LoopReference {
            seq: 0,
            ref_rad: 1.0,
        },
    );
    assert!(core.is_running());
    assert!(
        (hal.u_v - 2.0).abs() < 1e-6,
        "u = kp e at once: {}",
        hal.u_v
    );
    assert_eq!(samples(&hal.sent())[0].seq, 0);
    hal.count = 2048; // pi rad: e = 1 - pi
    hal.now_us = 1000;
    core.tick(&mut hal);
    let s = samples(&hal.sent())[0];
    assert_eq!(s.flags & flags::ONBOARD_LOOP, flags::ONBOARD_LOOP);
    assert_eq!(s.flags & flags::MISSED_DEADLINE, 0);
    let want = 2.0 * (1.0 - core::f32::consts::PI);
    assert!((hal.u_v - want).abs() < 1e-4, "{} vs {want}", hal.u_v);
    // A SetVoltage ends on-board mode.
    send(
        &mut core,
        &mut hal,
        Message::SetVoltage { seq: 1, u_v: 0.5 },
    );
    hal.now_us = 2000;
    core.tick(&mut hal);
    assert_eq!(samples(&hal.sent())[0].flags & flags::ONBOARD_LOOP, 0);
    assert_eq!(hal.u_v, 0.5);
}

#[test]
fn invalid_configs_are_rejected() {
    let bad = [
        BoardConfig {
            sample_period_us: 10,
            ..cfg()
        },
        BoardConfig {
            watchdog_ms: 1,
            ..cfg()
        },
        BoardConfig {
            counts_per_rev: 0,
            ..cfg()
        },
        BoardConfig {
            current_scale_a_per_lsb: f32::NAN,
            ..cfg()
        },
    ];
    for c in bad {
        assert!(BoardCore::new(c).is_err(), "{c:?}");
    }
}

/// Every out-of-order command the protocol chapter lists gets its answer, in every idle state
/// (after reset, after Hello, after Stop, after a fault), and the late answers to a run a fault
/// ended are not mistaken for out-of-order commands.
#[test]
fn out_of_order_commands_get_the_promised_fault() {
    fn bad_command(v: &[Message]) -> bool {
        matches!(v, [Message::Fault(f)] if f.code == FaultCode::BadCommand)
    }
    let mut hal = MockHal::default();
    let mut core = BoardCore::new(cfg()).unwrap();
    // After reset, after Hello, after a Stop that ended a run, after a Stop while idle.
    let sv = |seq| Message::SetVoltage { seq, u_v: 2.0 };
    for before in [
        None,
        Some(Message::Hello {
            protocol_version: PROTOCOL_VERSION,
        }),
        Some(Message::Start),
        Some(Message::Stop),
    ] {
        if let Some(m) = before {
            send(&mut core, &mut hal, m);
            if m == Message::Start {
                send(&mut core, &mut hal, Message::Stop);
            }
            hal.sent();
        }
        for seq in [0, 1, 7] {
            send(&mut core, &mut hal, sv(seq));
            let v = hal.sent();
            assert!(
                bad_command(&v),
                "after {before:?}, SetVoltage({seq}): {v:?}"
            );
            assert_eq!(hal.u_v, 0.0);
            assert!(!core.is_running());
        }
    }
    // LoopReference without gains, invalid gains: BadCommand each time, nothing starts.
    for _ in 0..2 {
        send(
            &mut core,
            &mut hal,
            Message::LoopReference {
                seq: 0,
                ref_rad: 1.0,
            },
        );
        assert!(bad_command(&hal.sent()));
        send(
            &mut core,
            &mut hal,
            Message::LoopGains(LoopGains {
                kp: f32::NAN,
                ki: 0.0,
                kd: 0.0,
                tau_f_s: 0.001,
            }),
        );
        assert!(bad_command(&hal.sent()));
        assert!(!core.is_running());
    }
    // A run a fault ends (the watchdog at tick 60, after sample 59): the host's answers in
    // flight (seq up to 60, its SetVoltage(0 V) before Stop) are silent; a command from beyond that run is
    // out of order; after the host's Stop, every SetVoltage is out of order again.
    send(&mut core, &mut hal, Message::Start);
    send(&mut core, &mut hal, sv(0));
    for k in 1..=60u32 {
        hal.now_us = k * 1000;
        core.tick(&mut hal);
        if k < 10 {
            send(&mut core, &mut hal, sv(k));
        }
    }
    assert!(!core.is_running());
    assert!(matches!(hal.sent().last(), Some(Message::Fault(f)) if f.code == FaultCode::Watchdog));
    for seq in [10, 59, 60] {
        send(&mut core, &mut hal, sv(seq));
        assert!(hal.sent().is_empty(), "late answer {seq} after the fault");
    }
    for seq in [61, 500] {
        send(&mut core, &mut hal, sv(seq));
        assert!(
            bad_command(&hal.sent()),
            "SetVoltage({seq}) after the fault"
        );
    }
    send(&mut core, &mut hal, Message::Stop);
    assert_eq!(hal.sent(), [Message::Stopped]);
    send(&mut core, &mut hal, sv(5));
    assert!(bad_command(&hal.sent()));
    assert_eq!(hal.u_v, 0.0);
    // Stop while idle: Stopped; Start while running begins a new run at sample 0.
    send(&mut core, &mut hal, Message::Stop);
    assert_eq!(hal.sent(), [Message::Stopped]);
    send(&mut core, &mut hal, Message::Start);
    send(&mut core, &mut hal, sv(0));
    hal.now_us += 1000;
    core.tick(&mut hal);
    send(&mut core, &mut hal, Message::Start);
    let s = samples(&hal.sent());
    assert_eq!(s.last().map(|s| s.seq), Some(0));
    assert!(core.is_running());
}
