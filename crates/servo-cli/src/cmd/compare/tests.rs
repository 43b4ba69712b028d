//! Unit tests of `servo compare`'s replay controller and plot stacking.

use super::*;
use servo_core::compare::Controller;
use servo_core::control::pid::PidConfig;

#[test]
fn replay_controller_adds_the_logged_feedforward() {
    use servo_core::control::PidGains;
    let cfg = PidConfig::new(
        PidGains {
            kp: 2.0,
            ki: 10.0,
            kd: 0.1,
            tl_s: 0.0,
        },
        1e-3,
    )
    .with_symmetric_limit(100.0);
    let ff = [0.5, -0.25];
    let mut c = ReplayController::new(&cfg, Some(&ff)).unwrap();
    // Backward Euler: I_0 = 10 * 1e-3 * 1 = 0.01; no derivative kick at the first sample.
    assert!((Controller::update(&mut c, 1.0, 0.0) - (2.01 + 0.5)).abs() < 1e-12);
    // e = 0.5: P = 1, I = 0.015, D = 0.1 * (-0.5) / 1e-3 = -50
    assert!((Controller::update(&mut c, 0.5, 0.0) - (1.015 - 50.0 - 0.25)).abs() < 1e-9);
    // Past the logged samples: no feedforward; the limit holds.
    assert_eq!(Controller::update(&mut c, 1e3, 0.0), 100.0);
}

#[test]
fn stacks_panels() {
    let a = line_chart_svg(
        &Chart::default(),
        &[Series {
            label: "a",
            x: &[0.0, 1.0],
            y: &[0.0, 1.0],
        }],
    )
    .unwrap();
    let s = stack_svg(&[a.clone(), a]);
    assert!(
        s.contains("height=\"800\"") && s.matches("<svg").count() == 3,
        "{}",
        &s[..200]
    );
}
