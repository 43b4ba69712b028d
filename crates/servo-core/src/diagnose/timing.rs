//! Where a diagnosis spends its time: with the environment variable `SERVO_DIAG_TIMING` set
//! (std builds), each timed stage prints its wall time [s] and the thread it ran on to stderr.
//! Off by default: nothing is measured or printed.

/// Runs `f`, printing `label` and its wall time [s] to stderr when `SERVO_DIAG_TIMING` is set.
#[cfg(feature = "std")]
pub fn timed<R>(label: impl FnOnce() -> alloc::string::String, f: impl FnOnce() -> R) -> R {
    if !enabled() {
        return f();
    }
    let t0 = std::time::Instant::now();
    let r = f();
    std::eprintln!(
        "[diagnose timing] {:>7.3} s  {} ({:?})",
        t0.elapsed().as_secs_f64(),
        label(),
        std::thread::current().id()
    );
    r
}

/// Runs `f` (no timing without std).
#[cfg(not(feature = "std"))]
pub fn timed<R>(_label: impl FnOnce() -> alloc::string::String, f: impl FnOnce() -> R) -> R {
    f()
}

/// Whether `SERVO_DIAG_TIMING` is set (read once).
#[cfg(feature = "std")]
fn enabled() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("SERVO_DIAG_TIMING").is_some())
}
