//! The smart servo of a model file: `[drive] kind = "position"` (the firmware's position loop
//! drives a PWM bridge: `v_supply_v`, `duty_limit` of the `[drive]` table) with a
//! `[smart_servo]` table for the firmware and the gearbox:
//!
//! ```toml
//! [drive]
//! kind = "position"
//! v_supply_v = 7.4               # the supply where the log has no supply column
//! duty_limit = 1.0
//!
//! [smart_servo]
//! kp_fw = 100.0                  # the firmware's P gain in the vendor's units
//! duty_per_rad_per_kp = 2.877378e-3  # duty per rad of error per unit of kp_fw (Dynamixel X: 4096 / (2 pi 256 885))
//! encoder_counts = 4096          # the firmware's angle grid (omit: exact)
//! period_s = 0.001               # the firmware's loop period
//! latency_s = 0.012              # the firmware's and the bus's latency after the logged goal
//! supply_from_log = true         # use the log's supply column when it has one
//! load_friction = 0.1            # the gearbox's Coulomb friction grows by this fraction of the motor's torque
//! ```
//!
//! Everything else is the model's: `[params]` (J_eq, B_eq, tau_sf, k_t, k_e, R_a, N) and the
//! gravity of an arm as the catalogue's gravity effect (`servo_core::effects::GRAVITY`:
//! amplitude m g L, phase).

use crate::error::{self as anyhow, bail};
use servo_core::drive::Drive;
use servo_core::smart::{PositionLoop, SmartParams};

fn default_period_s() -> f64 {
    1e-3
}

/// The `[smart_servo]` table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct SmartServo {
    /// The firmware's proportional gain in the vendor's units.
    pub kp_fw: f64,
    /// Duty per rad of error per unit of kp_fw (the vendor's unit conversion).
    pub duty_per_rad_per_kp: f64,
    /// Counts per turn of the firmware's encoder (`None`: the angle is exact).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder_counts: Option<u32>,
    /// The firmware's loop period [s].
    #[serde(default = "default_period_s")]
    pub period_s: f64,
    /// The firmware's and the bus's latency between the logged goal and the loop [s].
    #[serde(default)]
    pub latency_s: f64,
    /// Use the log's supply column when it has one (else `[drive] v_supply_v`).
    #[serde(default)]
    pub supply_from_log: bool,
    /// The gearbox's load-dependent friction: the Coulomb friction grows by this fraction of
    /// the motor's torque [-].
    #[serde(default)]
    pub load_friction: f64,
}

impl SmartServo {
    /// Checks the values; `drive` is the `[drive]` of a position drive (its supply is required).
    pub fn validate(&self, drive: &Drive) -> anyhow::Result<()> {
        let checks = [
            ("kp_fw", self.kp_fw, self.kp_fw > 0.0),
            (
                "duty_per_rad_per_kp",
                self.duty_per_rad_per_kp,
                self.duty_per_rad_per_kp > 0.0,
            ),
            ("period_s", self.period_s, self.period_s > 0.0),
            (
                "latency_s",
                self.latency_s,
                (0.0..10.0).contains(&self.latency_s),
            ),
            (
                "load_friction",
                self.load_friction,
                (0.0..1.0).contains(&self.load_friction),
            ),
        ];
        for (key, v, ok) in checks {
            if !(ok && v.is_finite()) {
                bail!("[smart_servo] {key} = {v}: expected a positive finite number (latency_s >= 0, load_friction in [0, 1))");
            }
        }
        if self.encoder_counts == Some(0) {
            bail!("[smart_servo] encoder_counts = 0: expected the counts per turn (omit it for an exact angle)");
        }
        if drive.v_supply_v.is_none() {
            bail!("[drive] kind = \"position\" needs v_supply_v (the bridge's supply [V])");
        }
        Ok(())
    }

    /// The firmware's loop with the drive's supply and duty limit (`kp_fw` overrides the
    /// file's gain: a log taken at another gain).
    pub fn position_loop(&self, drive: &Drive, kp_fw: Option<f64>) -> PositionLoop {
        PositionLoop {
            kp_fw: kp_fw.unwrap_or(self.kp_fw),
            duty_per_rad_per_kp: self.duty_per_rad_per_kp,
            duty_limit: drive.duty_limit.unwrap_or(1.0),
            v_supply_v: drive.v_supply_v.unwrap_or(f64::NAN),
            supply_from_log: self.supply_from_log,
            encoder_counts: self.encoder_counts,
            period_s: self.period_s,
        }
    }

    /// The output-shaft parameters of a model's `plant` and `effects` with this table's latency
    /// and gearbox friction.
    pub fn params(
        &self,
        plant: &servo_core::PlantParams,
        effects: &servo_core::effects::Effects,
    ) -> SmartParams {
        SmartParams {
            load_friction: self.load_friction,
            ..SmartParams::from_model(plant, effects, self.latency_s)
        }
    }

    /// The `[smart_servo]` table with units and meanings in comments.
    pub fn toml_section(&self) -> String {
        let mut s =
            String::from("\n[smart_servo]  # the firmware's position loop and the gearbox\n");
        let rows: [(&str, f64, &str); 4] = [
            ("kp_fw", self.kp_fw, "the firmware's P gain [vendor units]"),
            (
                "duty_per_rad_per_kp",
                self.duty_per_rad_per_kp,
                "duty per rad of error per unit of kp_fw [1/rad]",
            ),
            ("period_s", self.period_s, "the firmware's loop period [s]"),
            (
                "latency_s",
                self.latency_s,
                "firmware and bus latency after the logged goal [s]",
            ),
        ];
        for (k, v, doc) in rows {
            s.push_str(&format!("{k} = {v:e}  # {doc}\n"));
        }
        if let Some(n) = self.encoder_counts {
            s.push_str(&format!(
                "encoder_counts = {n}  # the firmware's angle grid [counts/turn]\n"
            ));
        }
        s.push_str(&format!(
            "supply_from_log = {}  # the log's supply column drives the bridge when present\n\
             load_friction = {:e}  # the Coulomb friction grows by this fraction of the motor's torque [-]\n",
            self.supply_from_log, self.load_friction
        ));
        s
    }
}
