//! servo's board firmware on QEMU's `mps2-an386` machine (ARM MPS2 FPGA image AN386, a
//! Cortex-M4F at 25 MHz): the board core of `servo_core::board` with the simulated gearmotor
//! (`SimDrive`) behind its HAL, so the firmware core runs on a real Cortex-M instruction set in
//! CI (`servo board --qemu`).
//!
//! HAL:
//! * serial link: CMSDK APB UART0 (0x4000_4000), polled; QEMU connects it to a chardev;
//! * clock: SysTick free-running over its 24 bits at the 25 MHz core clock, extended to 64 bits
//!   by polling; QEMU's SysTick follows the host's real time;
//! * encoder, current ADC, voltage output: the simulated plant, advanced in physics sub-steps
//!   of period/`substeps` on the board's own clock (the same scheme as the host's virtual board);
//! * statistics (one line a second: runs, samples, missed deadlines, late ticks, busy time per
//!   period) on UART1 (0x4000_5000), for the loop-rate benchmark.
//!
//! Boot configuration: QEMU's `-device loader,addr=...,data=...,data-len=4` may write a
//! [`BootConfig`] at [`BOOT_CONFIG_ADDR`] (outside the RAM the linker uses); without its magic
//! word the defaults below apply (1 ms period, 50 ms watchdog, 5 physics sub-steps, the lab
//! plant).
#![no_std]
#![no_main]

use core::fmt::Write;
use core::ptr::{read_volatile, write_volatile};
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use panic_halt as _;
use servo_core::board::{BoardConfig, BoardCore, BoardHal, SimDrive};
use servo_core::effects::{Effect, EffectKind};
use servo_core::protocol::{fixed_text, FaultCode};
use servo_core::safety::SafetyLimits;
use servo_core::sim::SensorConfig;
use servo_core::Plant;

/// Core clock of the AN386 image [Hz].
const SYSCLK_HZ: u64 = 25_000_000;
/// Where `servo board --qemu` puts the boot configuration (last 4 KiB of SSRAM2/3).
const BOOT_CONFIG_ADDR: usize = 0x203F_F000;
/// "SRVB" little-endian.
const BOOT_MAGIC: u32 = 0x4256_5253;

/// The boot configuration written by QEMU's loader device, one little-endian u32 per field.
#[repr(C)]
#[derive(Clone, Copy)]
struct BootConfig {
    magic: u32,
    /// Control period [us].
    period_us: u32,
    /// Watchdog [ms].
    watchdog_ms: u32,
    /// Physics sub-steps per period.
    substeps: u32,
    /// 0: the lab plant (`Plant::lab`), 1: Table 2 without friction (`Plant::nominal`), 2: the
    /// lab plant with an unbalanced load (imbalance amplitude 0.01 N m, phase 0.5 rad).
    plant: u32,
    /// Soft position limit ± from Start [mrad]; 0 = the default ±2 rev.
    theta_limit_mrad: u32,
}

impl BootConfig {
    const DEFAULT: BootConfig = BootConfig {
        magic: BOOT_MAGIC,
        period_us: 1000,
        watchdog_ms: 50,
        substeps: 5,
        plant: 0,
        theta_limit_mrad: 0,
    };

    fn read() -> BootConfig {
        // SAFETY: a fixed, aligned address in SSRAM2/3 that the linker leaves alone.
        let c = unsafe { read_volatile(BOOT_CONFIG_ADDR as *const BootConfig) };
        if c.magic == BOOT_MAGIC && (1..=20).contains(&c.substeps) && c.period_us >= 100 {
            c
        } else {
            BootConfig::DEFAULT
        }
    }
}

/// A CMSDK APB UART (DATA, STATE, CTRL, INTSTATUS, BAUDDIV registers).
struct Uart(usize);

impl Uart {
    const DATA: usize = 0x00;
    const STATE: usize = 0x04;
    const CTRL: usize = 0x08;
    const INTCLEAR: usize = 0x0C;
    const BAUDDIV: usize = 0x10;
    const TX_FULL: u32 = 1;
    const RX_FULL: u32 = 2;

    fn reg(&self, off: usize) -> *mut u32 {
        (self.0 + off) as *mut u32
    }
    fn init(&self) {
        // SAFETY: memory-mapped registers of the UART at a fixed address of the machine.
        unsafe {
            write_volatile(self.reg(Self::BAUDDIV), 16);
            // TX and RX enabled, RX interrupt enabled (it only wakes the core from WFI: PRIMASK
            // stays set and the pending bit is cleared by hand).
            write_volatile(self.reg(Self::CTRL), 0b1011);
        }
    }
    fn read(&self) -> Option<u8> {
        // SAFETY: as in `init`.
        unsafe {
            write_volatile(self.reg(Self::INTCLEAR), 0b10);
            if read_volatile(self.reg(Self::STATE)) & Self::RX_FULL != 0 {
                Some(read_volatile(self.reg(Self::DATA)) as u8)
            } else {
                None
            }
        }
    }
    fn write(&self, bytes: &[u8]) {
        for &b in bytes {
            // SAFETY: as in `init`.
            unsafe {
                while read_volatile(self.reg(Self::STATE)) & Self::TX_FULL != 0 {}
                write_volatile(self.reg(Self::DATA), b as u32);
            }
        }
    }
}

impl Write for Uart {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        Uart::write(self, s.as_bytes());
        Ok(())
    }
}

/// An interrupt line of the AN386 image (NVIC numbering).
#[derive(Clone, Copy)]
enum Irq {
    Uart0Rx = 0,
    Timer0 = 8,
}

// SAFETY: the values are the AN386 interrupt numbers.
unsafe impl cortex_m::interrupt::InterruptNumber for Irq {
    fn number(self) -> u16 {
        self as u16
    }
}

/// CMSDK APB timer 0 (0x4000_0000) as the wake-up tick of WFI: an interrupt every physics
/// sub-step, so the emulated core sleeps between events and QEMU does not spin a host core.
struct WakeTimer;

impl WakeTimer {
    const BASE: usize = 0x4000_0000;
    fn start(period_cycles: u32) {
        // SAFETY: memory-mapped registers of TIMER0 (CTRL, VALUE, RELOAD, INTCLEAR).
        unsafe {
            write_volatile((Self::BASE + 0x8) as *mut u32, period_cycles);
            write_volatile((Self::BASE + 0x4) as *mut u32, period_cycles);
            write_volatile(Self::BASE as *mut u32, 0b1001); // enable, interrupt enable
        }
    }
    /// Starts the current period over (the next interrupt one period from now).
    fn realign() {
        // SAFETY: as in `start`.
        unsafe {
            let reload = read_volatile((Self::BASE + 0x8) as *const u32);
            write_volatile((Self::BASE + 0x4) as *mut u32, reload);
        }
    }
    fn clear() {
        // SAFETY: as in `start`.
        unsafe { write_volatile((Self::BASE + 0xC) as *mut u32, 1) };
    }
}

/// Sleeps until the UART or the wake timer raises its interrupt (interrupts stay masked by
/// PRIMASK: WFI wakes on a pending one without taking it).
fn sleep_until_event() {
    cortex_m::asm::wfi();
    WakeTimer::clear();
    cortex_m::peripheral::NVIC::unpend(Irq::Timer0);
    cortex_m::peripheral::NVIC::unpend(Irq::Uart0Rx);
}

/// SysTick counting down over 24 bits, extended to 64 bits by polling (at least every 0.67 s).
struct Clock {
    last: u32,
    cycles: u64,
}

impl Clock {
    fn start(syst: &mut SYST) -> Clock {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();
        Clock {
            last: SYST::get_current(),
            cycles: 0,
        }
    }
    fn now_us(&mut self) -> u64 {
        let cur = SYST::get_current();
        self.cycles += (self.last.wrapping_sub(cur) & 0x00FF_FFFF) as u64;
        self.last = cur;
        self.cycles * 1_000_000 / SYSCLK_HZ
    }
}

struct QemuHal {
    clock: Clock,
    uart: Uart,
    drive: SimDrive,
    restart: bool,
    last_fault: Option<FaultCode>,
}

impl BoardHal for QemuHal {
    fn now_us(&mut self) -> u32 {
        self.clock.now_us() as u32
    }
    fn encoder_count(&mut self) -> i32 {
        self.drive.encoder_count()
    }
    fn current_raw(&mut self) -> i16 {
        self.drive.current_raw()
    }
    fn set_voltage(&mut self, u_v: f32) {
        self.drive.set_voltage(u_v);
    }
    fn restart_tick(&mut self) {
        self.restart = true;
    }
    fn write(&mut self, bytes: &[u8]) {
        self.uart.write(bytes);
    }
    fn on_fault(&mut self, code: FaultCode, _text: &str) {
        self.last_fault = Some(code);
    }
}

/// Loop-timing statistics for UART1.
#[derive(Default)]
struct Timing {
    late_ticks: u64,
    max_lateness_us: u64,
    busy_max_us: u64,
    busy_sum_us: u64,
    periods: u64,
}

#[entry]
fn main() -> ! {
    let boot = BootConfig::read();
    let mut cp = cortex_m::Peripherals::take().unwrap_or_else(|| loop {
        cortex_m::asm::wfi()
    });
    let uart = Uart(0x4000_4000);
    uart.init();
    let mut stats_uart = Uart(0x4000_5000);
    stats_uart.init();

    let period_us = boot.period_us as u64;
    let subs = boot.substeps as u64;
    let plant = match boot.plant {
        1 => Plant::nominal(),
        2 => {
            let mut p = Plant::lab();
            if let Ok(e) = Effect::new(EffectKind::Imbalance, &[0.01, 0.5]) {
                p.effects.insert(e);
            }
            p
        }
        _ => Plant::lab(),
    };
    let sensors = SensorConfig::default();
    let cfg = BoardConfig {
        firmware: fixed_text("servo-qemu-an386"),
        sample_period_us: boot.period_us,
        watchdog_ms: boot.watchdog_ms.min(65_535) as u16,
        limits: if boot.theta_limit_mrad > 0 {
            let lim = boot.theta_limit_mrad as f64 * 1e-3;
            SafetyLimits {
                theta_min_rad: -lim,
                theta_max_rad: lim,
                ..SafetyLimits::default()
            }
        } else {
            SafetyLimits::default()
        },
        counts_per_rev: sensors.counts_per_rev,
        current_scale_a_per_lsb: 1e-3,
    };
    let h_s = period_us as f64 * 1e-6 / subs as f64;
    let (Ok(mut core), Ok(drive)) = (
        BoardCore::new(cfg),
        SimDrive::new(&plant, sensors, h_s, cfg.current_scale_a_per_lsb),
    ) else {
        let _ = writeln!(stats_uart, "servo-qemu: invalid boot configuration");
        #[allow(clippy::empty_loop)]
        loop {}
    };
    cortex_m::interrupt::disable();
    WakeTimer::start((SYSCLK_HZ * period_us / subs / 1_000_000) as u32);
    // SAFETY: PRIMASK is set, so enabling the lines only lets them wake WFI.
    unsafe {
        cortex_m::peripheral::NVIC::unmask(Irq::Uart0Rx);
        cortex_m::peripheral::NVIC::unmask(Irq::Timer0);
    }
    let mut hal = QemuHal {
        clock: Clock::start(&mut cp.SYST),
        uart,
        drive,
        restart: false,
        last_fault: None,
    };
    let _ = writeln!(
        stats_uart,
        "servo-qemu: period {} us, watchdog {} ms, {} sub-steps, plant {}",
        boot.period_us,
        boot.watchdog_ms,
        subs,
        if boot.plant == 1 { "table2" } else { "lab" }
    );

    // Sub-step n of the run ends at t0 + n period / subs.
    let mut t0 = hal.clock.now_us();
    let mut n: u64 = 0;
    let mut idle_next = t0;
    let mut timing = Timing::default();
    let mut next_report = t0 + 1_000_000;
    let mut busy_this_period = 0u64;
    loop {
        while let Some(b) = hal.uart.read() {
            core.receive(&mut hal, &[b]);
            if hal.restart {
                hal.restart = false;
                WakeTimer::realign();
                t0 = hal.clock.now_us();
                n = 0;
                busy_this_period = 0;
            }
        }
        let now = hal.clock.now_us();
        let mut worked = false;
        if core.is_running() {
            let due = t0 + (n + 1) * period_us / subs;
            if now >= due {
                worked = true;
                hal.drive.step();
                n += 1;
                if n.is_multiple_of(subs) {
                    let late = now - due;
                    if late > period_us {
                        timing.late_ticks += 1;
                    }
                    timing.max_lateness_us = timing.max_lateness_us.max(late);
                    core.tick(&mut hal);
                }
                busy_this_period += hal.clock.now_us() - now;
                if n.is_multiple_of(subs) {
                    timing.busy_max_us = timing.busy_max_us.max(busy_this_period);
                    timing.busy_sum_us += busy_this_period;
                    timing.periods += 1;
                    busy_this_period = 0;
                }
                if !core.is_running() {
                    idle_next = hal.clock.now_us();
                }
            }
        } else if now >= idle_next {
            // Idle: the plant coasts at 0 V (at most 1 s of catching up).
            hal.drive.step();
            idle_next = idle_next.max(now.saturating_sub(1_000_000)) + period_us / subs;
        }
        if now >= next_report {
            next_report = now + 1_000_000;
            let s = core.stats();
            let d = core.decoder_stats();
            let _ = writeln!(
                stats_uart,
                "t {} s | u {:.3} V | runs {} samples {} missed {} faults {} last {:?} | late ticks {} max late {} us | busy/period max {} us mean {} us | crc {} framing {}",
                now / 1_000_000,
                hal.drive.voltage_v(),
                s.runs,
                s.samples,
                s.missed_deadlines,
                s.faults,
                hal.last_fault,
                timing.late_ticks,
                timing.max_lateness_us,
                timing.busy_max_us,
                timing.busy_sum_us.checked_div(timing.periods).unwrap_or(0),
                d.crc_errors,
                d.framing_errors,
            );
            timing = Timing::default();
        }
        if !worked {
            sleep_until_event();
        }
    }
}
