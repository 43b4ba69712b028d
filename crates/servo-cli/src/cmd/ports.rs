//! `servo ports`: lists serial ports that may be boards.
//!
//! serialport's enumeration without libudev reads /sys/class/tty (USB/PCI/platform ports); the
//! usual device names (/dev/ttyACM*, /dev/ttyUSB*) are added from /dev in case sysfs is not
//! mounted, and `--all` adds pseudo-terminals (virtual boards from `servo board --pty`).

use std::collections::BTreeMap;

/// List serial ports that may be boards.
#[derive(Debug, clap::Parser)]
pub struct Ports {
    /// Also list pseudo-terminals (/dev/pts/N), e.g. virtual boards.
    #[arg(long)]
    pub all: bool,
}

/// Candidate ports: path → description.
pub fn candidates(all: bool) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    if std::path::Path::new("/sys/class/tty").is_dir() {
        if let Ok(ports) = serialport::available_ports() {
            for p in ports {
                let what = match p.port_type {
                    serialport::SerialPortType::UsbPort(u) => format!(
                        "USB {:04x}:{:04x}{}{}",
                        u.vid,
                        u.pid,
                        u.manufacturer.map(|m| format!(" {m}")).unwrap_or_default(),
                        u.product.map(|m| format!(" {m}")).unwrap_or_default()
                    ),
                    serialport::SerialPortType::PciPort => "PCI serial".into(),
                    serialport::SerialPortType::BluetoothPort => "Bluetooth serial".into(),
                    serialport::SerialPortType::Unknown => "serial".into(),
                };
                out.insert(p.port_name, what);
            }
        }
    }
    let mut scan = |dir: &str, prefixes: &[&str], what: &str| {
        if let Ok(rd) = std::fs::read_dir(dir) {
            for e in rd.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if prefixes.iter().any(|p| name.starts_with(p))
                    && (prefixes != [""] || name.parse::<u32>().is_ok())
                {
                    let path = format!("{dir}/{name}");
                    out.entry(path).or_insert_with(|| what.to_string());
                }
            }
        }
    };
    scan("/dev", &["ttyACM", "ttyUSB"], "serial (USB CDC/UART)");
    if all {
        scan("/dev/pts", &[""], "pseudo-terminal");
    }
    out
}

impl Ports {
    pub fn run(self) -> anyhow::Result<()> {
        let c = candidates(self.all);
        if c.is_empty() {
            outln!(
                "no serial ports found{}; plug a board in, or start a virtual one with `servo board --pty`",
                if self.all { "" } else { " (--all also lists pseudo-terminals)" }
            );
            return Ok(());
        }
        for (path, what) in c {
            outln!("{path}\t{what}");
        }
        Ok(())
    }
}
