//! The drive between the controller's command and the motor: a linear voltage amplifier, a
//! current (torque) drive, or a PWM H-bridge / smart servo driven by a duty cycle.
//!
//! * `voltage`: the handout's linear amplifier, u_drv = k_drv u through the first-order lag
//!   T_drv (eq. 18). The command is a voltage u [V].
//! * `current`: the drive's own current loop makes the armature current follow the reference
//!   i_ref [A] through a first-order lag of `bandwidth_hz` (instant when absent), the reference
//!   clipped at `i_limit_a`. A command written as a voltage (an analog +-10 V input) is scaled
//!   by `k_i_a_per_v`. The motor torque is k_t i_a: there is no electrical balance to fit, and
//!   R_a, L_a, k_e, k_drv are neither needed nor refitted (the loop rejects the back-EMF; the
//!   supply's headroom is not modelled).
//! * `duty`: an H-bridge switching the supply: u = d V_supply - R_supply i_a - V_dead, with the
//!   duty d in [-1, 1] clipped at `duty_limit`, the supply V_supply from a `v_supply` column or
//!   `v_supply_v`, its sag through the supply's resistance R_supply (in series with the
//!   armature), and the dead-time loss V_dead = V_supply t_dead f_pwm with the sign of the
//!   duty (the sign of the current in steady drive).
//!
//! Every drive is computed as an *equivalent voltage chain*: the simulator, the fits and the
//! design work on eqs. 18-20 with the drive's equivalent constants ([`Drive::equivalent`]) and
//! the drive's command turned into the chain's input ([`Drive::input`]). For a current drive
//! the chain is a current source: k_drv = R_eq = [`CURRENT_EQ_OHM`], L_a = R_eq / (2 pi
//! bandwidth), k_e = the smallest sensible value (its back-EMF current k_e w / R_eq is below
//! 2e-9 w A), so i_a follows k_drv i_ref / R_eq = i_ref with the loop's lag; for a duty drive
//! k_drv = 1 V/V with no driver lag and R_eq = R_a + R_s + R_supply. The chain's input is then
//! the current reference [A] or the bridge's effective voltage [V].

use crate::math;
use crate::params::PlantParams;
#[cfg(feature = "alloc")]
use crate::record::Record;
#[cfg(feature = "alloc")]
use alloc::{format, string::String, vec::Vec};

/// Resistance and gain of a current drive's equivalent chain [ohm], [V/V]: large, so that the
/// back-EMF of the smallest sensible k_e moves the current by 2e-9 A per rad/s at most, and
/// within the sensible range with the fits' drive-constant tolerance on top.
pub const CURRENT_EQ_OHM: f64 = 500.0;

/// The current loop's lag when no bandwidth is given [s] ("instant").
pub const INSTANT_S: f64 = 1e-6;

/// Cut-off of the equivalent chain's driver where a drive has no driver lag [Hz].
pub const NO_LAG_HZ: f64 = 1e6;

/// The kind of drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DriveKind {
    /// A linear voltage amplifier (k_drv, T_drv): the command is a voltage u [V].
    #[default]
    Voltage,
    /// A current (torque) drive: the command is a current reference i_ref [A].
    Current,
    /// A PWM H-bridge or smart servo: the command is a duty cycle in [-1, 1].
    Duty,
}

impl DriveKind {
    /// The name in the model file's `[drive] kind`.
    pub const fn name(self) -> &'static str {
        match self {
            DriveKind::Voltage => "voltage",
            DriveKind::Current => "current",
            DriveKind::Duty => "duty",
        }
    }
    /// The log signal that carries this drive's command (`u`, `i_ref`, `duty`).
    pub const fn input_signal(self) -> &'static str {
        match self {
            DriveKind::Voltage => "u",
            DriveKind::Current => "i_ref",
            DriveKind::Duty => "duty",
        }
    }
    /// The unit of the command (and of the controller's output).
    pub const fn command_unit(self) -> &'static str {
        match self {
            DriveKind::Voltage => "V",
            DriveKind::Current => "A",
            DriveKind::Duty => "duty (fraction)",
        }
    }
}

/// Why a drive description was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriveError {
    /// A value is not a finite number in its range.
    #[error("[drive] `{key}` must be {what}, got {}", math::Num(*.value))]
    BadValue {
        key: &'static str,
        what: &'static str,
        value: f64,
    },
    /// A key that the drive kind does not use.
    #[error("[drive] `{key}` is not a parameter of a {kind} drive (a {kind} drive takes {takes})")]
    NotUsed {
        key: &'static str,
        kind: &'static str,
        takes: &'static str,
    },
    /// A parameter of `[params]` the drive needs is missing.
    #[error("[params] `{key}` is missing: a {kind} drive needs it ({why})")]
    Missing {
        key: &'static str,
        kind: &'static str,
        why: &'static str,
    },
    /// A parameter of `[params]` the drive does not use was given.
    #[error("[params] `{key}` is not used by a {kind} drive ({why}): remove it")]
    Unused {
        key: &'static str,
        kind: &'static str,
        why: &'static str,
    },
    /// The log's input column does not match the drive.
    #[cfg(feature = "alloc")]
    #[error("{log}: {why}")]
    Input { log: String, why: String },
}

/// A drive: its kind and parameters (SI units; unused ones `None`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Drive {
    pub kind: DriveKind,
    /// Current drive: the current loop's bandwidth [Hz] (instant when `None`).
    pub bandwidth_hz: Option<f64>,
    /// Current drive: the limit of the current reference [A] (none when `None`).
    pub i_limit_a: Option<f64>,
    /// Current drive commanded by a voltage: amps of reference per volt of command [A/V].
    pub k_i_a_per_v: Option<f64>,
    /// Duty drive: the supply voltage [V] when the log has no `v_supply` column.
    pub v_supply_v: Option<f64>,
    /// Duty drive: the supply's internal resistance [ohm] (its sag R_supply i_a); 0 when `None`.
    pub r_supply_ohm: Option<f64>,
    /// Duty drive: the bridge's dead time [s] (with `f_pwm_hz`).
    pub t_dead_s: Option<f64>,
    /// Duty drive: the PWM frequency [Hz] (with `t_dead_s`).
    pub f_pwm_hz: Option<f64>,
    /// Duty drive: the largest duty magnitude the bridge applies (1 when `None`).
    pub duty_limit: Option<f64>,
}

/// The `[params]` keys of the voltage chain that a drive may not use, with why.
const CURRENT_UNUSED: [(&str, &str); 6] = [
    ("r_a", "its current loop sets the current"),
    (
        "l_a",
        "its current loop sets the current's lag: give [drive] bandwidth_hz",
    ),
    ("k_e", "its current loop rejects the back-EMF"),
    ("k_drv", "its command is the current reference"),
    ("f_c_drv", "give the current loop's [drive] bandwidth_hz"),
    ("r_s", "its current loop sets the current"),
];

impl Drive {
    /// Today's linear voltage amplifier.
    pub const VOLTAGE: Drive = Drive {
        kind: DriveKind::Voltage,
        bandwidth_hz: None,
        i_limit_a: None,
        k_i_a_per_v: None,
        v_supply_v: None,
        r_supply_ohm: None,
        t_dead_s: None,
        f_pwm_hz: None,
        duty_limit: None,
    };

    /// A current drive of bandwidth `bandwidth_hz` (instant when `None`), no limit.
    pub fn current(bandwidth_hz: Option<f64>) -> Drive {
        Drive {
            kind: DriveKind::Current,
            bandwidth_hz,
            ..Drive::VOLTAGE
        }
    }

    /// A duty drive on a supply of `v_supply_v` with internal resistance `r_supply_ohm`.
    pub fn duty(v_supply_v: Option<f64>, r_supply_ohm: Option<f64>) -> Drive {
        Drive {
            kind: DriveKind::Duty,
            v_supply_v,
            r_supply_ohm,
            ..Drive::VOLTAGE
        }
    }

    /// The parameters as (key, value), in the model file's order.
    pub fn values(&self) -> [(&'static str, Option<f64>); 8] {
        [
            ("bandwidth_hz", self.bandwidth_hz),
            ("i_limit_a", self.i_limit_a),
            ("k_i_a_per_v", self.k_i_a_per_v),
            ("v_supply_v", self.v_supply_v),
            ("r_supply_ohm", self.r_supply_ohm),
            ("t_dead_s", self.t_dead_s),
            ("f_pwm_hz", self.f_pwm_hz),
            ("duty_limit", self.duty_limit),
        ]
    }

    /// The `[drive]` keys this kind takes.
    pub const fn takes(kind: DriveKind) -> &'static str {
        match kind {
            DriveKind::Voltage => "no parameters: its k_drv and f_c_drv are in [params]",
            DriveKind::Current => "bandwidth_hz, i_limit_a, k_i_a_per_v",
            DriveKind::Duty => "v_supply_v, r_supply_ohm, t_dead_s, f_pwm_hz, duty_limit",
        }
    }

    /// Checks the values and that each given key belongs to the kind.
    pub fn validate(&self) -> Result<(), DriveError> {
        let kind = self.kind;
        for (key, v) in self.values() {
            let Some(v) = v else { continue };
            let belongs = match kind {
                DriveKind::Voltage => false,
                DriveKind::Current => {
                    matches!(key, "bandwidth_hz" | "i_limit_a" | "k_i_a_per_v")
                }
                DriveKind::Duty => !matches!(key, "bandwidth_hz" | "i_limit_a" | "k_i_a_per_v"),
            };
            if !belongs {
                return Err(DriveError::NotUsed {
                    key,
                    kind: kind.name(),
                    takes: Drive::takes(kind),
                });
            }
            let (ok, what) = match key {
                "r_supply_ohm" | "t_dead_s" => ((0.0..1e4).contains(&v), "a finite number >= 0"),
                "duty_limit" => (v > 0.0 && v <= 1.0, "a fraction in (0, 1]"),
                "bandwidth_hz" => (v > 0.0 && v < 1e7, "a positive frequency in Hz"),
                _ => (v > 0.0 && v < 1e6, "a positive finite number"),
            };
            if !(ok && v.is_finite()) {
                return Err(DriveError::BadValue {
                    key,
                    what,
                    value: v,
                });
            }
        }
        if kind == DriveKind::Duty && self.t_dead_s.is_some() != self.f_pwm_hz.is_some() {
            return Err(DriveError::BadValue {
                key: if self.t_dead_s.is_some() {
                    "f_pwm_hz"
                } else {
                    "t_dead_s"
                },
                what: "given with the other (the dead-time loss is V_supply t_dead_s f_pwm_hz)",
                value: f64::NAN,
            });
        }
        Ok(())
    }

    /// The `[params]` keys of the voltage chain this drive does not use, with why
    /// (a current drive: R_a, L_a, k_e, k_drv, f_c_drv, R_s).
    pub fn unused_params(&self) -> &'static [(&'static str, &'static str)] {
        match self.kind {
            DriveKind::Current => &CURRENT_UNUSED,
            _ => &[],
        }
    }

    /// The `[params]` keys this drive may leave out, with the value they default to (a duty
    /// drive: k_drv = 1, f_c_drv = [`NO_LAG_HZ`], r_s = 0).
    ///
    /// (A current or duty drive's file may also leave out the datasheet's split of the
    /// mechanics, B_m, B_l, J_72, J_d = 0, when it gives J_eq; J_m then defaults to J_eq.)
    pub fn optional_params(&self) -> &'static [(&'static str, f64)] {
        match self.kind {
            DriveKind::Duty => &[
                ("k_drv", 1.0),
                ("f_c_drv", NO_LAG_HZ),
                ("r_s", 0.0),
                ("b_m", 0.0),
                ("b_l", 0.0),
                ("j_72", 0.0),
                ("j_d", 0.0),
            ],
            DriveKind::Current => &[("b_m", 0.0), ("b_l", 0.0), ("j_72", 0.0), ("j_d", 0.0)],
            DriveKind::Voltage => &[],
        }
    }

    /// The drive whose log signal and unit carry this drive's command
    /// ([`DriveKind::input_signal`], [`DriveKind::command_unit`]): its own kind, except a
    /// current drive commanded by an analog voltage (`k_i_a_per_v`), whose command is a voltage
    /// u [V] as [`Drive::prepare`] reads it.
    pub fn command_kind(&self) -> DriveKind {
        match self.kind {
            DriveKind::Current if self.k_i_a_per_v.is_some() => DriveKind::Voltage,
            k => k,
        }
    }

    /// The range of the equivalent chain's input, where the drive itself clips: a duty drive's
    /// whole bridge, duty_limit x V_supply [V]; a current drive's limit i_limit_a [A]; `None`
    /// for a voltage amplifier (its input range is the board's or the simulator's, 10 V) and a
    /// current drive without a limit. A simulator of the chain takes it as its input limit, and
    /// a loop on the drive as its default output limit, instead of an amplifier's 10 V.
    pub fn input_range(&self) -> Option<f64> {
        match self.kind {
            DriveKind::Duty => self.v_supply_v.map(|v| v * self.duty_limit.unwrap_or(1.0)),
            DriveKind::Current => self.i_limit_a,
            DriveKind::Voltage => None,
        }
    }

    /// The current loop's time constant [s] (current drive).
    pub fn loop_lag_s(&self) -> f64 {
        self.bandwidth_hz
            .map_or(INSTANT_S, |f| 1.0 / (math::TAU * f))
    }

    /// The supply's internal resistance [ohm] (0 when not given).
    pub fn r_supply(&self) -> f64 {
        self.r_supply_ohm.unwrap_or(0.0)
    }

    /// The constants of the equivalent voltage chain (see the module) from the parameters as
    /// the model file gives them. A voltage drive returns `p` unchanged; a current drive
    /// replaces R_a, R_s, L_a, k_e, k_drv, f_c_drv by its current source; a duty drive adds
    /// R_supply to R_s.
    pub fn equivalent(&self, p: &PlantParams) -> PlantParams {
        match self.kind {
            DriveKind::Voltage => *p,
            DriveKind::Current => {
                let lag = self.loop_lag_s();
                // L_a <= 10 H (its sensible range): a slower loop gets a smaller R_eq.
                let r = CURRENT_EQ_OHM.min(9.9 / lag);
                PlantParams {
                    r_a: r,
                    r_s: 0.0,
                    l_a: r * lag,
                    k_e: 1e-6,
                    k_drv: r,
                    f_c_drv: NO_LAG_HZ,
                    ..*p
                }
            }
            DriveKind::Duty => PlantParams {
                r_s: p.r_s + self.r_supply(),
                ..*p
            },
        }
    }

    /// The parameters as the model file writes them (the inverse of [`Drive::equivalent`] for
    /// the keys the drive uses; the unused keys of a current drive are not written).
    pub fn written(&self, p: &PlantParams) -> PlantParams {
        match self.kind {
            DriveKind::Duty => PlantParams {
                r_s: (p.r_s - self.r_supply()).max(0.0),
                ..*p
            },
            _ => *p,
        }
    }

    /// The dead-time loss of a duty drive as a fraction of the supply (t_dead f_pwm; 0 without).
    pub fn dead_fraction(&self) -> f64 {
        match (self.t_dead_s, self.f_pwm_hz) {
            (Some(t), Some(f)) => t * f,
            _ => 0.0,
        }
    }

    /// The equivalent chain's input for one command of the drive: the voltage u itself; the
    /// current reference (`command` in A, or in V times k_i_a_per_v) clipped at i_limit_a; the
    /// bridge's effective voltage d V_supply - V_dead sign(d) with d clipped at duty_limit.
    /// `v_supply_v` is the supply of this sample (duty drive; ignored otherwise).
    pub fn input(&self, command: f64, v_supply_v: f64) -> f64 {
        match self.kind {
            DriveKind::Voltage => command,
            DriveKind::Current => {
                let i = command * self.k_i_a_per_v.unwrap_or(1.0);
                match self.i_limit_a {
                    Some(l) => i.clamp(-l, l),
                    None => i,
                }
            }
            DriveKind::Duty => {
                let l = self.duty_limit.unwrap_or(1.0);
                let d = command.clamp(-l, l);
                let dead = if d > 0.0 {
                    self.dead_fraction()
                } else if d < 0.0 {
                    -self.dead_fraction()
                } else {
                    0.0
                };
                v_supply_v * (d - dead)
            }
        }
    }

    #[cfg(feature = "alloc")]
    /// Turns a log of this drive's command into the equivalent chain's log: `u_v` holds the
    /// chain's input ([`Drive::input`] of each row). A voltage drive needs `u`; a current drive
    /// `i_ref` (or `u` with k_i_a_per_v); a duty drive `duty` and its supply (a `v_supply`
    /// column or v_supply_v). A current drive's measured current is dropped: the reference is
    /// its input, and the equivalent chain's electrical balance is not the drive's. A log whose
    /// input is another drive's is refused, naming both.
    pub fn prepare(&self, rec: &mut Record) -> Result<(), DriveError> {
        let err = |why: String| DriveError::Input {
            log: rec.source.clone(),
            why,
        };
        let kind = self.kind;
        let has = [
            ("u", rec.u_v.is_some()),
            ("i_ref", rec.i_ref_a.is_some()),
            ("duty", rec.duty.is_some()),
        ];
        let given: Vec<&str> = has.iter().filter(|h| h.1).map(|h| h.0).collect();
        let foreign = |s: &str| -> Option<&'static str> {
            match s {
                "i_ref" => Some("a current drive's reference"),
                "duty" => Some("a duty drive's command"),
                _ => Some("a voltage drive's command"),
            }
        };
        let mismatch = |s: &str| {
            err(format!(
                "the log's input is `{s}` ({}) but the model's drive is `{}` (its input is `{}` in {}): \
                 give the model file of the log's drive ([drive] kind = ...) or the drive's input column",
                foreign(s).unwrap_or(""),
                kind.name(),
                kind.input_signal(),
                kind.command_unit()
            ))
        };
        match kind {
            DriveKind::Voltage => {
                if rec.u_v.is_none() {
                    if let Some(s) = given.first() {
                        return Err(mismatch(s));
                    }
                }
                if let Some(s) = given.iter().find(|s| **s != "u") {
                    if rec.u_v.is_some() {
                        return Err(err(format!(
                            "the log has both `u` and `{s}`: a voltage drive's input is `u` only"
                        )));
                    }
                }
            }
            DriveKind::Current => {
                if rec.duty.is_some() {
                    return Err(mismatch("duty"));
                }
                let cmd = match (rec.i_ref_a.take(), rec.u_v.take()) {
                    (Some(i), None) => i
                        .iter()
                        .map(|&i| {
                            let l = self.i_limit_a.unwrap_or(f64::INFINITY);
                            i.clamp(-l, l)
                        })
                        .collect(),
                    (None, Some(u)) => {
                        if self.k_i_a_per_v.is_none() {
                            return Err(err(String::from(
                                "the log's input is `u` (a voltage) but the model's drive is `current`: \
                                 give the current reference as `i_ref=<column>:A`, or [drive] k_i_a_per_v \
                                 when the command is a voltage scaled to amps",
                            )));
                        }
                        u.iter().map(|&u| self.input(u, 0.0)).collect()
                    }
                    (Some(_), Some(_)) => return Err(err(String::from(
                        "the log has both `u` and `i_ref`: a current drive's input is one of them",
                    ))),
                    (None, None) => return Ok(()),
                };
                rec.u_v = Some(cmd);
                rec.i_a_a = None;
            }
            DriveKind::Duty => {
                if rec.i_ref_a.is_some() {
                    return Err(mismatch("i_ref"));
                }
                let Some(d) = rec.duty.take() else {
                    if rec.u_v.is_some() {
                        return Err(mismatch("u"));
                    }
                    return Ok(());
                };
                if rec.u_v.is_some() {
                    return Err(err(String::from(
                        "the log has both `u` and `duty`: a duty drive's input is `duty`",
                    )));
                }
                let supply: Vec<f64> = match (&rec.v_supply_v, self.v_supply_v) {
                    (Some(v), _) => v.clone(),
                    (None, Some(v)) => alloc::vec![v; d.len()],
                    (None, None) => return Err(err(String::from(
                        "a duty drive needs its supply voltage: a `v_supply=<column>:V` column or \
                             [drive] v_supply_v",
                    ))),
                };
                rec.u_v = Some(
                    d.iter()
                        .zip(&supply)
                        .map(|(&d, &v)| self.input(d, v))
                        .collect(),
                );
            }
        }
        Ok(())
    }

    /// A controller's output in the equivalent chain's input units (V or A) turned into this
    /// drive's command units: per volt of the chain, 1 / V_supply of duty (duty drive); amps
    /// stay amps (current drive, a voltage command divides by k_i_a_per_v); volts stay volts.
    pub fn command_per_input(&self) -> f64 {
        match self.kind {
            DriveKind::Voltage => 1.0,
            DriveKind::Current => 1.0 / self.k_i_a_per_v.unwrap_or(1.0),
            DriveKind::Duty => 1.0 / self.v_supply_v.unwrap_or(f64::NAN),
        }
    }
}

#[cfg(all(test, feature = "alloc"))]
mod tests {
    use super::*;
    use alloc::string::String;

    fn motor() -> PlantParams {
        PlantParams {
            r_a: 1.2,
            l_a: 0.4e-3,
            k_e: 0.05,
            k_t: 0.05,
            j_m: 2e-5,
            n: 5.0,
            r_s: 0.0,
            ..PlantParams::TABLE2
        }
    }

    #[test]
    fn a_current_drive_is_a_current_source_with_the_loop_lag() {
        let d = Drive::current(Some(500.0));
        let e = d.equivalent(&motor());
        e.validate().unwrap();
        // i_ss = k_drv i_ref / R_eq = i_ref; lag L_a / R_eq = 1 / (2 pi 500 Hz).
        assert_eq!(e.k_drv / e.r_eq(), 1.0);
        assert!((e.l_a / e.r_eq() - 1.0 / (math::TAU * 500.0)).abs() < 1e-12);
        // The back-EMF current at 1000 rad/s is 2e-6 A at most.
        assert!(e.k_e * 1000.0 / e.r_eq() <= 2.000_001e-6);
        // The fits' drive-constant tolerance keeps k_drv in its sensible range.
        PlantParams {
            k_drv: e.k_drv * 1.1,
            r_a: e.r_a * 1.1,
            ..e
        }
        .validate()
        .unwrap();
        assert_eq!(e.k_t, 0.05);
        // A slow loop stays within L_a's sensible range.
        Drive::current(Some(0.5))
            .equivalent(&motor())
            .validate()
            .unwrap();
        Drive::current(None)
            .equivalent(&motor())
            .validate()
            .unwrap();
    }

    #[test]
    fn a_duty_drive_applies_supply_sag_dead_time_and_limit() {
        let d = Drive {
            t_dead_s: Some(1e-6),
            f_pwm_hz: Some(20e3),
            duty_limit: Some(0.9),
            ..Drive::duty(Some(12.0), Some(0.3))
        };
        d.validate().unwrap();
        // 0.5 x 12 V minus 12 V x 1e-6 s x 20 kHz = 6 - 0.24 V
        assert!((d.input(0.5, 12.0) - 5.76).abs() < 1e-12);
        assert!((d.input(-2.0, 12.0) + (0.9 - 0.02) * 12.0).abs() < 1e-12);
        assert_eq!(d.input(0.0, 12.0), 0.0);
        let e = d.equivalent(&motor());
        assert!((e.r_eq() - 1.5).abs() < 1e-12);
        assert!((d.written(&e).r_s - 0.0).abs() < 1e-12);
    }

    #[test]
    fn keys_of_another_drive_and_bad_values_are_refused() {
        let bad = Drive {
            bandwidth_hz: Some(100.0),
            ..Drive::duty(Some(12.0), None)
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("bandwidth_hz") && e.contains("duty"), "{e}");
        let bad = Drive {
            duty_limit: Some(1.5),
            ..Drive::duty(Some(12.0), None)
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("duty_limit"));
        let bad = Drive {
            i_limit_a: Some(-1.0),
            ..Drive::current(None)
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("i_limit_a"));
        let bad = Drive {
            t_dead_s: Some(1e-6),
            ..Drive::duty(Some(12.0), None)
        };
        assert!(bad.validate().unwrap_err().to_string().contains("f_pwm_hz"));
    }

    #[test]
    fn a_log_of_another_drive_is_refused() {
        let mut rec = Record {
            source: String::from("run.csv"),
            time_s: alloc::vec![0.0, 0.001],
            i_ref_a: Some(alloc::vec![0.5, 3.0]),
            i_a_a: Some(alloc::vec![0.4, 0.5]),
            ..Record::default()
        };
        let e = Drive::VOLTAGE
            .prepare(&mut rec.clone())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("run.csv") && e.contains("i_ref") && e.contains("voltage"),
            "{e}"
        );
        let e = Drive::duty(Some(12.0), None)
            .prepare(&mut rec.clone())
            .unwrap_err()
            .to_string();
        assert!(e.contains("i_ref") && e.contains("duty"), "{e}");
        let d = Drive {
            i_limit_a: Some(2.0),
            ..Drive::current(None)
        };
        d.prepare(&mut rec).unwrap();
        assert_eq!(rec.u_v, Some(alloc::vec![0.5, 2.0]));
        assert!(rec.i_a_a.is_none() && rec.i_ref_a.is_none());
        // A duty log without its supply.
        let mut rec = Record {
            source: String::from("servo.csv"),
            time_s: alloc::vec![0.0],
            duty: Some(alloc::vec![0.5]),
            ..Record::default()
        };
        let e = Drive::duty(None, None)
            .prepare(&mut rec.clone())
            .unwrap_err()
            .to_string();
        assert!(e.contains("v_supply"), "{e}");
        rec.v_supply_v = Some(alloc::vec![11.0]);
        Drive::duty(None, None).prepare(&mut rec).unwrap();
        assert_eq!(rec.u_v, Some(alloc::vec![5.5]));
    }
}
