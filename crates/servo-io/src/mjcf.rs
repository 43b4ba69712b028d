//! A model file as a MuJoCo model (MJCF): one joint, one actuator, what MuJoCo cannot express
//! listed with the error it leaves.
//!
//! The joint is the load: a hinge about x whose position is the load angle theta_l [rad], or, on
//! a linear axis (screw, belt), a slide along x whose position is the travel x = s theta_l [m]
//! (s the travel per radian of the load shaft, [`servo_core::transmission`]). Every constant is
//! taken to that joint (load side; `per` = 1 rad or s m per load radian):
//!
//! * `gear` = N / per: the actuator's length is the motor angle theta_m, its force the motor
//!   torque tau_m [N m], the joint's force N tau_m / per.
//! * the actuator's `ctrl` is the drive's command in its own units. A voltage drive (u [V]):
//!   with the armature's electrical lag L_a / R_eq neglected, eqs. 19-20 give
//!   tau_m = (k_t / R_eq) (k_drv u_drv - k_e omega_m), a `general` actuator with
//!   `gainprm` = k_t k_drv / R_eq and an affine `biasprm` = (0, 0, -k_t k_e / R_eq) on the
//!   actuator velocity omega_m; the driver's lag T_drv (eq. 21) is the actuator's first-order
//!   `filterexact` dynamics. A duty drive (d, a fraction): the same with k_drv V_supply in
//!   place of k_drv and R_supply in R_eq. A current drive (i_ref [A], or [V] times k_i_a_per_v):
//!   tau_m = k_t i_ref through the current loop's lag, no back-EMF (the loop rejects it).
//! * `armature`: the reflected rotor inertia N^2 J_m / per^2; the body carries the rest of the
//!   identified N^2 J_eq / per^2 (eq. 10).
//! * `damping`: N^2 B_eq / per^2 (eq. 9, the viscous friction at the load); `frictionloss`:
//!   tau_sf / per (eq. 8, Coulomb, load side).
//! * `ctrlrange` where the model clips the command (a saturation, a current or duty limit);
//!   `forcerange` where the torque is limited (a current drive's limit, k_t i_limit).
//! * gravity (the catalogue's gravity effect, m g L sin(theta_l + phi)): the body's centre of
//!   mass at an arm L from the hinge with m g L the identified amplitude; servo identifies the
//!   product m g L and the total inertia, not m and L apart, so L is chosen so that the point
//!   mass carries 99 % of the body's inertia (a simple pendulum), and the comment says so.
//!
//! Everything else (a dead band, a delay, friction laws other than Coulomb and viscous, periodic
//! torques, play, user-defined effects, a duty drive's dead-time loss) is left out, listed in an XML comment and in
//! [`Mjcf::left_out`] with the error it leaves: servo's simulator drives the model with and
//! without it, open loop, on random command steps ([`PROBE_S`] s, levels of 10 % to 100 % of
//! the command's range), and the RMSE of the load position is given with the travel.

use crate::error::{anyhow, bail, Result};
use crate::model_file::ModelFile;
use servo_core::drive::{Drive, DriveKind};
use servo_core::effects::{self, EffectKind};
use servo_core::sim::excitation::RandomSteps;
use servo_core::sim::PlantSim;
use servo_core::Plant;
use std::fmt::Write as _;
use std::path::Path;

/// Gravity of the exported world [m/s^2] (the body's mass and arm are set so that m g L is the
/// identified amplitude with this g).
pub const G_M_S2: f64 = 9.81;
/// MuJoCo's time step in the exported model [s].
pub const TIMESTEP_S: f64 = 1e-4;
/// Length of the representative input on which the left-out effects' error is measured [s].
pub const PROBE_S: f64 = 4.0;
/// Period of that input [s].
const PROBE_DT_S: f64 = 1e-3;
/// A lag shorter than this is left out of the actuator (a drive without lag) [s].
const NO_LAG_S: f64 = 1e-6;
/// Share of the body's inertia the gravity point mass carries (the rest is its own inertia).
const POINT_SHARE: f64 = 0.99;
/// The largest command of the probe when the model sets none (servo's loops' default output
/// limit: 10 V, or 10 A for a current drive).
const DEFAULT_CMD_MAX: f64 = 10.0;

/// One thing of the model MuJoCo cannot express.
#[derive(Debug, Clone, PartialEq)]
pub struct LeftOut {
    /// The effect's name (`[effects.NAME]`, `[custom.NAME]`) or what it is.
    pub name: String,
    /// Why MuJoCo cannot express it.
    pub why: String,
    /// RMSE of the load position without it [rad or m] on the probe.
    pub rmse: f64,
}

/// The exported model.
#[derive(Debug, Clone, PartialEq)]
pub struct Mjcf {
    /// The MJCF text.
    pub xml: String,
    /// `hinge` or `slide`.
    pub joint: &'static str,
    /// The joint position's unit (`rad`, `m`).
    pub position_unit: &'static str,
    /// The unit of the actuator's ctrl (`V`, `A`, `duty (fraction)`).
    pub ctrl_unit: &'static str,
    /// What MuJoCo cannot express, each with its error.
    pub left_out: Vec<LeftOut>,
    /// RMSE of the load position with all of them left out at once [rad or m].
    pub rmse_all: f64,
    /// The travel of servo's full model on the probe [rad or m].
    pub travel: f64,
    /// Statements the user should read (choices made, neglected dynamics).
    pub notes: Vec<String>,
}

impl Mjcf {
    /// The lines the command prints: the left-out effects with their error.
    pub fn summary(&self) -> Vec<String> {
        summary_lines(
            &self.left_out,
            self.rmse_all,
            self.travel,
            self.position_unit,
        )
    }
}

fn summary_lines(left: &[LeftOut], all: f64, travel: f64, u: &str) -> Vec<String> {
    let mut out = Vec::new();
    if left.is_empty() {
        out.push("MuJoCo expresses every effect of the model".to_string());
        return out;
    }
    out.push(format!(
        "MuJoCo cannot express {} part(s) of the model, left out; the load position then differs \
         from servo's by (RMSE, open loop, {PROBE_S} s of random command steps, travel {} {u}):",
        left.len(),
        short(travel)
    ));
    for l in left {
        out.push(format!(
            "  {}: {} {u} ({:.2} % of the travel): {}",
            l.name,
            short(l.rmse),
            pct(l.rmse, travel),
            l.why
        ));
    }
    if left.len() > 1 {
        out.push(format!(
            "  all of them: {} {u} ({:.2} % of the travel)",
            short(all),
            pct(all, travel)
        ));
    }
    out
}

fn pct(x: f64, of: f64) -> f64 {
    if of > 0.0 {
        100.0 * x / of
    } else {
        0.0
    }
}

/// A number as MJCF and the comments write it (shortest round-trip form).
fn num(x: f64) -> String {
    if x == 0.0 {
        "0".to_string()
    } else {
        format!("{x:e}")
    }
}

/// A number for the reader: 4 significant digits.
fn short(x: f64) -> String {
    let r: f64 = format!("{x:.3e}").parse().unwrap_or(x);
    servo_core::math::Num(r).to_string()
}

/// `s` as an XML attribute value (quotes and markup escaped).
pub fn attr(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&apos;"),
            c if (c as u32) < 0x20 => o.push(' '),
            c => o.push(c),
        }
    }
    o
}

/// `s` inside an XML comment: no `--`, no trailing `-`, no control characters.
pub fn comment(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        let c = if (c as u32) < 0x20 && c != '\n' {
            ' '
        } else {
            c
        };
        if c == '-' && o.ends_with('-') {
            o.push(' ');
        }
        o.push(c);
    }
    if o.ends_with('-') {
        o.push(' ');
    }
    o
}

/// How the drive's command becomes the actuator's force.
struct Actuator {
    ctrl_unit: &'static str,
    /// Motor torque per unit of ctrl [N m per unit].
    gain: f64,
    /// Motor torque per motor speed [N m s/rad] (negative: the back-EMF).
    bias_v: f64,
    /// First-order lag of the command [s] (0: none).
    lag_s: f64,
    /// The drive's own command limit [ctrl units], if any.
    ctrl_max: Option<f64>,
    /// Chain input (V or A, what [`PlantSim::step`] takes) per unit of ctrl.
    scale: f64,
    /// Motor torque limit [N m], if any.
    force_max: Option<f64>,
    /// What the actuator leaves out of the drive (e.g. the electrical lag), as a note.
    note: Option<String>,
}

fn actuator(model: &ModelFile) -> Result<Actuator> {
    let p = &model.params;
    let d = &model.drive;
    let t_a = p.l_a / p.r_eq();
    let lag_note = |t_drv: f64| {
        Some(format!(
            "the armature's electrical lag L_a / R_eq = {} s is left out (one lag per actuator: \
             the driver's, {} s)",
            short(t_a),
            short(t_drv)
        ))
    };
    Ok(match d.kind {
        DriveKind::Voltage => Actuator {
            ctrl_unit: "V",
            gain: p.k_t * p.k_drv / p.r_eq(),
            bias_v: -p.k_t * p.k_e / p.r_eq(),
            lag_s: p.t_drv(),
            ctrl_max: None,
            scale: 1.0,
            force_max: None,
            note: lag_note(p.t_drv()),
        },
        DriveKind::Duty => {
            let Some(v_s) = d.v_supply_v else {
                bail!(
                    "[drive] v_supply_v is missing: a duty drive's model needs its supply voltage \
                     to be exported (its logs may carry it as a v_supply column; MuJoCo's actuator \
                     has one constant gain)"
                );
            };
            Actuator {
                ctrl_unit: "duty (fraction)",
                gain: p.k_t * p.k_drv * v_s / p.r_eq(),
                bias_v: -p.k_t * p.k_e / p.r_eq(),
                lag_s: p.t_drv(),
                ctrl_max: Some(d.duty_limit.unwrap_or(1.0)),
                scale: v_s,
                force_max: None,
                note: lag_note(p.t_drv()),
            }
        }
        DriveKind::Current => {
            let k = d.k_i_a_per_v.unwrap_or(1.0);
            Actuator {
                ctrl_unit: if d.k_i_a_per_v.is_some() { "V" } else { "A" },
                gain: p.k_t * k,
                bias_v: 0.0,
                lag_s: d.bandwidth_hz.map_or(0.0, |_| d.loop_lag_s()),
                ctrl_max: d.i_limit_a.map(|l| l / k),
                scale: k,
                force_max: d.i_limit_a.map(|l| p.k_t * l),
                note: None,
            }
        }
    })
}

/// Whether MuJoCo expresses `kind` on this joint, and if not why.
fn inexpressible(kind: EffectKind, linear: bool) -> Option<String> {
    use servo_core::effects::ActsOn;
    if kind == EffectKind::Viscous || kind == EffectKind::Coulomb {
        return None;
    }
    if kind == EffectKind::Saturation {
        return None;
    }
    if kind == effects::GRAVITY {
        return linear.then(|| {
            "a load torque periodic in the angle of the load shaft; on a slide joint gravity is \
             a constant force"
                .to_string()
        });
    }
    if kind.sim_role() == effects::SimRole::InputDelay {
        return Some("a transport delay of the command; a MuJoCo actuator has none".to_string());
    }
    Some(match kind.acts_on() {
        ActsOn::Input => "it changes the command before the drive; a MuJoCo actuator's command \
                          is linear (with a range)"
            .to_string(),
        ActsOn::LoadTorque | ActsOn::MotorTorque if kind.sim_role() == effects::SimRole::Smooth => {
            "a torque that depends on the position or speed in a way joint damping, frictionloss \
             and a body's gravity cannot write"
                .to_string()
        }
        ActsOn::LoadTorque | ActsOn::MotorTorque => "a friction or contact law of its own; MuJoCo \
                                                     has symmetric Coulomb friction \
                                                     (frictionloss) and viscous damping only"
            .to_string(),
        ActsOn::Electrical => "it acts in the armature circuit, which the actuator reduces to \
                               its static gain"
            .to_string(),
        ActsOn::Sensor => "it acts on the measurement, not on the motion".to_string(),
    })
}

/// The load position [rad] of `plant` driven open loop through `drive` by `cmds` (one per
/// [`PROBE_DT_S`], held).
fn response(plant: &Plant, drive: &Drive, cmds: &[f64]) -> Result<Vec<f64>> {
    let mut sim = PlantSim::new(plant, PROBE_DT_S)
        .map_err(|e| anyhow!("simulating the model for the error of what is left out: {e}"))?;
    let v_s = drive.v_supply_v.unwrap_or(0.0);
    let mut out = Vec::with_capacity(cmds.len());
    for &c in cmds {
        out.push(sim.state().theta_l_rad);
        sim.step(drive.input(c, v_s));
    }
    Ok(out)
}

fn rmse(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1) as f64;
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / n).sqrt()
}

/// The MJCF of `model`, named `name` (the `<mujoco model=...>` attribute); `source` names the
/// model file in the header comment.
pub fn to_mjcf(model: &ModelFile, name: &str, source: &str) -> Result<Mjcf> {
    let p = &model.params;
    let plant = model.plant()?;
    let tr = &model.transmission;
    let linear = tr.is_linear();
    let per = tr.metres_per_rad().unwrap_or(1.0);
    let n = p.n;
    let (joint, position_unit) = if linear {
        ("slide", "m")
    } else {
        ("hinge", "rad")
    };
    let act = actuator(model)?;
    let mut notes: Vec<String> = act.note.iter().cloned().collect();

    // Inertia at the joint: the rotor's share as armature, the rest on the body.
    let j_tot = n * n * p.j_eq() / (per * per);
    let rotor = n * n * p.j_m / (per * per);
    let body = (j_tot - rotor).max((1.0 - POINT_SHARE) * j_tot);
    let armature = j_tot - body;
    if rotor > armature * (1.0 + 1e-12) {
        notes.push(format!(
            "the rotor's reflected inertia N^2 J_m = {} exceeds the identified total's share left \
             to the body: armature = {}, the body {} (the total N^2 J_eq = {} is kept)",
            short(rotor),
            short(armature),
            short(body),
            short(j_tot)
        ));
    }
    let damping = n * n * plant.b_eq() / (per * per);
    let frictionloss = plant.tau_sf() / per;

    // The command's range: the drive's own limit and a saturation of the chain's input.
    let sat = plant
        .effects
        .value(EffectKind::Saturation, "limit")
        .map(|l| l / act.scale);
    let ctrl_max = match (act.ctrl_max, sat) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };

    // What MuJoCo cannot express: the catalogue effects, the user's, a duty drive's dead time.
    let mut reduced = plant;
    let mut reduced_drive = model.drive;
    let mut left: Vec<(String, String, Plant, Drive)> = Vec::new();
    for e in plant.effects.iter() {
        if let Some(why) = inexpressible(e.kind, linear) {
            reduced.effects.remove(e.kind);
            let mut alone = plant;
            alone.effects.remove(e.kind);
            left.push((e.kind.name().to_string(), why, alone, model.drive));
        }
    }
    for c in plant.custom.iter() {
        let mut alone = plant;
        alone.custom.remove(c.name());
        left.push((
            format!("{} (user-defined)", c.name()),
            "an expression of servo's; MuJoCo has no user-defined torques in MJCF".to_string(),
            alone,
            model.drive,
        ));
    }
    reduced.custom = servo_core::custom::CustomSlots::NONE;
    if model.drive.kind == DriveKind::Duty && model.drive.dead_fraction() > 0.0 {
        let mut d = model.drive;
        d.t_dead_s = None;
        d.f_pwm_hz = None;
        reduced_drive = d;
        left.push((
            "PWM dead-time loss".to_string(),
            "V_supply t_dead f_pwm against the sign of the duty: an offset MuJoCo's linear \
             actuator cannot write"
                .to_string(),
            plant,
            d,
        ));
    }

    // The error each leaves, on random command steps over the command's range.
    let cmd_max = ctrl_max.unwrap_or(DEFAULT_CMD_MAX);
    let steps = RandomSteps {
        hold_samples: 400,
        min_v: 0.1 * cmd_max,
        span_v: 0.9 * cmd_max,
        ramps: None,
        seed: 7,
    };
    let cmds = steps.voltages((PROBE_S / PROBE_DT_S) as usize, PROBE_DT_S);
    let full = response(&plant, &model.drive, &cmds)?;
    let (lo, hi) = full
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let travel = (hi - lo).max(0.0) * per;
    let mut left_out = Vec::new();
    for (name, why, alone, drive) in &left {
        let r = response(alone, drive, &cmds)?;
        left_out.push(LeftOut {
            name: name.clone(),
            why: why.clone(),
            rmse: rmse(&full, &r) * per,
        });
    }
    let rmse_all = if left.is_empty() {
        0.0
    } else {
        rmse(&full, &response(&reduced, &reduced_drive, &cmds)?) * per
    };

    // Gravity: a point mass at an arm (hinge only).
    let gravity = if linear {
        None
    } else {
        plant
            .effects
            .get(effects::GRAVITY)
            .and_then(|e| Some((e.get("amplitude")?, e.get("phase").unwrap_or(0.0))))
            .filter(|(a, _)| *a > 0.0)
    };
    let (mass, pos, own) = match gravity {
        Some((a, phi)) => {
            let l = POINT_SHARE * body * G_M_S2 / a;
            let m = a / (G_M_S2 * l);
            notes.push(format!(
                "gravity: servo identifies m g L = {} N m and the total inertia, not m and L \
                 apart; the body is a point mass m = {} kg at L = {} m (m L^2 is {} % of its \
                 inertia) with phase {} rad",
                short(a),
                short(m),
                short(l),
                POINT_SHARE * 100.0,
                short(phi)
            ));
            (
                m,
                format!("0 {} {}", num(l * phi.sin()), num(-l * phi.cos())),
                (1.0 - POINT_SHARE) * body,
            )
        }
        // Without gravity the hinge body's mass plays no part; a slide's is the moving mass.
        None if linear => (body, "0 0 0".to_string(), body * 1e-4),
        None => (1.0, "0 0 0".to_string(), body),
    };

    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="utf-8"?>"#);
    let mut head = vec![
        format!(
            "written by servo {} from {source}: the load as one {joint} joint (position {}), \
             the drive as one general actuator whose ctrl is the drive's command [{}]",
            env!("CARGO_PKG_VERSION"),
            if linear {
                "x = s theta_l [m]"
            } else {
                "theta_l [rad]"
            },
            act.ctrl_unit
        ),
        format!(
            "gear = N{} = {}; gainprm: motor torque per unit of ctrl [N m]{}{}",
            if linear { " / s" } else { "" },
            short(n / per),
            if act.bias_v != 0.0 {
                "; biasprm[2]: the back-EMF's torque per motor rad/s"
            } else {
                ""
            },
            if act.lag_s >= NO_LAG_S {
                "; dynprm: the drive's lag [s]"
            } else {
                ""
            }
        ),
    ];
    head.extend(notes.iter().cloned());
    head.extend(summary_lines(&left_out, rmse_all, travel, position_unit));
    let _ = writeln!(x, "<!--");
    for h in &head {
        let _ = writeln!(x, "  {}", comment(h));
    }
    let _ = writeln!(x, "-->");
    let _ = writeln!(x, r#"<mujoco model="{}">"#, attr(name));
    let _ = writeln!(x, r#"  <compiler angle="radian"/>"#);
    let _ = writeln!(
        x,
        r#"  <option timestep="{}" integrator="implicitfast" gravity="0 0 {}"/>"#,
        num(TIMESTEP_S),
        num(-G_M_S2)
    );
    let _ = writeln!(x, "  <worldbody>");
    let _ = writeln!(x, r#"    <body name="load">"#);
    let _ = writeln!(
        x,
        r#"      <joint name="load" type="{joint}" axis="1 0 0" armature="{}" damping="{}" frictionloss="{}"/>"#,
        num(armature),
        num(damping),
        num(frictionloss)
    );
    let _ = writeln!(
        x,
        r#"      <inertial pos="{pos}" mass="{}" diaginertia="{i} {i} {i}"/>"#,
        num(mass),
        i = num(own)
    );
    let _ = writeln!(x, "    </body>");
    let _ = writeln!(x, "  </worldbody>");
    let _ = writeln!(x, "  <actuator>");
    let mut a = format!(
        r#"    <general name="drive" joint="load" gear="{}""#,
        num(n / per)
    );
    if act.lag_s >= NO_LAG_S {
        let _ = write!(a, r#" dyntype="filterexact" dynprm="{}""#, num(act.lag_s));
    }
    let _ = write!(a, r#" gaintype="fixed" gainprm="{}""#, num(act.gain));
    if act.bias_v != 0.0 {
        let _ = write!(a, r#" biastype="affine" biasprm="0 0 {}""#, num(act.bias_v));
    }
    if let Some(c) = ctrl_max {
        let _ = write!(
            a,
            r#" ctrllimited="true" ctrlrange="{} {}""#,
            num(-c),
            num(c)
        );
    }
    if let Some(f) = act.force_max {
        let _ = write!(
            a,
            r#" forcelimited="true" forcerange="{} {}""#,
            num(-f),
            num(f)
        );
    }
    let _ = writeln!(x, "{a}/>");
    let _ = writeln!(x, "  </actuator>");
    let _ = writeln!(x, "</mujoco>");
    Ok(Mjcf {
        xml: x,
        joint,
        position_unit,
        ctrl_unit: act.ctrl_unit,
        left_out,
        rmse_all,
        travel,
        notes,
    })
}

/// Writes the MJCF of the model file `model_path` to `out` (atomically, through
/// [`crate::output`]), named after the output file's stem.
pub fn export(model_path: &Path, out: &Path) -> Result<(Mjcf, crate::output::Written)> {
    let model = ModelFile::load(model_path)?;
    let name = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "servo".to_string());
    let m = to_mjcf(&model, &name, &model_path.display().to_string())?;
    let w = crate::output::write_file(out, "MJCF model", m.xml.as_bytes())?;
    Ok((m, w))
}

#[cfg(test)]
mod tests {
    use super::*;
    use servo_core::effects::Effect;
    use servo_core::PlantParams;

    fn lab() -> ModelFile {
        ModelFile::from_plant(&Plant::lab())
    }

    /// Every `<` opens a tag that is closed (or self-closed) in order; attributes are quoted.
    fn well_formed(xml: &str) -> std::result::Result<(), String> {
        let body = xml
            .split_once("-->")
            .map(|(_, b)| b)
            .ok_or("no header comment")?;
        let mut stack: Vec<String> = Vec::new();
        let mut rest = body;
        while let Some(i) = rest.find('<') {
            let j = rest[i..].find('>').ok_or("unclosed tag")? + i;
            let tag = &rest[i + 1..j];
            if tag.contains('<') {
                return Err(format!("'<' inside a tag: {tag}"));
            }
            if tag.matches('"').count() % 2 != 0 {
                return Err(format!("unbalanced quotes: {tag}"));
            }
            if let Some(name) = tag.strip_prefix('/') {
                if stack.pop().as_deref() != Some(name) {
                    return Err(format!("</{name}> closes nothing open"));
                }
            } else if !tag.ends_with('/') {
                let name = tag.split_whitespace().next().ok_or("empty tag")?;
                stack.push(name.to_string());
            }
            rest = &rest[j + 1..];
        }
        if stack.is_empty() {
            Ok(())
        } else {
            Err(format!("left open: {stack:?}"))
        }
    }

    fn attr_of(xml: &str, key: &str) -> f64 {
        let k = format!(" {key}=\"");
        let i = xml.find(&k).map(|i| i + k.len()).unwrap_or(0);
        let v = &xml[i..i + xml[i..].find('"').unwrap_or(0)];
        v.split_whitespace()
            .last()
            .and_then(|s| s.parse().ok())
            .unwrap_or(f64::NAN)
    }

    #[test]
    fn a_voltage_drive_gives_the_handout_constants_at_the_load() {
        let m = to_mjcf(&lab(), "lab", "lab.toml").unwrap();
        assert!(
            well_formed(&m.xml).is_ok(),
            "{:?}\n{}",
            well_formed(&m.xml),
            m.xml
        );
        let p = PlantParams::LAB;
        let n = p.n;
        assert_eq!(m.joint, "hinge");
        assert_eq!(m.ctrl_unit, "V");
        assert_eq!(attr_of(&m.xml, "gear"), n);
        assert_eq!(attr_of(&m.xml, "gainprm"), p.k_t * p.k_drv / p.r_eq());
        assert_eq!(attr_of(&m.xml, "biasprm"), -p.k_t * p.k_e / p.r_eq());
        assert_eq!(attr_of(&m.xml, "damping"), n * n * 1e-6);
        assert_eq!(attr_of(&m.xml, "frictionloss"), 9e-3);
        let total = attr_of(&m.xml, "armature") + attr_of(&m.xml, "diaginertia");
        assert!((total / (n * n * 7e-7) - 1.0).abs() < 1e-12, "{total}");
        assert_eq!(attr_of(&m.xml, "armature"), n * n * p.j_m);
        assert!(m.left_out.is_empty());
    }

    #[test]
    fn names_and_comments_are_escaped() {
        let m = to_mjcf(&lab(), "a<b>&\"c'--", "x--y.toml").unwrap();
        assert!(
            m.xml.contains(r#"model="a&lt;b&gt;&amp;&quot;c&apos;--""#),
            "{}",
            m.xml
        );
        let (c, _) = m.xml.split_once("-->").unwrap();
        let inner = c.split_once("<!--").unwrap().1;
        assert!(!inner.contains("--"), "{inner}");
        assert!(well_formed(&m.xml).is_ok());
        assert_eq!(comment("a--b-"), "a- -b- ");
        assert_eq!(attr("x\ny"), "x y");
    }

    #[test]
    fn what_mujoco_cannot_express_is_listed_with_its_error() {
        let mut model = lab();
        let delay = EffectKind::from_name("delay").unwrap();
        model.effects.insert(Effect::new(delay, &[0.02]).unwrap());
        let m = to_mjcf(&model, "d", "d.toml").unwrap();
        assert_eq!(m.left_out.len(), 1, "{:?}", m.left_out);
        assert_eq!(m.left_out[0].name, "delay");
        assert!(m.left_out[0].rmse > 0.0 && m.travel > 0.0);
        assert!(m.xml.contains("left out"), "{}", m.xml);
        assert!(m.summary().iter().any(|l| l.contains("delay")));
    }

    #[test]
    fn a_duty_drive_without_its_supply_is_refused() {
        let mut model = lab();
        model.drive = Drive::duty(None, None);
        let e = to_mjcf(&model, "d", "d.toml").unwrap_err().to_string();
        assert!(e.contains("v_supply_v"), "{e}");
    }

    #[test]
    fn a_screw_is_a_slide_in_metres() {
        use servo_core::transmission::{EncoderSide, Transmission, TransmissionKind};
        let mut model = lab();
        let lead = 0.012;
        model.transmission = Transmission {
            kind: TransmissionKind::Screw { lead_m: lead },
            encoder: EncoderSide::Load,
        };
        let gravity = Effect::new(effects::GRAVITY, &[0.05, 0.0]).unwrap();
        model.effects.insert(gravity);
        let m = to_mjcf(&model, "screw", "s.toml").unwrap();
        let s = lead / std::f64::consts::TAU;
        let n = PlantParams::LAB.n;
        assert_eq!((m.joint, m.position_unit), ("slide", "m"));
        assert!(m.xml.contains(r#"type="slide""#));
        assert!((attr_of(&m.xml, "gear") / (n / s) - 1.0).abs() < 1e-12);
        assert!((attr_of(&m.xml, "frictionloss") / (9e-3 / s) - 1.0).abs() < 1e-12);
        assert!((attr_of(&m.xml, "damping") / (n * n * 1e-6 / (s * s)) - 1.0).abs() < 1e-12);
        let mass = attr_of(&m.xml, "mass") + attr_of(&m.xml, "armature");
        assert!(
            (mass / (n * n * 7e-7 / (s * s)) - 1.0).abs() < 1e-12,
            "{mass}"
        );
        // Gravity on a linear axis is a constant force, not this periodic torque: left out.
        assert_eq!(m.left_out.len(), 1, "{:?}", m.left_out);
        assert_eq!(m.left_out[0].name, effects::GRAVITY.name());
    }

    #[test]
    fn a_current_drive_is_a_torque_source_in_amps() {
        let mut model = lab();
        model.drive = Drive {
            i_limit_a: Some(2.0),
            ..Drive::current(Some(200.0))
        };
        let m = to_mjcf(&model, "c", "c.toml").unwrap();
        let k_t = PlantParams::LAB.k_t;
        assert_eq!(m.ctrl_unit, "A");
        assert_eq!(attr_of(&m.xml, "gainprm"), k_t);
        assert!(!m.xml.contains("biasprm="), "{}", m.xml);
        assert_eq!(attr_of(&m.xml, "ctrlrange"), 2.0);
        assert_eq!(attr_of(&m.xml, "forcerange"), k_t * 2.0);
        let lag = 1.0 / (std::f64::consts::TAU * 200.0);
        assert!((attr_of(&m.xml, "dynprm") / lag - 1.0).abs() < 1e-12);
    }

    #[test]
    fn gravity_is_a_point_mass_whose_m_g_l_is_the_amplitude() {
        let mut model = lab();
        let (a, phi) = (0.08, 0.3);
        model
            .effects
            .insert(Effect::new(effects::GRAVITY, &[a, phi]).unwrap());
        let m = to_mjcf(&model, "arm", "a.toml").unwrap();
        let mass = attr_of(&m.xml, "mass");
        let k = " pos=\"0 ";
        let i = m.xml.find(k).unwrap() + k.len();
        let yz: Vec<f64> = m.xml[i..i + m.xml[i..].find('"').unwrap()]
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let l = yz[0].hypot(yz[1]);
        assert!((mass * G_M_S2 * l / a - 1.0).abs() < 1e-9);
        // theta_l = 0 is phi past the bottom: y = L sin(phi), z = -L cos(phi).
        assert!((yz[0].atan2(-yz[1]) - phi).abs() < 1e-9, "{yz:?}");
        assert!(m.left_out.is_empty());
    }

    #[test]
    fn a_duty_drive_takes_the_duty_and_lists_its_dead_time() {
        let mut model = lab();
        model.drive = Drive {
            t_dead_s: Some(2e-6),
            f_pwm_hz: Some(20e3),
            duty_limit: Some(0.95),
            ..Drive::duty(Some(12.0), None)
        };
        let m = to_mjcf(&model, "d", "d.toml").unwrap();
        let p = PlantParams::LAB;
        assert_eq!(m.ctrl_unit, "duty (fraction)");
        assert_eq!(
            attr_of(&m.xml, "gainprm"),
            p.k_t * p.k_drv * 12.0 / p.r_eq()
        );
        assert_eq!(attr_of(&m.xml, "ctrlrange"), 0.95);
        assert_eq!(m.left_out.len(), 1, "{:?}", m.left_out);
        assert!(m.left_out[0].name.contains("dead-time"));
        assert!(m.left_out[0].rmse > 0.0);
    }
}
