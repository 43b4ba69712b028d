//! Where a diagnosis spends its time: with the environment variable `SERVO_DIAG_TIMING` set
//! (std builds), each timed stage prints its wall time [s], the thread it ran on, how many cores
//! it kept busy and how many control periods its simulations stepped to stderr (stages that run
//! side by side count each other's periods).
//! Off by default: nothing is measured or printed.

/// Runs `f`, printing `label` and its wall time [s] to stderr when `SERVO_DIAG_TIMING` is set.
#[cfg(feature = "std")]
pub fn timed<R>(label: impl FnOnce() -> alloc::string::String, f: impl FnOnce() -> R) -> R {
    if !enabled() {
        return f();
    }
    let (t0, c0) = (std::time::Instant::now(), cpu_s());
    let p0 = crate::fit::oe::simulated_periods();
    let r = f();
    let wall = t0.elapsed().as_secs_f64();
    let periods = crate::fit::oe::simulated_periods().saturating_sub(p0);
    let cpu = match (c0, cpu_s()) {
        (Some(a), Some(b)) => alloc::format!(", {:.2} cores busy", (b - a) / wall.max(1e-9)),
        _ => alloc::string::String::new(),
    };
    std::eprintln!(
        "[diagnose timing] {:>7.3} s  {} ({:?}{cpu}, {:.1} M periods simulated)",
        wall,
        label(),
        std::thread::current().id(),
        periods as f64 * 1e-6
    );
    r
}

/// The process's CPU time [s] (user and system, every thread), where the system tells it
/// (Linux: `/proc/self/stat`, in clock ticks of 10 ms); `None` elsewhere.
#[cfg(feature = "std")]
fn cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name (which may hold spaces) in parentheses.
    let rest = stat.rsplit_once(')')?.1;
    let f: alloc::vec::Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line: 12 and 13 after the name.
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
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
