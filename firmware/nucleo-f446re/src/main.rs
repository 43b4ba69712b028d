//! servo's board firmware for the ST Nucleo-F446RE (STM32F446RE, Cortex-M4F at 180 MHz): the
//! board core of `servo_core::board` behind a HAL of the board's peripherals. Wiring, bill of
//! materials and flashing: `docs/board.md`.
//!
//! | function | peripheral | pin (Arduino header) |
//! |---|---|---|
//! | serial link to the host | USART2, 921 600 baud 8N1 (ST-LINK virtual COM port, USB) | PA2/PA3 (wired on the Nucleo) |
//! | quadrature encoder A/B | TIM3 in encoder mode (x4), extended to 32 bits | PA6 (D12), PA7 (D11) |
//! | amplifier input (feature `dac`) | DAC1: 0..3.3 V, 1.65 V = 0 V; an op-amp stage maps it to ±10 V | PA4 (A2) |
//! | H-bridge (feature `hbridge`) | TIM1 CH1 PWM 20 kHz (magnitude) + GPIO (direction) | PA8 (D7), PB5 (D4) |
//! | current sense | ADC1 channel 0, 12 bit, offset calibrated at 0 V after reset | PA0 (A0) |
//! | tick and clock | DWT cycle counter (180 MHz), polled | — |
//!
//! The main loop polls the UART and the clock; nothing runs in interrupts, so `receive` and
//! `tick` of the core never overlap.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use panic_halt as _;
use servo_core::board::{BoardConfig, BoardCore, BoardHal};
use servo_core::protocol::fixed_text;
use servo_core::safety::SafetyLimits;
use stm32f4xx_hal::{
    adc::{
        config::{AdcConfig, SampleTime},
        Adc,
    },
    pac,
    prelude::*,
    qei::Qei,
    serial::{Config as SerialConfig, Rx, Tx},
};

#[cfg(all(feature = "dac", feature = "hbridge"))]
compile_error!(
    "choose one output stage: feature `dac` (default) or `hbridge` (with --no-default-features)"
);

/// Core clock [Hz].
const SYSCLK_HZ: u32 = 180_000_000;
/// Control period [us].
const SAMPLE_PERIOD_US: u32 = 1000;
/// Encoder counts per load revolution: the SRV-02's 1024-line encoder in x4 quadrature.
const COUNTS_PER_REV: u32 = 4096;
/// Current sense: 0.5 ohm shunt (R_s of the handout's Table 2) into a unity-gain differential
/// amplifier biased at mid-scale: 3.3 V / 4096 LSB / 0.5 ohm [A/LSB].
const CURRENT_SCALE_A_PER_LSB: f32 = 3.3 / 4096.0 / 0.5;
/// Driver input span [V] of the output stage at full scale (DAC + op-amp stage: ±10 V; H-bridge:
/// the motor supply).
const OUTPUT_FULL_SCALE_V: f32 = 10.0;

/// The HAL: the board's peripherals.
struct NucleoHal {
    tx: Tx<pac::USART2>,
    qei: Qei<pac::TIM3>,
    /// Last 16-bit count of TIM3 and the 32-bit extension.
    enc_last: u16,
    enc_count: i32,
    adc: Adc<pac::ADC1>,
    current_pin: stm32f4xx_hal::gpio::PA0<stm32f4xx_hal::gpio::Analog>,
    current_offset_lsb: i32,
    out: Output,
    /// DWT cycles, extended to 64 bits by polling.
    cyc_last: u32,
    cycles: u64,
    restart: bool,
}

#[cfg(feature = "dac")]
struct Output {
    dac: stm32f4xx_hal::dac::C1,
}

#[cfg(feature = "dac")]
impl Output {
    fn set(&mut self, u_v: f32) {
        use stm32f4xx_hal::dac::DacOut;
        // 0 V at mid-scale; ±OUTPUT_FULL_SCALE_V at the ends.
        let x = (u_v / OUTPUT_FULL_SCALE_V).clamp(-1.0, 1.0);
        let code = 2048.0 + x * 2047.0;
        self.dac.set_value(code as u16);
    }
}

#[cfg(feature = "hbridge")]
struct Output {
    pwm: stm32f4xx_hal::timer::PwmChannel<pac::TIM1, 0>,
    dir: stm32f4xx_hal::gpio::PB5<stm32f4xx_hal::gpio::Output<stm32f4xx_hal::gpio::PushPull>>,
}

#[cfg(feature = "hbridge")]
impl Output {
    fn set(&mut self, u_v: f32) {
        // Sign-magnitude drive: duty = |u| / supply, direction pin = sign.
        let x = (u_v / OUTPUT_FULL_SCALE_V).clamp(-1.0, 1.0);
        if x < 0.0 {
            self.dir.set_high();
        } else {
            self.dir.set_low();
        }
        let max = self.pwm.get_max_duty() as f32;
        let mag = if x < 0.0 { -x } else { x };
        self.pwm.set_duty((mag * max) as u16);
    }
}

impl NucleoHal {
    fn now_us64(&mut self) -> u64 {
        let c = cortex_m::peripheral::DWT::cycle_count();
        self.cycles += c.wrapping_sub(self.cyc_last) as u64;
        self.cyc_last = c;
        self.cycles / (SYSCLK_HZ / 1_000_000) as u64
    }
    fn read_current_lsb(&mut self) -> i32 {
        self.adc.convert(&self.current_pin, SampleTime::Cycles_56) as i32
    }
}

impl BoardHal for NucleoHal {
    fn now_us(&mut self) -> u32 {
        self.now_us64() as u32
    }
    fn encoder_count(&mut self) -> i32 {
        let c = self.qei.count();
        self.enc_count = self
            .enc_count
            .wrapping_add(c.wrapping_sub(self.enc_last) as i16 as i32);
        self.enc_last = c;
        self.enc_count
    }
    fn current_raw(&mut self) -> i16 {
        let lsb = self.read_current_lsb() - self.current_offset_lsb;
        lsb.clamp(i16::MIN as i32, i16::MAX as i32) as i16
    }
    fn set_voltage(&mut self, u_v: f32) {
        self.out.set(u_v);
    }
    fn restart_tick(&mut self) {
        self.restart = true;
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            // 26 bytes at 921 600 baud: 0.28 ms, within the 1 ms period.
            let _ = nb::block!(self.tx.write(b));
        }
    }
}

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        #[allow(clippy::empty_loop)]
        loop {}
    };
    // The Nucleo's ST-LINK feeds an 8 MHz clock into OSC_IN (HSE bypass).
    let rcc = dp.RCC.constrain();
    let clocks = rcc
        .cfgr
        .use_hse(8.MHz())
        .bypass_hse_oscillator()
        .sysclk(SYSCLK_HZ.Hz())
        .freeze();
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();
    let _ = &gpiob;

    // Output stage first, at 0 V.
    #[cfg(feature = "dac")]
    let mut out = {
        use stm32f4xx_hal::dac::DacPin;
        let mut dac = dp.DAC.constrain(gpioa.pa4.into_analog());
        dac.enable();
        Output { dac }
    };
    #[cfg(feature = "hbridge")]
    let mut out = {
        let (_, (ch1, ..)) = dp.TIM1.pwm_hz(20.kHz(), &clocks);
        let mut pwm = ch1.with(gpioa.pa8);
        pwm.set_duty(0);
        pwm.enable();
        Output {
            pwm,
            dir: gpiob.pb5.into_push_pull_output(),
        }
    };
    out.set(0.0);

    let serial = dp
        .USART2
        .serial(
            (gpioa.pa2, gpioa.pa3),
            SerialConfig::default().baudrate(921_600.bps()),
            &clocks,
        )
        .unwrap_or_else(|_| loop {
            cortex_m::asm::wfi()
        });
    let (tx, mut rx): (Tx<pac::USART2>, Rx<pac::USART2>) = serial.split();

    let qei = Qei::new(dp.TIM3, (gpioa.pa6, gpioa.pa7));
    let adc = Adc::adc1(dp.ADC1, true, AdcConfig::default());
    let mut hal = NucleoHal {
        tx,
        enc_last: qei.count(),
        qei,
        enc_count: 0,
        adc,
        current_pin: gpioa.pa0.into_analog(),
        current_offset_lsb: 0,
        out,
        cyc_last: cortex_m::peripheral::DWT::cycle_count(),
        cycles: 0,
        restart: false,
    };
    // Current-sense offset at 0 V (the motor is not driven after reset).
    let mut sum = 0i32;
    for _ in 0..64 {
        sum += hal.read_current_lsb();
    }
    hal.current_offset_lsb = sum / 64;

    let cfg = BoardConfig {
        firmware: fixed_text("servo-f446re"),
        sample_period_us: SAMPLE_PERIOD_US,
        watchdog_ms: 50,
        limits: SafetyLimits::default(),
        counts_per_rev: COUNTS_PER_REV,
        current_scale_a_per_lsb: CURRENT_SCALE_A_PER_LSB,
    };
    let Ok(mut core) = BoardCore::new(cfg) else {
        #[allow(clippy::empty_loop)]
        loop {}
    };

    let mut next_tick = hal.now_us64() + SAMPLE_PERIOD_US as u64;
    loop {
        while let Ok(b) = rx.read() {
            core.receive(&mut hal, &[b]);
            if hal.restart {
                hal.restart = false;
                next_tick = hal.now_us64() + SAMPLE_PERIOD_US as u64;
            }
        }
        let now = hal.now_us64();
        if now >= next_tick {
            next_tick += SAMPLE_PERIOD_US as u64;
            // A late loop catches up one period at a time; never more than one period behind.
            if now > next_tick + SAMPLE_PERIOD_US as u64 {
                next_tick = now + SAMPLE_PERIOD_US as u64;
            }
            core.tick(&mut hal);
        }
    }
}
