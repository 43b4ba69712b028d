//! The model file (TOML): plant parameters, active effects, simulator sensors and provenance.
//!
//! One format serves `--params`, `--plant` (the simulator's truth), `--model` (compare/diagnose)
//! and the output of `identify` and `compare --save`:
//!
//! ```toml
//! [params]            # every Table 2 key is required; j_eq, b_eq, tau_sf are optional overrides
//! r_a = 2.6           # ohm
//! ...
//! [effects.<name>]    # registered effects, keys as in the registry (SI units)
//! gap = 0.04
//! [transmission]      # optional: gear (default), screw or belt, and the encoder's place
//! kind = "screw"      # "gear" | "screw" | "belt" ("rack" is a belt)
//! lead_m = 0.01       # screw: travel per screw revolution [m]; belt: radius_m [m]
//! encoder = "motor"   # "load" (default) | "motor" | "both"
//! m_eq_kg = 5.3       # linear axis: total mass at the load [kg] (in place of [params] j_eq)
//! b_eq_n_s_m = 40     # viscous friction [N s/m] (in place of b_eq)
//! f_c_n = 12          # Coulomb friction [N] (in place of tau_sf)
//! [sensors]           # optional, simulator only
//! counts_per_rev = 4096
//! [provenance]        # optional, free-form: where identified values came from
//! [limits]            # optional: maintenance limits `servo trend` forecasts the crossing of
//! tau_sf = 0.02       # a base parameter [its SI unit], or an effect's: "<effect>.<key>" = v
//! ```

use crate::error::{self as anyhow, anyhow, bail, Context};
use servo_core::custom::CustomSlots;
use servo_core::drive::{Drive, DriveKind};
use servo_core::effects::{Effect, EffectKind, Effects};
use servo_core::sim::SensorConfig;
use servo_core::transmission::{EncoderSide, Transmission, TransmissionKind};
use servo_core::{Plant, PlantParams};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Clone, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    params: RawParams,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    drive: Option<RawDrive>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    smart_servo: Option<crate::smart_model::SmartServo>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    effects: BTreeMap<String, BTreeMap<String, f64>>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    custom: BTreeMap<String, crate::effects_file::RawCustom>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    transmission: Option<RawTransmission>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sensors: Option<SensorConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    provenance: Option<toml::Table>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    limits: Option<toml::Table>,
}

/// `[params]` as written: every key optional here; which are required depends on the drive
/// ([`ModelFile::from_raw`]: a voltage drive needs every Table 2 key, a current drive neither
/// R_a, L_a, k_e, k_drv, f_c_drv nor R_s). Keys and their unit-suffixed aliases as in
/// [`PlantParams`].
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct RawParams {
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "r_a_ohm")]
    r_a: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "l_a_h")]
    l_a: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        alias = "k_e_v_s_rad"
    )]
    k_e: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "k_t_n_m_a")]
    k_t: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "j_m_kg_m2")]
    j_m: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        alias = "b_m_n_m_s_rad"
    )]
    b_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "j_72_kg_m2")]
    j_72: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "j_d_kg_m2")]
    j_d: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        alias = "b_l_n_m_s_rad"
    )]
    b_l: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    k_drv: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "f_c_drv_hz")]
    f_c_drv: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "r_s_ohm")]
    r_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "j_eq_kg_m2")]
    j_eq: Option<f64>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        alias = "b_eq_n_m_s_rad"
    )]
    b_eq: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none", alias = "tau_sf_n_m")]
    tau_sf: Option<f64>,
}

/// Why a [params] key is needed, for the error naming it.
fn why_needed(key: &str) -> &'static str {
    match key {
        "r_a" | "l_a" | "r_s" => "the armature circuit it drives",
        "k_e" => "the back-EMF its voltage works against",
        "k_t" => "the motor torque k_t i_a",
        "k_drv" | "f_c_drv" => "the voltage amplifier's gain and lag",
        "n" => "the gear ratio between motor and load",
        _ => "the mechanics",
    }
}

impl RawParams {
    /// The parameters of `drive` (its equivalent voltage chain, [`Drive::equivalent`]): every
    /// key the drive needs present, none it does not use.
    fn params(&self, drive: &Drive) -> anyhow::Result<PlantParams> {
        let kind = drive.kind.name();
        for (key, why) in drive.unused_params() {
            if self.get(key).is_some() {
                bail!(
                    "{}",
                    servo_core::drive::DriveError::Unused { key, kind, why }
                );
            }
        }
        let unused = |k: &str| drive.unused_params().iter().any(|(u, _)| *u == k);
        let optional = |k: &str| {
            drive
                .optional_params()
                .iter()
                .find(|(o, _)| *o == k)
                .map(|o| o.1)
        };
        let base = PlantParams::TABLE2;
        let need = |key: &'static str, dflt: f64| -> anyhow::Result<f64> {
            match self.get(key) {
                Some(v) => Ok(v),
                None if unused(key) => Ok(dflt),
                None => optional(key).ok_or_else(|| {
                    anyhow!(
                        "{}",
                        servo_core::drive::DriveError::Missing {
                            key,
                            kind,
                            why: why_needed(key)
                        }
                    )
                }),
            }
        };
        let p = PlantParams {
            r_a: need("r_a", base.r_a)?,
            l_a: need("l_a", base.l_a)?,
            k_e: need("k_e", base.k_e)?,
            k_t: need("k_t", base.k_t)?,
            j_m: match (self.j_m, self.j_eq, drive.kind) {
                (None, Some(j), DriveKind::Current | DriveKind::Duty) => j,
                _ => need("j_m", base.j_m)?,
            },
            b_m: need("b_m", base.b_m)?,
            n: need("n", base.n)?,
            j_72: need("j_72", base.j_72)?,
            j_d: need("j_d", base.j_d)?,
            b_l: need("b_l", base.b_l)?,
            k_drv: need("k_drv", base.k_drv)?,
            f_c_drv: need("f_c_drv", base.f_c_drv)?,
            r_s: need("r_s", base.r_s)?,
            j_eq: self.j_eq,
            b_eq: self.b_eq,
            tau_sf: self.tau_sf,
        };
        Ok(drive.equivalent(&p))
    }

    fn get(&self, key: &str) -> Option<f64> {
        match key {
            "r_a" => self.r_a,
            "l_a" => self.l_a,
            "k_e" => self.k_e,
            "k_t" => self.k_t,
            "j_m" => self.j_m,
            "b_m" => self.b_m,
            "n" => self.n,
            "j_72" => self.j_72,
            "j_d" => self.j_d,
            "b_l" => self.b_l,
            "k_drv" => self.k_drv,
            "f_c_drv" => self.f_c_drv,
            "r_s" => self.r_s,
            _ => None,
        }
    }

    /// The table written for `p` (equivalent chain constants) on `drive`: the keys the drive
    /// does not use are left out.
    fn of(p: &PlantParams, drive: &Drive) -> RawParams {
        let w = drive.written(p);
        let keep = |k: &str, v: f64| {
            let unused = drive.unused_params().iter().any(|(u, _)| *u == k);
            let default = drive
                .optional_params()
                .iter()
                .any(|(o, d)| *o == k && *d == v);
            (!unused && !default).then_some(v)
        };
        RawParams {
            r_a: keep("r_a", w.r_a),
            l_a: keep("l_a", w.l_a),
            k_e: keep("k_e", w.k_e),
            k_t: Some(w.k_t),
            j_m: Some(w.j_m),
            b_m: keep("b_m", w.b_m),
            n: Some(w.n),
            j_72: keep("j_72", w.j_72),
            j_d: keep("j_d", w.j_d),
            b_l: keep("b_l", w.b_l),
            k_drv: keep("k_drv", w.k_drv),
            f_c_drv: keep("f_c_drv", w.f_c_drv),
            r_s: keep("r_s", w.r_s),
            j_eq: w.j_eq,
            b_eq: w.b_eq,
            tau_sf: w.tau_sf,
        }
    }
}

/// `kind` of a `[drive]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
enum RawDriveKind {
    #[default]
    Voltage,
    Current,
    Duty,
    /// A smart servo: the firmware's position loop drives a PWM bridge (a duty drive) from the
    /// goal position; its firmware in `[smart_servo]` ([`crate::smart_model`]).
    Position,
}

/// The `[drive]` table as written ([`servo_core::drive`]).
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct RawDrive {
    #[serde(default)]
    kind: RawDriveKind,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bandwidth_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    i_limit_a: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    k_i_a_per_v: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    v_supply_v: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    r_supply_ohm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    t_dead_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    f_pwm_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    duty_limit: Option<f64>,
}

impl RawDrive {
    fn drive(&self) -> anyhow::Result<Drive> {
        let d = Drive {
            kind: match self.kind {
                RawDriveKind::Voltage => DriveKind::Voltage,
                RawDriveKind::Current => DriveKind::Current,
                RawDriveKind::Duty | RawDriveKind::Position => DriveKind::Duty,
            },
            bandwidth_hz: self.bandwidth_hz,
            i_limit_a: self.i_limit_a,
            k_i_a_per_v: self.k_i_a_per_v,
            v_supply_v: self.v_supply_v,
            r_supply_ohm: self.r_supply_ohm,
            t_dead_s: self.t_dead_s,
            f_pwm_hz: self.f_pwm_hz,
            duty_limit: self.duty_limit,
        };
        d.validate().map_err(|e| anyhow!("{e}"))?;
        Ok(d)
    }

    fn of(d: &Drive) -> Option<RawDrive> {
        (*d != Drive::VOLTAGE).then_some(RawDrive {
            kind: match d.kind {
                DriveKind::Voltage => RawDriveKind::Voltage,
                DriveKind::Current => RawDriveKind::Current,
                DriveKind::Duty => RawDriveKind::Duty,
            },
            bandwidth_hz: d.bandwidth_hz,
            i_limit_a: d.i_limit_a,
            k_i_a_per_v: d.k_i_a_per_v,
            v_supply_v: d.v_supply_v,
            r_supply_ohm: d.r_supply_ohm,
            t_dead_s: d.t_dead_s,
            f_pwm_hz: d.f_pwm_hz,
            duty_limit: d.duty_limit,
        })
    }
}

/// `kind` of a `[transmission]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
enum RawKind {
    #[default]
    Gear,
    Screw,
    #[serde(alias = "rack")]
    Belt,
}

/// `encoder` of a `[transmission]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
enum RawEncoder {
    #[default]
    Load,
    Motor,
    Both,
}

/// The `[transmission]` table as written. A linear axis' mass, viscous and Coulomb friction
/// live here, in linear units, in place of `[params]` j_eq, b_eq, tau_sf: each quantity once.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct RawTransmission {
    #[serde(default)]
    kind: RawKind,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    lead_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    radius_m: Option<f64>,
    #[serde(default)]
    encoder: RawEncoder,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    m_eq_kg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    b_eq_n_s_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    f_c_n: Option<f64>,
}

impl RawTransmission {
    /// The transmission, its lead or radius checked.
    fn transmission(&self) -> anyhow::Result<Transmission> {
        let kind = match (self.kind, self.lead_m, self.radius_m) {
            (RawKind::Gear, None, None) => TransmissionKind::Gear,
            (RawKind::Screw, Some(lead_m), None) => TransmissionKind::Screw { lead_m },
            (RawKind::Belt, None, Some(radius_m)) => TransmissionKind::Belt { radius_m },
            (RawKind::Screw, _, _) => {
                return Err(anyhow!(
                    "[transmission]: kind = \"screw\" needs lead_m (travel per screw revolution [m]) and no radius_m"
                ))
            }
            (RawKind::Belt, _, _) => {
                return Err(anyhow!(
                    "[transmission]: kind = \"belt\" needs radius_m (pulley or pinion radius [m]) and no lead_m"
                ))
            }
            (RawKind::Gear, _, _) => {
                return Err(anyhow!(
                    "[transmission]: a gear (the default kind) has no lead_m or radius_m; give kind = \"screw\" or \"belt\""
                ))
            }
        };
        let t = Transmission {
            kind,
            encoder: match self.encoder {
                RawEncoder::Load => EncoderSide::Load,
                RawEncoder::Motor => EncoderSide::Motor,
                RawEncoder::Both => EncoderSide::Both,
            },
        };
        t.validate().map_err(|e| anyhow!("[transmission]: {e}"))?;
        Ok(t)
    }

    /// Moves the linear mass, viscous and Coulomb values into `params` (motor-side J_eq, B_eq,
    /// load-side tau_sf); a quantity given in both tables is refused.
    fn write_params(&self, t: &Transmission, params: &mut PlantParams) -> anyhow::Result<()> {
        let given = [
            ("m_eq_kg", self.m_eq_kg, "j_eq", params.j_eq.is_some()),
            ("b_eq_n_s_m", self.b_eq_n_s_m, "b_eq", params.b_eq.is_some()),
            ("f_c_n", self.f_c_n, "tau_sf", params.tau_sf.is_some()),
        ];
        for (key, v, rotary, twice) in given {
            let Some(v) = v else { continue };
            if !t.is_linear() {
                return Err(anyhow!(
                    "[transmission]: `{key}` is a linear axis' value; a gear takes [params] {rotary}"
                ));
            }
            if twice {
                return Err(anyhow!(
                    "`{key}` in [transmission] and `{rotary}` in [params] give one quantity twice: keep one"
                ));
            }
            if !(v >= 0.0 && v.is_finite()) {
                return Err(anyhow!(
                    "[transmission]: `{key}` must be a finite number >= 0, got {v}"
                ));
            }
        }
        let n = params.n;
        if let Some(m) = self.m_eq_kg {
            params.j_eq = t.j_eq_of_mass(m, n);
        }
        if let Some(b) = self.b_eq_n_s_m {
            params.b_eq = t.b_eq_of_viscous(b, n);
        }
        if let Some(f) = self.f_c_n {
            params.tau_sf = t.torque_of_force(f);
        }
        Ok(())
    }

    /// The table of `t`, with the linear values of `params` (which are taken out of it).
    fn of(t: &Transmission, params: &mut PlantParams) -> Option<RawTransmission> {
        if *t == Transmission::GEAR {
            return None;
        }
        let (kind, lead_m, radius_m) = match t.kind {
            TransmissionKind::Gear => (RawKind::Gear, None, None),
            TransmissionKind::Screw { lead_m } => (RawKind::Screw, Some(lead_m), None),
            TransmissionKind::Belt { radius_m } => (RawKind::Belt, None, Some(radius_m)),
        };
        let n = params.n;
        let mut raw = RawTransmission {
            kind,
            lead_m,
            radius_m,
            encoder: match t.encoder {
                EncoderSide::Load => RawEncoder::Load,
                EncoderSide::Motor => RawEncoder::Motor,
                EncoderSide::Both => RawEncoder::Both,
            },
            ..RawTransmission::default()
        };
        if t.is_linear() {
            raw.m_eq_kg = params.j_eq.take().and_then(|j| t.mass_kg(j, n));
            raw.b_eq_n_s_m = params.b_eq.take().and_then(|b| t.viscous_n_s_m(b, n));
            raw.f_c_n = params.tau_sf.take().and_then(|f| t.force_n(f));
        }
        Some(raw)
    }
}

/// A parsed and validated model file. With serde it (de)serialises as the file's tables
/// (`[params]`, `[effects.<name>]`, ...), validated on the way in as [`ModelFile::parse`] does.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Raw", into = "Raw")]
pub struct ModelFile {
    pub params: PlantParams,
    /// Effects listed in the file (in addition to the friction implied by the params).
    pub effects: Effects,
    /// User-defined effects (`[custom.NAME]`, see [`crate::effects_file`]), active in the model.
    pub custom: CustomSlots,
    /// The transmission (`[transmission]`; a gear with a load-side encoder when absent). On a
    /// linear axis `params` holds the equivalent rotation's J_eq, B_eq, tau_sf, converted from
    /// the file's m_eq_kg, b_eq_n_s_m, f_c_n (and back when written).
    pub transmission: Transmission,
    /// The drive (`[drive]`; a linear voltage amplifier when absent). `params` holds its
    /// equivalent voltage chain ([`Drive::equivalent`]), what the simulator, the fits and the
    /// design compute with; the file holds the keys the drive uses.
    pub drive: Drive,
    /// The smart servo's firmware and gearbox (`[drive] kind = "position"` with a
    /// `[smart_servo]` table; `drive` is then its PWM bridge, a duty drive).
    pub smart_servo: Option<crate::smart_model::SmartServo>,
    pub sensors: Option<SensorConfig>,
    /// Free-form provenance (log, method, date, ...).
    pub provenance: Option<toml::Table>,
    /// `[limits]`: the value each named parameter must not cross (a maintenance limit, in the
    /// parameter's SI unit), keyed as `servo trend` names parameters: `j_eq`, `b_eq`, `tau_sf`,
    /// or `<effect>.<key>` (written `"<effect>.<key>" = v` or as a `[limits.<effect>]` table).
    pub limits: BTreeMap<String, f64>,
}

impl TryFrom<Raw> for ModelFile {
    type Error = crate::Error;
    fn try_from(raw: Raw) -> crate::Result<ModelFile> {
        ModelFile::from_raw(raw)
    }
}

impl From<ModelFile> for Raw {
    fn from(m: ModelFile) -> Raw {
        m.to_raw()
    }
}

impl Default for ModelFile {
    /// Table 2, no effects.
    fn default() -> Self {
        ModelFile {
            params: PlantParams::TABLE2,
            effects: Effects::NONE,
            custom: CustomSlots::NONE,
            transmission: Transmission::GEAR,
            drive: Drive::VOLTAGE,
            smart_servo: None,
            sensors: None,
            provenance: None,
            limits: BTreeMap::new(),
        }
    }
}

impl ModelFile {
    /// Reads and validates `path`; errors name the file, the key and what was expected.
    pub fn load(path: &Path) -> anyhow::Result<ModelFile> {
        let text = crate::text_file::read_text(path)
            .with_context(|| format!("reading model file {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("in model file {}", path.display()))
    }

    /// Parses and validates TOML text.
    pub fn parse(text: &str) -> anyhow::Result<ModelFile> {
        let raw: Raw =
            toml::from_str(text).map_err(|e| anyhow!("{}", crate::text_file::toml_error(&e)))?;
        Self::from_raw(raw)
    }

    /// Validates the deserialised file: parameters, effect names and keys, complete effects.
    fn from_raw(raw: Raw) -> anyhow::Result<ModelFile> {
        let drive = match &raw.drive {
            Some(d) => d.drive()?,
            None => Drive::VOLTAGE,
        };
        let position = raw
            .drive
            .as_ref()
            .is_some_and(|d| d.kind == RawDriveKind::Position);
        match (&raw.smart_servo, position) {
            (Some(s), true) => s.validate(&drive)?,
            (None, true) => bail!(
                "[drive] kind = \"position\" needs a [smart_servo] table (kp_fw, duty_per_rad_per_kp, latency_s, ...)"
            ),
            (Some(_), false) => bail!(
                "[smart_servo] is the firmware of a smart servo: it needs [drive] kind = \"position\""
            ),
            (None, false) => {}
        }
        let mut params = raw.params.params(&drive)?;
        let transmission = match &raw.transmission {
            Some(t) => {
                let tr = t.transmission()?;
                t.write_params(&tr, &mut params)?;
                tr
            }
            None => Transmission::GEAR,
        };
        params.validate().map_err(|e| anyhow!("[params]: {e}"))?;
        // One value per quantity: the friction of [params] (or of a linear axis' [transmission])
        // and the friction effects are the same quantities (the effect would silently override).
        for (key, given, section) in [
            ("b_eq", params.b_eq, EffectKind::Viscous),
            ("tau_sf", params.tau_sf, EffectKind::Coulomb),
        ] {
            let other = raw
                .effects
                .get(section.name())
                .and_then(|kv| kv.get(key).map(|v| (section.name(), *v)));
            if let (Some(a), Some((name, b))) = (given, other) {
                bail!(
                    "{key} is given twice: [params] {key} = {a:e} and [effects.{name}] {key} = {b:e}; \
                     a model file holds each quantity once: keep one of the two"
                );
            }
        }
        let mut effects = Effects::NONE;
        for (name, kv) in &raw.effects {
            let kind = EffectKind::from_name(name).ok_or_else(|| {
                anyhow!(
                    "[effects.{name}]: unknown effect; the registry has {}",
                    servo_core::effects::RegisteredNames
                )
            })?;
            let mut e = Effect::unset(kind);
            for (k, v) in kv {
                e.set(k, *v)
                    .map_err(|err| anyhow!("[effects.{name}]: {err}"))?;
            }
            e.check_complete()
                .map_err(|err| anyhow!("[effects.{name}]: {err}"))?;
            effects.insert(e);
        }
        let mut custom = CustomSlots::NONE;
        for def in crate::effects_file::compile_all(&raw.custom)? {
            custom
                .insert(def.active())
                .map_err(|e| anyhow!("[custom.{}]: {e}", def.name()))?;
        }
        Ok(ModelFile {
            params,
            effects,
            custom,
            transmission,
            drive,
            smart_servo: raw.smart_servo,
            sensors: raw.sensors,
            provenance: raw.provenance,
            limits: parse_limits(raw.limits.as_ref())?,
        })
    }

    /// What the file leaves to a default of zero friction, one sentence each starting with
    /// `what` (how the user named the file: `--plant model.toml`), with the key (`tau_sf`,
    /// `b_eq`): no Coulomb friction (no `tau_sf`, no `[effects.coulomb]`), no viscous friction
    /// (no `b_eq`, no `[effects.viscous]`, and B_m = B_l = 0). Every motor has both: a file
    /// without them is a datasheet's (Table 2 has neither) or one that lost its lines; a command
    /// that simulates or compares with it says so ([`ModelFile::warn_defaults`]). Writing
    /// `tau_sf = 0` or `b_eq = 0` says that zero is meant.
    pub fn friction_defaults(&self, what: &str) -> Vec<(&'static str, String)> {
        let p = &self.params;
        let linear = self.transmission.is_linear();
        let (coulomb, viscous) = if linear {
            ("[transmission] f_c_n", "[transmission] b_eq_n_s_m")
        } else {
            ("[params] tau_sf", "[params] b_eq")
        };
        let mut out = Vec::new();
        if p.tau_sf.is_none() && !self.effects.contains(EffectKind::Coulomb) {
            out.push((
                "tau_sf",
                format!(
                    "{what}: no {coulomb}: the model has no Coulomb friction (tau_sf = 0 N m); \
                     write `{} = 0` if that is meant, or identify it (`servo identify`)",
                    if linear { "f_c_n" } else { "tau_sf" }
                ),
            ));
        }
        if p.b_eq.is_none() && !self.effects.contains(EffectKind::Viscous) && p.b_eq() == 0.0 {
            out.push((
                "b_eq",
                format!(
                    "{what}: no {viscous}, and b_m = b_l = 0: the model has no viscous friction \
                     (B_eq = 0 N m s/rad); write `{} = 0` if that is meant, or identify it \
                     (`servo identify`)",
                    if linear { "b_eq_n_s_m" } else { "b_eq" }
                ),
            ));
        }
        out
    }

    /// Prints [`ModelFile::friction_defaults`] to stderr as warnings, but for the keys in
    /// `given` (friction given elsewhere, e.g. `--plant-effect coulomb:...`).
    pub fn warn_defaults(&self, what: &str, given: &[&str]) {
        for (key, w) in self.friction_defaults(what) {
            if !given.contains(&key) {
                eprintln!("warning: {w}");
            }
        }
    }

    /// The plant: friction from the params (B_eq, tau_sf), then the file's effects on top (an
    /// explicit `[effects.viscous]` or `[effects.coulomb]` replaces the params' value).
    pub fn plant(&self) -> anyhow::Result<Plant> {
        let mut plant = Plant::from_params(self.params).map_err(|e| anyhow!("[params]: {e}"))?;
        for e in self.effects.iter() {
            plant.effects.insert(*e);
        }
        plant.custom = self.custom;
        Ok(plant)
    }

    /// The 95 % interval [lo, hi] of `key` (`<effect>.<key>`, an effect's amplitude) as
    /// `[provenance.intervals]` records it (written by `compare --add --save`); None when the
    /// file records none.
    pub fn interval(&self, key: &str) -> Option<(f64, f64)> {
        let t = self.provenance.as_ref()?.get("intervals")?.as_table()?;
        let a = t.get(key)?.as_array()?;
        let num = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
        match (a.first().and_then(num), a.get(1).and_then(num)) {
            (Some(lo), Some(hi)) if lo.is_finite() && hi.is_finite() && lo <= hi => Some((lo, hi)),
            _ => None,
        }
    }

    /// Records the 95 % interval [lo, hi] of `key` in `[provenance.intervals]` (replacing an
    /// older one); non-finite bounds are not recorded.
    pub fn set_interval(&mut self, key: &str, lo: f64, hi: f64) {
        if !(lo.is_finite() && hi.is_finite()) {
            return;
        }
        let prov = self.provenance.get_or_insert_with(toml::Table::new);
        let entry = prov
            .entry("intervals")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if !entry.is_table() {
            *entry = toml::Value::Table(toml::Table::new());
        }
        if let Some(t) = entry.as_table_mut() {
            t.insert(
                key.to_string(),
                toml::Value::Array(vec![toml::Value::Float(lo), toml::Value::Float(hi)]),
            );
        }
    }

    /// The model file of fitted output-shaft parameters `p` on the firmware `fw`: `base`'s
    /// motor constants and gear ratio (R_a set so that k_t N / (R_a + R_s) is the fitted
    /// k_t / R), J_eq, B_eq, tau_sf at the file's sides, the gravity as the catalogue's effect,
    /// the drive a position drive on `fw`'s supply and duty limit.
    pub fn with_smart_fit(
        &self,
        p: &servo_core::smart::SmartParams,
        fw: &servo_core::smart::PositionLoop,
    ) -> anyhow::Result<ModelFile> {
        use servo_core::effects::{Effect, GRAVITY};
        let mut m = self.clone();
        let n = m.params.n;
        m.params.j_eq = Some(p.j_eq / (n * n));
        m.params.b_eq = Some(p.b_eq / (n * n));
        m.params.tau_sf = Some(p.tau_sf);
        let r_eq = m.params.k_t * n / p.k_t_per_r;
        m.params.r_a = r_eq - m.params.r_s;
        m.effects.remove(servo_core::effects::EffectKind::Viscous);
        m.effects.remove(servo_core::effects::EffectKind::Coulomb);
        let mut g = Effect::unset(GRAVITY);
        g.set("amplitude", p.gravity_nm)
            .and_then(|_| g.set("phase", p.phase_rad))
            .map_err(|e| crate::error::anyhow!("gravity: {e}"))?;
        m.effects.remove(GRAVITY);
        m.effects.insert(g);
        m.drive = Drive {
            duty_limit: Some(fw.duty_limit),
            ..Drive::duty(Some(fw.v_supply_v), None)
        };
        m.smart_servo = Some(crate::smart_model::SmartServo {
            kp_fw: fw.kp_fw,
            duty_per_rad_per_kp: fw.duty_per_rad_per_kp,
            encoder_counts: fw.encoder_counts,
            period_s: fw.period_s,
            latency_s: p.latency_s,
            supply_from_log: fw.supply_from_log,
            load_friction: p.load_friction,
        });
        m.params
            .validate()
            .map_err(|e| crate::error::anyhow!("identified parameters are not physical: {e}"))?;
        Ok(m)
    }

    /// A model file describing `plant` (friction written as effects).
    pub fn from_plant(plant: &Plant) -> ModelFile {
        ModelFile {
            params: plant.params,
            effects: plant.effects,
            custom: plant.custom,
            transmission: Transmission::GEAR,
            drive: Drive::VOLTAGE,
            smart_servo: None,
            sensors: None,
            provenance: None,
            limits: BTreeMap::new(),
        }
    }

    /// Serialises to TOML (machine form).
    pub fn to_toml(&self) -> anyhow::Result<String> {
        Ok(toml::to_string(&self.to_raw())?)
    }

    /// The params as written: B_eq and tau_sf of the friction effects go to `[params]` (one
    /// place per quantity), and those effects are not written again as sections.
    fn written_params(&self) -> PlantParams {
        let mut p = self.params;
        if let Some(b) = self.effects.value(EffectKind::Viscous, "b_eq") {
            // A B_eq equal to the one implied by B_m and B_l stays implied.
            if p.b_eq.is_some() || b != p.b_eq() {
                p.b_eq = Some(b);
            }
        }
        if let Some(t) = self.effects.value(EffectKind::Coulomb, "tau_sf") {
            p.tau_sf = Some(t);
        }
        p
    }

    /// Is effect `kind` written as params (the friction effects)?
    fn in_params(kind: EffectKind) -> bool {
        matches!(kind, EffectKind::Viscous | EffectKind::Coulomb)
    }

    /// The serialisable form: effects as tables of catalogue keys.
    fn to_raw(&self) -> Raw {
        let mut effects = BTreeMap::new();
        for e in self.effects.iter().filter(|e| !Self::in_params(e.kind)) {
            let kv: BTreeMap<String, f64> = e.iter().map(|(p, v)| (p.key.to_string(), v)).collect();
            effects.insert(e.kind.name().to_string(), kv);
        }
        let custom = self
            .custom
            .iter()
            .map(|c| (c.name().to_string(), crate::effects_file::to_raw(c, None)))
            .collect();
        let mut params = self.written_params();
        let transmission = RawTransmission::of(&self.transmission, &mut params);
        Raw {
            params: RawParams::of(&params, &self.drive),
            drive: RawDrive::of(&self.drive).map(|mut d| {
                if self.smart_servo.is_some() {
                    d.kind = RawDriveKind::Position;
                }
                d
            }),
            smart_servo: self.smart_servo,
            effects,
            custom,
            transmission,
            sensors: self.sensors,
            provenance: self.provenance.clone(),
            limits: (!self.limits.is_empty()).then(|| {
                self.limits
                    .iter()
                    .map(|(k, v)| (k.clone(), toml::Value::Float(*v)))
                    .collect()
            }),
        }
    }

    /// Carries over from `old`, the model file this one is about to replace, what the command
    /// writing this one does not own: the effects of kinds this one lacks and `owned` does not
    /// name, the custom effects it lacks, the `[limits]` keys it lacks, and `old`'s provenance as
    /// `[provenance.previous]`. The drive, transmission, sensors and `[params]` are this file's.
    /// Nothing is carried over when the result would not be a valid model file (a friction given
    /// twice). Returns the tables kept, as the file names them (`[effects.<name>]`, `[limits]`).
    pub fn keep_from(&mut self, old: &ModelFile, owned: &[EffectKind]) -> Vec<String> {
        let mut merged = self.clone();
        let mut kept = Vec::new();
        for e in old.effects.iter() {
            let kind = e.kind;
            if !owned.contains(&kind) && !merged.effects.contains(kind) {
                merged.effects.insert(*e);
                kept.push(format!("[effects.{}]", kind.name()));
            }
        }
        for c in old.custom.iter() {
            if merged.custom.get(c.name()).is_none() && merged.custom.insert(*c).is_ok() {
                kept.push(format!("[custom.{}]", c.name()));
            }
        }
        let mut limits = false;
        for (k, v) in &old.limits {
            if !merged.limits.contains_key(k) {
                merged.limits.insert(k.clone(), *v);
                limits = true;
            }
        }
        if limits {
            kept.push("[limits]".to_string());
        }
        if let Some(prev) = &old.provenance {
            let mut prev = prev.clone();
            prev.remove("previous");
            if !prev.is_empty() {
                merged
                    .provenance
                    .get_or_insert_with(Default::default)
                    .insert("previous".into(), toml::Value::Table(prev));
                kept.push("[provenance.previous]".to_string());
            }
        }
        let valid = merged
            .to_toml()
            .ok()
            .is_some_and(|t| ModelFile::parse(&t).is_ok());
        if !valid {
            return Vec::new();
        }
        *self = merged;
        kept
    }

    /// Saves over `path`: when a model file is there, first keeps its tables this command does
    /// not own ([`ModelFile::keep_from`], `owned` the effect kinds the command fits or removes)
    /// and says so on stderr; then [`ModelFile::save`] (which keeps the previous file as
    /// `NAME.N`). Returns the tables kept.
    pub fn save_over(&mut self, path: &Path, owned: &[EffectKind]) -> anyhow::Result<Vec<String>> {
        let kept = match std::fs::read_to_string(path)
            .ok()
            .map(|t| ModelFile::parse(&t))
        {
            Some(Ok(old)) => self.keep_from(&old, owned),
            _ => Vec::new(),
        };
        if !kept.is_empty() {
            eprintln!(
                "note: kept {} of the previous {} (tables this command does not write)",
                kept.join(", "),
                path.display()
            );
        }
        self.save(path)?;
        Ok(kept)
    }

    /// The effect kinds every command that writes a model owns: the friction of `[params]`
    /// (`b_eq`, `tau_sf`), which `[effects.viscous]` / `[effects.coulomb]` would override.
    pub const FRICTION_KINDS: [EffectKind; 2] = [EffectKind::Viscous, EffectKind::Coulomb];

    /// Writes the file atomically ([`crate::output`]: a previous file with other contents is
    /// kept as `NAME.N`, said on stderr).
    pub fn save(&self, path: &Path) -> anyhow::Result<()> {
        crate::output::write_file(path, "model file", self.to_toml_commented()).map(|_| ())
    }

    /// TOML with units and meanings in comments (what `servo params` prints).
    pub fn to_toml_commented(&self) -> String {
        let written = self.written_params();
        let p = &written;
        let mut s = String::from(
            "# servo model file: DC gearmotor parameters (handout Table 2), SI units.\n\
             # Motor side / load side as in the handout: omega_l = omega_m / N.\n",
        );
        // Values a command took from a default, said where the file is read first.
        if let Some(d) = self
            .provenance
            .as_ref()
            .and_then(|p| p.get("defaults"))
            .and_then(|d| d.as_str())
        {
            for line in d.lines() {
                s.push_str(&format!("# NOTE: {line}\n"));
            }
        }
        s.push_str("\n[params]\n");
        let rows: [(&str, f64, &str); 13] = [
            ("r_a", p.r_a, "armature resistance R_a [ohm]"),
            ("l_a", p.l_a, "armature inductance L_a [H]"),
            ("k_e", p.k_e, "electric (BEMF) constant k_e [V s/rad]"),
            ("k_t", p.k_t, "torque constant k_t [N m/A]"),
            ("j_m", p.j_m, "rotor moment of inertia J_m [kg m^2]"),
            ("b_m", p.b_m, "rotor viscous friction B_m [N m s/rad]"),
            ("n", p.n, "gearbox ratio N [-]"),
            (
                "j_72",
                p.j_72,
                "inertia of one external 72-tooth gear J_72 [kg m^2] (3 fitted)",
            ),
            ("j_d", p.j_d, "inertia of the extra disc J_d [kg m^2]"),
            ("b_l", p.b_l, "load viscous friction B_l [N m s/rad]"),
            ("k_drv", p.k_drv, "voltage driver static gain k_drv [V/V]"),
            (
                "f_c_drv",
                p.f_c_drv,
                "voltage driver cut-off frequency f_c,drv [Hz]",
            ),
            ("r_s", p.r_s, "shunt resistance R_s [ohm]"),
        ];
        let raw = RawParams::of(p, &self.drive);
        for (k, _, doc) in rows {
            match raw.get(k) {
                Some(v) => s.push_str(&format!("{k} = {v:e}  # {doc}\n")),
                None if self.drive.unused_params().iter().any(|(u, _)| *u == k) => s.push_str(
                    &format!("# {k}: not used by a {} drive\n", self.drive.kind.name()),
                ),
                None => s.push_str(&format!(
                    "# {k} = ...  # {doc} (a {} drive's default)\n",
                    self.drive.kind.name()
                )),
            }
        }
        let opt: [(&str, Option<f64>, &str); 3] = [
            ("j_eq", p.j_eq, "identified total inertia at motor side J_eq [kg m^2] (overrides J_m + J_l/N^2)"),
            ("b_eq", p.b_eq, "identified viscous friction at motor side B_eq [N m s/rad] (overrides B_m + B_l/N^2)"),
            ("tau_sf", p.tau_sf, "identified Coulomb friction at load side tau_sf [N m]"),
        ];
        let linear = self.transmission.is_linear();
        for (k, v, doc) in opt {
            match v {
                _ if linear => s.push_str(&format!(
                    "# {k}: a linear axis gives it in [transmission]\n"
                )),
                Some(v) => s.push_str(&format!("{k} = {v:e}  # {doc}\n")),
                None => s.push_str(&format!("# {k} = ...  # {doc}\n")),
            }
        }
        let mut rest = written;
        if let Some(t) = RawTransmission::of(&self.transmission, &mut rest) {
            s.push_str(&transmission_toml(&t));
        }
        if self.drive != Drive::VOLTAGE {
            let mut d = drive_toml(&self.drive);
            if let Some(sm) = &self.smart_servo {
                d = d.replacen("kind = \"duty\"", "kind = \"position\"", 1);
                d.push_str(&sm.toml_section());
            }
            s.push_str(&d);
        }
        for e in self.effects.iter().filter(|e| !Self::in_params(e.kind)) {
            s.push_str(&format!(
                "\n[effects.{}]  # {}\n",
                e.kind.name(),
                e.kind.description()
            ));
            for (spec, v) in e.iter() {
                s.push_str(&format!(
                    "{} = {:e}  # {} [{}]\n",
                    spec.key, v, spec.doc, spec.unit
                ));
            }
        }
        if !self.custom.is_empty() {
            s.push_str("\n# user-defined effects (docs/custom-effects.md)\n");
            let sections: Vec<(String, crate::effects_file::RawCustom)> = self
                .custom
                .iter()
                .map(|c| (c.name().to_string(), crate::effects_file::to_raw(c, None)))
                .collect();
            s.push_str(&crate::effects_file::to_toml(&sections));
        }
        if let Some(sn) = &self.sensors {
            s.push_str(&format!(
                "\n[sensors]  # simulator only\ncounts_per_rev = {}  # encoder counts per load revolution\n\
                 current_noise_a = {:e}  # current sensor noise std [A]\ncurrent_offset_a = {:e}  # current sensor offset [A]\nseed = {}  # noise seed\n",
                sn.counts_per_rev, sn.current_noise_a, sn.current_offset_a, sn.seed
            ));
        }
        if let Some(pv) = &self.provenance {
            // Under its own key, so that sub-tables come out as [provenance.intervals].
            let mut wrap = toml::Table::new();
            wrap.insert("provenance".into(), toml::Value::Table(pv.clone()));
            s.push('\n');
            s.push_str(&toml::to_string(&wrap).unwrap_or_default());
        }
        if !self.limits.is_empty() {
            s.push_str("\n[limits]  # maintenance limits servo trend forecasts (SI units)\n");
            for (k, v) in &self.limits {
                s.push_str(&format!("\"{k}\" = {v:e}\n"));
            }
        }
        s
    }
}

/// The `[limits]` table: `key = value` for a base parameter (`j_eq`, `b_eq`, `tau_sf`), and
/// `"<effect>.<key>" = value` or `[limits.<effect>] key = value` for an effect's parameter, each
/// key checked against the registry.
fn parse_limits(raw: Option<&toml::Table>) -> anyhow::Result<BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    let Some(t) = raw else { return Ok(out) };
    let number = |k: &str, v: &toml::Value| -> anyhow::Result<f64> {
        let x = match v {
            toml::Value::Float(f) => *f,
            toml::Value::Integer(i) => *i as f64,
            _ => bail!("[limits] {k}: expected a number (the limit in the parameter's SI unit)"),
        };
        if !x.is_finite() {
            bail!("[limits] {k}: expected a finite number, got {x}");
        }
        Ok(x)
    };
    for (k, v) in t {
        match v {
            toml::Value::Table(inner) => {
                for (kk, vv) in inner {
                    let key = format!("{k}.{kk}");
                    check_limit_key(&key)?;
                    out.insert(key.clone(), number(&key, vv)?);
                }
            }
            _ => {
                check_limit_key(k)?;
                out.insert(k.clone(), number(k, v)?);
            }
        }
    }
    Ok(out)
}

/// A `[limits]` key names a base parameter or a registered effect's parameter.
fn check_limit_key(key: &str) -> anyhow::Result<()> {
    if ["j_eq", "b_eq", "tau_sf"].contains(&key) {
        return Ok(());
    }
    let Some((effect, param)) = key.split_once('.') else {
        bail!(
            "[limits] {key}: expected j_eq, b_eq, tau_sf or <effect>.<key> (e.g. an effect's gap)"
        );
    };
    let kind = EffectKind::from_name(effect).ok_or_else(|| {
        anyhow!(
            "[limits] {key}: unknown effect `{effect}`; the registry has {}",
            servo_core::effects::RegisteredNames
        )
    })?;
    if !kind.params().iter().any(|p| p.key == param) {
        let keys: Vec<&str> = kind.params().iter().map(|p| p.key).collect();
        bail!(
            "[limits] {key}: {effect} has no parameter `{param}` (it has {})",
            keys.join(", ")
        );
    }
    Ok(())
}

/// The commented `[drive]` table.
fn drive_toml(d: &Drive) -> String {
    let mut s = format!(
        "\n[drive]  # between the command and the motor\nkind = \"{}\"  # voltage | current | duty\n",
        d.kind.name()
    );
    let docs = [
        (
            "bandwidth_hz",
            "current loop bandwidth [Hz] (instant when absent)",
        ),
        ("i_limit_a", "current reference limit [A]"),
        (
            "k_i_a_per_v",
            "amps of reference per volt of a voltage command [A/V]",
        ),
        (
            "v_supply_v",
            "supply voltage [V] (when the log has no v_supply column)",
        ),
        (
            "r_supply_ohm",
            "supply internal resistance [ohm] (sag R i_a)",
        ),
        ("t_dead_s", "bridge dead time [s]"),
        ("f_pwm_hz", "PWM frequency [Hz]"),
        ("duty_limit", "largest duty magnitude [-]"),
    ];
    for ((k, v), (_, doc)) in d.values().into_iter().zip(docs) {
        if let Some(v) = v {
            s.push_str(&format!("{k} = {v:e}  # {doc}\n"));
        }
    }
    s
}

/// The commented `[transmission]` table.
fn transmission_toml(t: &RawTransmission) -> String {
    let mut s =
        String::from("\n[transmission]  # between the motor (after its gearbox n) and the load\n");
    let kind = match t.kind {
        RawKind::Gear => "gear",
        RawKind::Screw => "screw",
        RawKind::Belt => "belt",
    };
    s.push_str(&format!(
        "kind = \"{kind}\"  # gear | screw | belt (or rack)\n"
    ));
    if let Some(v) = t.lead_m {
        s.push_str(&format!(
            "lead_m = {v:e}  # travel per screw revolution [m]\n"
        ));
    }
    if let Some(v) = t.radius_m {
        s.push_str(&format!(
            "radius_m = {v:e}  # pulley or pinion radius [m]\n"
        ));
    }
    let enc = match t.encoder {
        RawEncoder::Load => "load",
        RawEncoder::Motor => "motor",
        RawEncoder::Both => "both",
    };
    s.push_str(&format!(
        "encoder = \"{enc}\"  # load | motor | both: where the position encoder sits\n"
    ));
    let rows = [
        (
            "m_eq_kg",
            t.m_eq_kg,
            "total mass at the load, motor and screw included [kg]",
        ),
        (
            "b_eq_n_s_m",
            t.b_eq_n_s_m,
            "viscous friction at the load [N s/m]",
        ),
        ("f_c_n", t.f_c_n, "Coulomb friction at the load [N]"),
    ];
    for (k, v, doc) in rows {
        match v {
            Some(v) => s.push_str(&format!("{k} = {v:e}  # {doc}\n")),
            None => s.push_str(&format!("# {k} = ...  # {doc}\n")),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCREW: &str = "\n[transmission]\nkind = \"screw\"\nlead_m = 0.01\nencoder = \"motor\"\nm_eq_kg = 5.0\nb_eq_n_s_m = 40.0\nf_c_n = 12.0\n";

    #[test]
    fn a_screw_axis_reads_in_linear_units_and_round_trips() {
        let good = ModelFile::default().to_toml_commented();
        let m = ModelFile::parse(&format!("{good}{SCREW}")).unwrap();
        let t = m.transmission;
        assert_eq!(t.encoder, EncoderSide::Motor);
        let s = 0.01 / std::f64::consts::TAU;
        let n = m.params.n;
        assert!((m.params.j_eq.unwrap() - 5.0 * s * s / (n * n)).abs() < 1e-18);
        assert!((m.params.tau_sf.unwrap() - 12.0 * s).abs() < 1e-15);
        let text = m.to_toml_commented();
        assert!(
            text.contains("m_eq_kg = 5") && !text.contains("\nj_eq ="),
            "{text}"
        );
        let back = ModelFile::parse(&text).unwrap();
        assert!((back.params.j_eq.unwrap() / m.params.j_eq.unwrap() - 1.0).abs() < 1e-12);
        assert!((back.params.b_eq.unwrap() / m.params.b_eq.unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(back.transmission, t);
        let json = serde_json::to_string(&m).unwrap();
        let back: ModelFile = serde_json::from_str(&json).unwrap();
        assert!((back.params.tau_sf.unwrap() / m.params.tau_sf.unwrap() - 1.0).abs() < 1e-12);
        // A file without [transmission] is a gear with a load-side encoder.
        assert_eq!(
            ModelFile::parse(&good).unwrap().transmission,
            Transmission::GEAR
        );
    }

    #[test]
    fn a_transmission_is_refused_clearly() {
        let good = ModelFile::default().to_toml_commented();
        for (bad, needle) in [
            ("[transmission]\nkind = \"screw\"\n", "lead_m"),
            (
                "[transmission]\nkind = \"belt\"\nlead_m = 0.01\n",
                "radius_m",
            ),
            (
                "[transmission]\nkind = \"screw\"\nlead_m = 20.0\n",
                "lead_m",
            ),
            ("[transmission]\nkind = \"worm\"\n", "worm"),
            ("[transmission]\nencoder = \"hub\"\n", "hub"),
            (
                "[transmission]\nm_eq_kg = 5.0\n",
                "a gear takes [params] j_eq",
            ),
            (
                "[transmission]\nkind = \"belt\"\nradius_m = 0.02\nefficiency = 0.9\n",
                "efficiency",
            ),
        ] {
            let e = format!(
                "{:#}",
                ModelFile::parse(&format!("{good}\n{bad}")).unwrap_err()
            );
            assert!(e.contains(needle), "{bad}: {e}");
        }
        // One quantity twice: the mass in [transmission] and J_eq in [params].
        let twice = good.replace("# j_eq = ...", "j_eq = 1e-5");
        let e = format!(
            "{:#}",
            ModelFile::parse(&format!("{twice}{SCREW}")).unwrap_err()
        );
        assert!(e.contains("twice") && e.contains("m_eq_kg"), "{e}");
    }

    #[test]
    fn friction_left_to_zero_is_said_naming_the_key() {
        let lab = ModelFile::from_plant(&Plant::from_params(PlantParams::LAB).unwrap());
        assert!(lab.friction_defaults("m.toml").is_empty());
        let text = lab.to_toml_commented();
        let cut: String = text
            .lines()
            .filter(|l| !l.starts_with("b_eq") && !l.starts_with("tau_sf"))
            .map(|l| format!("{l}\n"))
            .collect();
        let m = ModelFile::parse(&cut).unwrap();
        let said = m.friction_defaults("--plant m.toml");
        let keys: Vec<&str> = said.iter().map(|(k, _)| *k).collect();
        assert_eq!(keys, ["tau_sf", "b_eq"]);
        assert!(
            said[0].1.starts_with("--plant m.toml: no [params] tau_sf"),
            "{said:?}"
        );
        // Zero written is zero meant; B_m > 0 gives a viscous friction.
        let zeros = cut.replacen("[params]\n", "[params]\ntau_sf = 0\nb_eq = 0\n", 1);
        assert!(ModelFile::parse(&zeros)
            .unwrap()
            .friction_defaults("m")
            .is_empty());
        let bm = cut.replace("b_m = 0e0", "b_m = 1e-7");
        assert_ne!(bm, cut);
        let keys: Vec<&str> = ModelFile::parse(&bm)
            .unwrap()
            .friction_defaults("m")
            .iter()
            .map(|(k, _)| *k)
            .collect();
        assert_eq!(keys, ["tau_sf"]);
    }

    #[test]
    fn default_file_round_trips() {
        let text = ModelFile::default().to_toml_commented();
        let back = ModelFile::parse(&text).unwrap();
        assert_eq!(back, ModelFile::default());
    }

    #[test]
    fn serde_round_trip_validates() {
        let mut m = ModelFile::default();
        m.effects
            .insert(Effect::new(EffectKind::Delay, &[0.003]).unwrap());
        let json = serde_json::to_string(&m).unwrap();
        // (effects compare by their TOML: unused parameter slots hold NaN)
        let back: ModelFile = serde_json::from_str(&json).unwrap();
        assert_eq!(back.to_toml().unwrap(), m.to_toml().unwrap());
        let bad = json.replace("\"r_a\":2.6", "\"r_a\":-2.6");
        assert!(serde_json::from_str::<ModelFile>(&bad).is_err(), "{bad}");
    }

    #[test]
    fn keys_with_unit_suffixes_of_the_json_outputs_are_read() {
        let good = ModelFile::default().to_toml_commented();
        let suffixed = good
            .replace("r_a =", "r_a_ohm =")
            .replace("# b_eq = ...", "b_eq_n_m_s_rad = 4.6e-6");
        let m = ModelFile::parse(&suffixed).unwrap();
        assert_eq!(m.params.r_a, ModelFile::default().params.r_a);
        assert_eq!(m.params.b_eq, Some(4.6e-6));
        // both spellings of one key are refused, not silently resolved
        let both = good.replace("r_s =", "r_a_ohm = 2.6\nr_s =");
        assert!(ModelFile::parse(&both).is_err());
    }

    #[test]
    fn each_quantity_is_written_once_and_a_file_with_one_twice_is_refused() {
        let plant = Plant::from_params(PlantParams {
            b_eq: Some(1.1e-6),
            tau_sf: Some(8.0e-3),
            ..PlantParams::TABLE2
        })
        .unwrap();
        let mut m = ModelFile::from_plant(&plant);
        m.effects
            .insert(Effect::new(EffectKind::Coulomb, &[7.0e-3]).unwrap());
        for text in [m.to_toml_commented(), m.to_toml().unwrap()] {
            assert!(!text.contains("[effects.coulomb]") && !text.contains("[effects.viscous]"));
            let back = ModelFile::parse(&text).unwrap().plant().unwrap();
            // The effect's value is the one the plant used: it is the one written.
            assert_eq!(back.tau_sf(), 7.0e-3, "{text}");
            assert_eq!(back.b_eq(), 1.1e-6);
        }
        let good = m.to_toml_commented();
        for (section, key) in [("coulomb", "tau_sf"), ("viscous", "b_eq")] {
            let bad = format!("{good}\n[effects.{section}]\n{key} = 1e-3\n");
            let e = ModelFile::parse(&bad).unwrap_err().to_string();
            assert!(
                e.contains(&format!("[params] {key}"))
                    && e.contains(&format!("[effects.{section}] {key}")),
                "{e}"
            );
        }
        // One place only (an older file's effects without the params' key) is read.
        let only_effect =
            good.replace("tau_sf = 7e-3", "") + "\n[effects.coulomb]\ntau_sf = 5e-3\n";
        let back = ModelFile::parse(&only_effect).unwrap().plant().unwrap();
        assert_eq!(back.tau_sf(), 5e-3);
    }

    #[test]
    fn rejects_bad_files_naming_the_key() {
        let good = ModelFile::default().to_toml_commented();
        let unknown = good.replace("r_s =", "r_x =");
        let e = format!("{:#}", ModelFile::parse(&unknown).unwrap_err());
        assert!(e.contains("r_x"), "{e}");
        let negative = good.replace("j_m = 3.9e-7", "j_m = -3.9e-7");
        let e = format!("{:#}", ModelFile::parse(&negative).unwrap_err());
        assert!(e.contains("j_m"), "{e}");
        let missing: String = good
            .lines()
            .filter(|l| !l.starts_with("k_t"))
            .map(|l| format!("{l}\n"))
            .collect();
        let e = format!("{:#}", ModelFile::parse(&missing).unwrap_err());
        assert!(e.contains("k_t"), "{e}");
        let wrong_type = good.replace("n = 1.4e1", "n = \"fourteen\"");
        let e = format!("{:#}", ModelFile::parse(&wrong_type).unwrap_err());
        assert!(e.contains('n'), "{e}");
        let bad_effect = format!("{good}\n[effects.delay]\ndelayy = 0.1\n");
        let e = format!("{:#}", ModelFile::parse(&bad_effect).unwrap_err());
        assert!(e.contains("delayy") && e.contains("delay [s]"), "{e}");
    }
}
