//! The QEMU board: servo's board firmware (`firmware/qemu-mps2`, the board core of
//! [`servo_core::board`] with the simulated plant behind its HAL) running on qemu-system-arm's
//! `mps2-an386` Cortex-M4F, its UART0 bridged to a pseudo-terminal.
//!
//! QEMU serves UART0 on a Unix socket (`-chardev socket,server=on`); [`QemuBoard`] connects to it
//! and copies bytes both ways between the socket and the master of a pty pair whose slave it
//! keeps open, so hosts (`servo run --backend serial --port PATH`) can come and go as with the
//! virtual board. UART1 carries the firmware's one-line-a-second loop statistics into a file.
//! The board's constants travel in a boot block that QEMU's `loader` device writes at
//! [`BOOT_CONFIG_ADDR`] (see the firmware's `BootConfig`).

use crate::backend::HwError;
use serialport::{SerialPort, TTYPort};
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Where the firmware reads its boot configuration.
pub const BOOT_CONFIG_ADDR: u32 = 0x203F_F000;
/// "SRVB" little-endian.
pub const BOOT_MAGIC: u32 = 0x4256_5253;
/// The image's file name under `firmware/target/thumbv7em-none-eabihf/release/`.
pub const IMAGE_NAME: &str = "servo-board-qemu";

/// The simulated plant inside the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QemuPlant {
    /// `Plant::lab()`: Table 2 with the friction and inertia measured on real SRV-02s.
    #[default]
    Lab,
    /// `Plant::nominal()`: Table 2 without friction.
    Table2,
    /// `Plant::lab()` with an unbalanced load (an eccentric mass: 0.01 N m at phase 0.5 rad, the
    /// README's motor with a secret): the compensation tests' plant.
    LabUnbalanced,
}

/// How to start the QEMU board.
#[derive(Debug, Clone, PartialEq)]
pub struct QemuConfig {
    /// The qemu-system-arm executable.
    pub qemu: PathBuf,
    /// The firmware image (ELF).
    pub elf: PathBuf,
    /// Control period [us].
    pub period_us: u32,
    /// Watchdog [ms].
    pub watchdog_ms: u32,
    /// Physics sub-steps per period.
    pub substeps: u32,
    /// Soft position limit ± from Start [mrad]; 0 = the firmware's default (±2 rev).
    pub theta_limit_mrad: u32,
    /// The plant inside the image.
    pub plant: QemuPlant,
    /// File for the firmware's loop statistics (UART1); none = discarded.
    pub stats_file: Option<PathBuf>,
}

impl Default for QemuConfig {
    fn default() -> Self {
        QemuConfig {
            qemu: PathBuf::from("qemu-system-arm"),
            elf: PathBuf::from(IMAGE_NAME),
            period_us: 1000,
            watchdog_ms: 50,
            substeps: 5,
            theta_limit_mrad: 0,
            plant: QemuPlant::Lab,
            stats_file: None,
        }
    }
}

/// Where the QEMU image is looked for when no path is given: `$SERVO_QEMU_ELF`, then
/// `firmware/target/thumbv7em-none-eabihf/release/servo-board-qemu` under the current directory
/// and under the checkout that holds the running executable (`target/<profile>/servo`).
pub fn default_image() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("SERVO_QEMU_ELF") {
        return Some(PathBuf::from(p));
    }
    let rel = Path::new("firmware/target/thumbv7em-none-eabihf/release").join(IMAGE_NAME);
    let mut candidates = vec![rel.clone()];
    if let Ok(exe) = std::env::current_exe() {
        for dir in exe.ancestors().skip(1).take(4) {
            candidates.push(dir.join(&rel));
        }
    }
    candidates.into_iter().find(|p| p.is_file())
}

/// Whether `qemu` runs (`qemu-system-arm --version`).
pub fn qemu_available(qemu: &Path) -> bool {
    Command::new(qemu)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// A running QEMU board bridged to a pseudo-terminal. Dropping it kills QEMU.
#[derive(Debug)]
pub struct QemuBoard {
    child: Child,
    path: String,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    dir: PathBuf,
    _slave: TTYPort,
}

impl QemuBoard {
    /// Starts QEMU with the image and bridges its UART to a new pty (see [`QemuBoard::path`]).
    pub fn start(cfg: &QemuConfig) -> Result<QemuBoard, HwError> {
        if !cfg.elf.is_file() {
            return Err(HwError::Protocol(format!(
                "QEMU board image {} not found: build it with `cargo build --release` in firmware/",
                cfg.elf.display()
            )));
        }
        static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "servo-qemu-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir)?;
        let sock = dir.join("uart0.sock");
        let stats = cfg
            .stats_file
            .clone()
            .unwrap_or_else(|| PathBuf::from("/dev/null"));
        let mut cmd = Command::new(&cfg.qemu);
        cmd.args(["-M", "mps2-an386", "-nographic", "-monitor", "none"])
            .arg("-kernel")
            .arg(&cfg.elf)
            .arg("-chardev")
            .arg(format!(
                "socket,id=uart0,path={},server=on,wait=off",
                sock.display()
            ))
            .args(["-serial", "chardev:uart0", "-serial"])
            .arg(format!("file:{}", stats.display()));
        let plant = match cfg.plant {
            QemuPlant::Lab => 0,
            QemuPlant::Table2 => 1,
            QemuPlant::LabUnbalanced => 2,
        };
        let words = [
            BOOT_MAGIC,
            cfg.period_us,
            cfg.watchdog_ms,
            cfg.substeps,
            plant,
            cfg.theta_limit_mrad,
        ];
        for (i, w) in words.iter().enumerate() {
            cmd.arg("-device").arg(format!(
                "loader,addr=0x{:08X},data=0x{w:08X},data-len=4",
                BOOT_CONFIG_ADDR + 4 * i as u32
            ));
        }
        // QEMU dies with the thread that started it, even when servo is killed with SIGKILL.
        // SAFETY: prctl is async-signal-safe; nothing else runs between fork and exec.
        unsafe {
            use std::os::unix::process::CommandExt;
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        cmd.stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().map_err(|e| {
            HwError::Protocol(format!(
                "starting {} (install qemu-system-arm): {e}",
                cfg.qemu.display()
            ))
        })?;
        // Connect to QEMU's socket as soon as it exists.
        let t = Instant::now();
        let stream = loop {
            match UnixStream::connect(&sock) {
                Ok(s) => break s,
                Err(_) if t.elapsed() < Duration::from_secs(10) => {
                    if let Ok(Some(status)) = child.try_wait() {
                        let mut err = String::new();
                        if let Some(mut e) = child.stderr.take() {
                            let _ = e.read_to_string(&mut err);
                        }
                        return Err(HwError::Protocol(format!(
                            "qemu-system-arm exited ({status}): {}",
                            err.trim()
                        )));
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Err(HwError::Protocol(format!(
                        "connecting to QEMU's UART socket {}: {e}",
                        sock.display()
                    )));
                }
            }
        };
        let (master, slave) = TTYPort::pair()?;
        let path = slave
            .name()
            .ok_or_else(|| HwError::Protocol("the pseudo-terminal has no path".into()))?;
        let stop = Arc::new(AtomicBool::new(false));
        let threads = bridge(stream, master, &stop)?;
        Ok(QemuBoard {
            child,
            path,
            stop,
            threads,
            dir,
            _slave: slave,
        })
    }

    /// The pty path hosts open.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Whether QEMU is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Kills QEMU and ends the bridge.
    pub fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.child.kill();
        let _ = self.child.wait();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Copies socket → pty master and pty master → socket until `stop` or the socket closes.
fn bridge(
    stream: UnixStream,
    master: TTYPort,
    stop: &Arc<AtomicBool>,
) -> Result<Vec<JoinHandle<()>>, HwError> {
    let mut from_qemu = stream.try_clone()?;
    from_qemu.set_read_timeout(Some(Duration::from_millis(100)))?;
    let mut to_qemu = stream;
    let mut from_host = master;
    from_host.set_timeout(Duration::from_millis(100))?;
    let mut to_host = from_host.try_clone_native()?;
    let (s1, s2) = (stop.clone(), stop.clone());
    let down = std::thread::spawn(move || {
        let mut buf = [0u8; 512];
        while !s1.load(Ordering::Relaxed) {
            match from_qemu.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    // A full pty (nobody reading) drops the bytes, like a UART with no listener.
                    let _ = to_host.write_all(&buf[..n]);
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                    ) => {}
                Err(_) => break,
            }
        }
    });
    let up = std::thread::spawn(move || {
        let mut buf = [0u8; 512];
        while !s2.load(Ordering::Relaxed) {
            match from_host.read(&mut buf) {
                Ok(0) => std::thread::sleep(Duration::from_millis(5)),
                Ok(n) => {
                    if to_qemu.write_all(&buf[..n]).is_err() {
                        break;
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                    ) => {}
                // No host has the slave open right now (EIO on some kernels): wait for one.
                Err(_) => std::thread::sleep(Duration::from_millis(5)),
            }
        }
    });
    Ok(vec![down, up])
}

/// Periods `servo board --qemu` tries when none is given, shortest first [us].
pub const PROBE_PERIODS_US: [u32; 4] = [1000, 2000, 5000, 10_000];
/// Share of missed deadlines a probe may show for its period to count as held (after its first
/// [`PROBE_WARMUP_SAMPLES`]): well inside the [`crate::starvation::STARVED_MISSED_FRACTION`]
/// that stops a run, so that a run at the chosen period (which does more per sample than the
/// probe: a PID, a log) has headroom.
pub const PROBE_MAX_MISSED_FRACTION: f64 = 0.1;
/// Share of the period the 99th percentile of the host's round trip may take for the period to
/// count as held: the room a run needs under load, beyond the probe's 0 V answers.
pub const PROBE_MAX_RTT_FRACTION: f64 = 0.5;
/// Samples at the start of a probe not judged [samples]: the emulator translates the
/// firmware's code on its first periods.
pub const PROBE_WARMUP_SAMPLES: u64 = 20;
/// How long a probe runs at each period [s] (at least [`PROBE_MIN_SAMPLES`] samples).
pub const PROBE_DURATION_S: f64 = 0.5;
/// Fewest samples a probe judges [samples].
pub const PROBE_MIN_SAMPLES: u64 = 150;

/// What a probe of one period measured.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodProbe {
    /// The period tried [us].
    pub period_us: u32,
    /// Samples answered and deadlines missed after the warm-up.
    pub samples: u64,
    pub missed: u64,
    /// The board-measured round trip (sample out, command in) of the answers in time, 99th
    /// percentile [s]: how much of the period the host's answer takes.
    pub rtt_p99_s: f64,
    /// Why the loop was starved, if the host's watch stopped it.
    pub starved: Option<String>,
}

impl PeriodProbe {
    /// Whether the loop held the period.
    pub fn held(&self) -> bool {
        self.starved.is_none()
            && self.samples >= PROBE_MIN_SAMPLES
            && (self.missed as f64) <= PROBE_MAX_MISSED_FRACTION * self.samples as f64
            && self.rtt_p99_s <= PROBE_MAX_RTT_FRACTION * self.period_us as f64 * 1e-6
    }
}

impl std::fmt::Display for PeriodProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = self.period_us as f64 * 1e-3;
        match &self.starved {
            Some(s) => write!(f, "{ms} ms: {s}"),
            None => write!(
                f,
                "{ms} ms: {} of {} deadlines missed, round trip p99 {:.2} ms",
                self.missed,
                self.samples,
                self.rtt_p99_s * 1e3
            ),
        }
    }
}

/// Runs the QEMU board of `cfg` at `period_us` for [`PROBE_DURATION_S`] with this process as
/// its host, answering every sample with 0 V (nothing moves), and measures whether the loop
/// keeps the period on this machine.
pub fn probe_period(cfg: &QemuConfig, period_us: u32) -> Result<PeriodProbe, HwError> {
    let qcfg = QemuConfig {
        period_us,
        stats_file: None,
        ..cfg.clone()
    };
    let board = QemuBoard::start(&qcfg)?;
    let host = crate::serial::SerialConfig {
        port: board.path().to_string(),
        timeout_s: 0.5,
        ..crate::serial::SerialConfig::default()
    };
    let mut be = crate::serial::SerialBackend::open(host)?;
    let period_s = period_us as f64 * 1e-6;
    let n = ((PROBE_DURATION_S / period_s).ceil() as u64).max(PROBE_MIN_SAMPLES);
    let mut starved = None;
    let mut warm = None;
    use crate::backend::Backend;
    for k in 0..n + PROBE_WARMUP_SAMPLES {
        if k == PROBE_WARMUP_SAMPLES {
            warm = Some(be.stats());
        }
        match be.sample() {
            Ok(_) => be.apply(0.0)?,
            // A starved loop, and a board that lost its host (its watchdog fired, or it went
            // silent): the period is not held here.
            Err(e @ (HwError::Starved(_) | HwError::Fault { .. } | HwError::Timeout { .. })) => {
                starved = Some(e.to_string());
                break;
            }
            Err(e) => {
                let _ = be.stop();
                return Err(e);
            }
        }
    }
    let _ = be.stop();
    let st = be.stats();
    drop(be);
    drop(board);
    let w = warm.unwrap_or(st);
    Ok(PeriodProbe {
        period_us,
        samples: st.samples.saturating_sub(w.samples),
        missed: st.missed_deadlines.saturating_sub(w.missed_deadlines),
        rtt_p99_s: st.rtt_p99_s,
        starved,
    })
}

/// The shortest of [`PROBE_PERIODS_US`] the QEMU board of `cfg` holds on this machine
/// ([`probe_period`]), with every probe's figures; `Ok((None, probes))` when it holds none.
pub fn choose_period(cfg: &QemuConfig) -> Result<(Option<u32>, Vec<PeriodProbe>), HwError> {
    let mut probes = Vec::new();
    for p in PROBE_PERIODS_US {
        let probe = probe_period(cfg, p)?;
        let held = probe.held();
        probes.push(probe);
        if held {
            return Ok((Some(p), probes));
        }
    }
    Ok((None, probes))
}
