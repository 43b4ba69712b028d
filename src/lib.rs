//! Helpers shared by the end-to-end tests in `tests/`.
//!
//! The real lab measurements live outside the repository, in `../shared/realdata` (they carry no
//! licence and are never copied here). Tests that need them call [`realdata_dir`] and skip with a
//! clear message when the folder is absent, as it is in a user's clone.

use std::path::PathBuf;

pub mod mat_writer;

/// Path of `../shared/realdata` relative to the workspace root, if it exists.
///
/// The environment variable `SERVO_REALDATA` overrides the location.
pub fn realdata_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("SERVO_REALDATA") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/realdata"),
    };
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIP: real lab data not found at {} (set SERVO_REALDATA or place shared/realdata beside the checkout)",
            dir.display()
        );
        None
    }
}

/// Path of the `servo` binary for the end-to-end tests, building it first when needed.
///
/// `cargo test` at the workspace root builds it already (servo-cli has integration tests); the
/// fallback runs `cargo build -p servo-cli --bin servo` with the same profile.
pub fn servo_bin() -> PathBuf {
    static BUILT: std::sync::Once = std::sync::Once::new();
    // Integration tests live in target/<profile>/deps; the binary sits in target/<profile>/.
    let mut dir = std::env::current_exe().expect("test executable path");
    dir.pop();
    if dir.ends_with("deps") {
        dir.pop();
    }
    let bin = dir.join(format!("servo{}", std::env::consts::EXE_SUFFIX));
    BUILT.call_once(|| {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = std::process::Command::new(cargo);
        cmd.args(["build", "-q", "-p", "servo-cli", "--bin", "servo"]);
        if dir.ends_with("release") {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("run cargo build for the servo binary");
        assert!(status.success(), "building the servo binary failed");
    });
    bin
}

/// Runs `servo` with `args`, returning (exit success, stdout, stderr). The process holds the
/// machine shared ([`shared`]) unless the calling thread already holds it.
///
/// When `args` hold `--json` and servo succeeds, the output is validated against the schema it
/// names (`"schema": "servo.<command>/1"`, docs/schemas/<command>.json): every `--json` output
/// that a test produces is checked, and a test fails on an output its schema does not describe.
pub fn servo(args: &[&str]) -> (bool, String, String) {
    let bin = servo_bin();
    let out = {
        let _machine = shared();
        std::process::Command::new(bin)
            .args(args)
            .output()
            .expect("spawn servo")
    };
    let (ok, stdout, stderr) = (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    );
    if ok && args.contains(&"--json") {
        let v: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
            panic!("servo {args:?} --json printed invalid JSON ({e}):\n{stdout}")
        });
        if let Err(errors) = validate_output(&v) {
            panic!("servo {args:?}: the --json output does not follow its schema:\n{errors}");
        }
    }
    (ok, stdout, stderr)
}

/// Path of the schema file of a schema id (`servo.design/1` -> docs/schemas/design.json).
pub fn schema_path(id: &str) -> Option<PathBuf> {
    let name = id.strip_prefix("servo.")?.strip_suffix("/1")?;
    Some(
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("docs/schemas")
            .join(format!("{name}.json")),
    )
}

/// Validates one `--json` output against the schema named by its `schema` key. Err holds every
/// violation, one per line, with its JSON pointer.
pub fn validate_output(v: &serde_json::Value) -> Result<(), String> {
    let id = v
        .get("schema")
        .and_then(|s| s.as_str())
        .ok_or_else(|| "the output has no \"schema\" key".to_string())?;
    let path = schema_path(id).ok_or_else(|| format!("unknown schema id {id:?}"))?;
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("reading schema {}: {e}", path.display()))?;
    let schema: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| format!("schema {} is not JSON: {e}", path.display()))?;
    let validator = jsonschema::draft202012::new(&schema).map_err(|e| {
        format!(
            "schema {} is not a valid 2020-12 schema: {e}",
            path.display()
        )
    })?;
    let errors: Vec<String> = validator
        .iter_errors(v)
        .map(|e| format!("  at {}: {e}", e.instance_path()))
        .collect();
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors.join("\n"))
    }
}

/// The QEMU board image and qemu-system-arm for the tests that run servo's firmware under
/// QEMU, if both are here. Without them the test skips with a clear message, unless
/// `SERVO_REQUIRE_QEMU` is set (CI installs qemu and builds the image): then it fails.
pub fn qemu_image() -> Option<PathBuf> {
    let qemu_ok = std::process::Command::new("qemu-system-arm")
        .arg("--version")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let image = std::env::var_os("SERVO_QEMU_ELF")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("firmware/target/thumbv7em-none-eabihf/release")
                .join("servo-board-qemu")
        });
    let why = if !qemu_ok {
        "qemu-system-arm not found (apt-get install qemu-system-arm)".to_string()
    } else if !image.is_file() {
        format!(
            "QEMU board image {} not built (cd firmware && cargo build --release)",
            image.display()
        )
    } else {
        return Some(image);
    };
    assert!(
        std::env::var_os("SERVO_REQUIRE_QEMU").is_none(),
        "SERVO_REQUIRE_QEMU is set but {why}"
    );
    eprintln!("SKIP: {why}");
    None
}

/// The machine as the tests share it: real-time tests (a board, QEMU or a pseudo-terminal
/// paced by the wall clock, all in tests/e2e/serial.rs) hold it alone through [`realtime`];
/// every other test holds it shared through [`shared`] for its whole run, as its first
/// statement (tests/e2e/layout.rs checks that), and so does every `servo` process a test spawns
/// through [`servo`] from a thread that holds nothing. A real-time test therefore runs with
/// no other test beside it: it waits for the tests in flight to end, and none starts until it
/// ends. On a 2-core CI machine any CPU-bound test beside a QEMU board (a diagnosis, and also
/// one thread of in-process simulation) starves the host's loop into missed deadlines that say
/// nothing about servo: stop 41's CI lost 3873 of 5904 samples beside a report test's `servo
/// diagnose`; stop 44's lost 2403 of 4350 beside the in-process simulator tests, which held
/// nothing then, and the board's Stop was not acknowledged in time.
static MACHINE: std::sync::RwLock<()> = std::sync::RwLock::new(());

thread_local! {
    /// Whether this thread holds [`MACHINE`] (either way): a thread never takes it twice.
    static HOLDS_MACHINE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// A hold on the machine ([`realtime`], [`shared`]); released when dropped.
pub struct MachineGuard {
    _guard: Option<MachineLock>,
}

enum MachineLock {
    Alone(#[allow(dead_code)] std::sync::RwLockWriteGuard<'static, ()>),
    Shared(#[allow(dead_code)] std::sync::RwLockReadGuard<'static, ()>),
}

impl Drop for MachineGuard {
    fn drop(&mut self) {
        if self._guard.take().is_some() {
            HOLDS_MACHINE.with(|h| h.set(false));
        }
    }
}

fn hold(alone: bool) -> MachineGuard {
    if HOLDS_MACHINE.with(|h| h.get()) {
        // Already held by this thread (a test spawning servo): nothing more to take.
        assert!(
            !alone,
            "a test asked for the machine alone while its thread already held it shared"
        );
        return MachineGuard { _guard: None };
    }
    let lock = if alone {
        MachineLock::Alone(MACHINE.write().unwrap_or_else(|e| e.into_inner()))
    } else {
        MachineLock::Shared(MACHINE.read().unwrap_or_else(|e| e.into_inner()))
    };
    HOLDS_MACHINE.with(|h| h.set(true));
    MachineGuard { _guard: Some(lock) }
}

/// Exclusive use of the machine for a real-time test (waits for the other tests in flight and
/// the `servo` processes they spawned to end).
pub fn realtime() -> MachineGuard {
    hold(true)
}

/// Shared use of the machine: the first statement of every test that is not real-time (waits
/// while a real-time test runs). The test's threads must not call [`servo`] while it holds
/// this (a waiting real-time test would make them wait for ever): only the test's own thread.
pub fn shared() -> MachineGuard {
    hold(false)
}

/// One minute of simulated logs as the diagnose benchmark takes them: `servo run` of the plant
/// `plant` (its flags, e.g. `["--plant", "truth.toml"]`) for 30 s open loop on a PRBS voltage of
/// `amp_v` volts (0.2 s bits, seed `seed`) written to `open`, and for 30 s closed loop with the
/// gains file `gains` on a square reference (2 rad, period 3 s, seed `seed + 1`) written to
/// `closed` (MCAP). Panics with servo's message when a run fails.
pub fn prbs_and_square_logs(
    plant: &[&str],
    gains: &str,
    amp_v: &str,
    seed: u64,
    (open, closed): (&str, &str),
) {
    let prbs = format!("prbs:amp={amp_v},bit=0.2");
    let (s_open, s_closed) = (seed.to_string(), (seed + 1).to_string());
    let runs: [Vec<&str>; 2] = [
        ["--voltage", &prbs, "--seed", &s_open, "--log", open].to_vec(),
        [
            "--gains",
            gains,
            "--ref",
            "square:amp=2,period=3",
            "--seed",
            &s_closed,
            "--log",
            closed,
        ]
        .to_vec(),
    ];
    for extra in runs {
        let mut args = vec!["run", "--duration", "30"];
        args.extend_from_slice(plant);
        args.extend_from_slice(&extra);
        let (ok, _, err) = servo(&args);
        assert!(ok, "servo {args:?} failed: {err}");
    }
}
