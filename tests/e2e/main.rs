//! The end-to-end tests, one module per area, in ONE integration-test binary (as ripgrep does),
//! so a change relinks once. Shared helpers live in the `servo_e2e` library (src/lib.rs)
//! and, for those that build logs with the core's types, in `util`.
//! Run one area with `cargo test --release --test e2e diagnose::`.

mod bounded;
mod calibration;
mod compare;
mod compensation;
mod control_loop;
mod custom;
mod demo;
mod design;
mod diagnose;
mod drives;
mod frf;
mod fuzz;
mod gravity;
mod guide;
mod honest;
mod hostile;
mod identify;
mod layout;
mod log_reader;
mod mat;
mod mjcf;
mod outputs;
mod promises;
mod registry;
mod robotics_logs;
mod run_log;
mod schemas;
mod serial;
mod sim;
mod smart_servo;
mod student;
mod transmission;
mod trend;
mod trend_noisy;
mod two_mass;
mod util;
mod window;
