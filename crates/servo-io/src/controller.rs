//! The controller of a run from the gains file and the command-line options (PID options and
//! the feedforward selection `--ff`), the record of it that a run's log carries
//! ([`LoggedController`]), and the one function that puts a PID configuration together from
//! these layers ([`pid_config`]): `servo run` and `servo demo` run it, `servo compare` replays it.
//!
//! The option types derive `clap::Args`/`clap::ValueEnum` with the `clap` feature, so that a
//! command-line tool can flatten [`PidOptions`] into its own arguments.

use crate::error::{self as anyhow, anyhow, bail, Context};
use crate::gains_file::GainsFile;
use servo_core::control::{
    AntiWindup, DerivativeOn, Discretization, FeedforwardConfig, PidConfig, PidGains,
};

/// Anti-windup choice on the command line (and in a log's controller record).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum AntiWindupArg {
    /// Not chosen here: the log's record (compare), else back-calculation when --kw or the gains
    /// file has K_w, else none.
    Auto,
    None,
    /// Conditional integration.
    Clamping,
    /// Back-calculation with gain K_w (--kw, the log's record or `kw` of the gains file).
    BackCalc,
}

/// Derivative input on the command line (and in a log's controller record).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum DerivativeOnArg {
    Error,
    Measurement,
}

/// Discretisation on the command line (and in a log's controller record).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum DiscretizationArg {
    /// Not chosen here: the log's record (compare), else as the gains were designed
    /// (`[design] discretization` of the gains file), else backward Euler.
    Auto,
    BackwardEuler,
    Tustin,
}

impl From<Discretization> for DiscretizationArg {
    fn from(d: Discretization) -> Self {
        match d {
            Discretization::BackwardEuler => DiscretizationArg::BackwardEuler,
            Discretization::Tustin => DiscretizationArg::Tustin,
        }
    }
}

impl DiscretizationArg {
    /// The rule, `None` for `auto`.
    pub fn rule(self) -> Option<Discretization> {
        match self {
            DiscretizationArg::Auto => None,
            DiscretizationArg::BackwardEuler => Some(Discretization::BackwardEuler),
            DiscretizationArg::Tustin => Some(Discretization::Tustin),
        }
    }
}

impl From<DerivativeOn> for DerivativeOnArg {
    fn from(d: DerivativeOn) -> Self {
        match d {
            DerivativeOn::Error => DerivativeOnArg::Error,
            DerivativeOn::Measurement => DerivativeOnArg::Measurement,
        }
    }
}

impl From<DerivativeOnArg> for DerivativeOn {
    fn from(d: DerivativeOnArg) -> Self {
        match d {
            DerivativeOnArg::Error => DerivativeOn::Error,
            DerivativeOnArg::Measurement => DerivativeOn::Measurement,
        }
    }
}

impl AntiWindupArg {
    /// The option value (`auto`, `none`, `clamping`, `back-calc`), as on the command line and
    /// in a log's controller record.
    pub fn name(self) -> &'static str {
        match self {
            AntiWindupArg::Auto => "auto",
            AntiWindupArg::None => "none",
            AntiWindupArg::Clamping => "clamping",
            AntiWindupArg::BackCalc => "back-calc",
        }
    }
}

impl DerivativeOnArg {
    /// The option value (`error`, `measurement`).
    pub fn name(self) -> &'static str {
        match self {
            DerivativeOnArg::Error => "error",
            DerivativeOnArg::Measurement => "measurement",
        }
    }
}

impl DiscretizationArg {
    /// The option value (`auto`, `backward-euler`, `tustin`).
    pub fn name(self) -> &'static str {
        match self {
            DiscretizationArg::Auto => "auto",
            DiscretizationArg::BackwardEuler => "backward-euler",
            DiscretizationArg::Tustin => "tustin",
        }
    }
}

/// Options of the PID beyond its gains, as given on the command line of `servo run` and
/// `servo compare` (`auto` or absent: not given, the next source decides).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct PidOptions {
    /// Anti-windup scheme (auto: as the log records it for compare, else back-calculation when
    /// --kw or the gains file's kw gives K_w, else none).
    #[cfg_attr(
        feature = "clap",
        arg(long = "anti-windup", value_enum, default_value = "auto")
    )]
    pub anti_windup: AntiWindupArg,
    /// Back-calculation anti-windup gain K_w [1/s] (overrides the log's and the gains file's kw).
    #[cfg_attr(feature = "clap", arg(long, value_name = "PER_SECOND"))]
    pub kw: Option<f64>,
    /// What the derivative acts on (default: as the log records it for compare, else the error).
    #[cfg_attr(feature = "clap", arg(long = "derivative-on", value_enum))]
    pub derivative_on: Option<DerivativeOnArg>,
    /// Discretisation of the integral and the derivative (auto: as the log records it for
    /// compare, else the gains file's `[design] discretization`, else backward Euler).
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value = "auto"))]
    pub discretization: DiscretizationArg,
}

impl Default for PidOptions {
    /// Nothing given.
    fn default() -> Self {
        PidOptions {
            anti_windup: AntiWindupArg::Auto,
            kw: None,
            derivative_on: None,
            discretization: DiscretizationArg::Auto,
        }
    }
}

/// The controller of a run as its log records it (MCAP metadata key
/// [`crate::meta_keys::CONTROLLER_TOML`], a TOML table): everything needed to rebuild it
/// exactly, with the value names of `servo run`'s options. The feedforward voltage itself is
/// logged per sample (`ff_v` of the loop message). Every field is optional so that a record
/// with fields missing still reads; the missing ones fall back to the next source.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LoggedController {
    /// Proportional gain K_P [V/rad].
    pub kp: Option<f64>,
    /// Integral gain K_I [V/(rad s)].
    pub ki: Option<f64>,
    /// Derivative gain K_D [V s/rad].
    pub kd: Option<f64>,
    /// Real-derivative time constant T_L [s].
    pub tl_s: Option<f64>,
    /// Control period T_s the loop ran at [s].
    pub ts_s: Option<f64>,
    pub discretization: Option<DiscretizationArg>,
    pub derivative_on: Option<DerivativeOnArg>,
    pub anti_windup: Option<AntiWindupArg>,
    /// Back-calculation gain K_w [1/s] (back-calc only).
    pub kw: Option<f64>,
    /// Symmetric output limit [V] (absent: none).
    pub u_limit_v: Option<f64>,
    /// Feedforward terms added to the PID output, in `--ff` form (`none`, `inertia,back_emf`).
    pub feedforward: Option<String>,
}

impl LoggedController {
    /// The record of the controller `pid` as it runs (limits and period as in force), with the
    /// feedforward `ff` (None: none).
    pub fn of(pid: &PidConfig, ff: Option<&FeedforwardConfig>) -> LoggedController {
        let (anti_windup, kw) = match pid.anti_windup {
            AntiWindup::None => (AntiWindupArg::None, None),
            AntiWindup::Clamping => (AntiWindupArg::Clamping, None),
            AntiWindup::BackCalculation { kw } => (AntiWindupArg::BackCalc, Some(kw)),
        };
        let symmetric = pid.u_max_v.is_finite() && pid.u_min_v == -pid.u_max_v;
        LoggedController {
            kp: Some(pid.kp),
            ki: Some(pid.ki),
            kd: Some(pid.kd),
            tl_s: Some(pid.tl_s),
            ts_s: Some(pid.ts_s),
            discretization: Some(pid.discretization.into()),
            derivative_on: Some(pid.derivative_on.into()),
            anti_windup: Some(anti_windup),
            kw,
            u_limit_v: symmetric.then_some(pid.u_max_v),
            feedforward: Some(ff.map_or_else(|| "none".to_string(), ff_name)),
        }
    }

    /// TOML text (the metadata value).
    pub fn to_toml(&self) -> anyhow::Result<String> {
        let body = toml::to_string(self).context("writing the controller record as TOML")?;
        Ok(format!(
            "# the controller as it ran: PID on the load-angle error [rad] -> u [V] plus feedforward\n{body}"
        ))
    }

    /// Parses the metadata value.
    pub fn parse(text: &str) -> anyhow::Result<LoggedController> {
        toml::from_str(text).map_err(|e| anyhow!("{}", e.to_string().trim_end()))
    }

    /// The names of the fields a complete record has but this one lacks (`kw` only with
    /// back-calculation; `u_limit_v` may be absent for an unlimited controller).
    pub fn missing(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        for (name, present) in [
            ("kp", self.kp.is_some()),
            ("ki", self.ki.is_some()),
            ("kd", self.kd.is_some()),
            ("tl_s", self.tl_s.is_some()),
            ("ts_s", self.ts_s.is_some()),
            ("discretization", self.discretization.is_some()),
            ("derivative_on", self.derivative_on.is_some()),
            ("anti_windup", self.anti_windup.is_some()),
            (
                "kw",
                self.kw.is_some() || self.anti_windup != Some(AntiWindupArg::BackCalc),
            ),
            ("feedforward", self.feedforward.is_some()),
        ] {
            if !present {
                v.push(name);
            }
        }
        v
    }
}

/// The record of the controller as it ran, from a log's metadata (`None` for logs without one:
/// CSV, open loop, or written before servo recorded it).
pub fn logged_controller(meta: &crate::LogMeta) -> anyhow::Result<Option<LoggedController>> {
    meta.get(crate::meta_keys::CONTROLLER_TOML)
        .map(|t| LoggedController::parse(t).context("in the log's controller metadata"))
        .transpose()
}

/// One part of a controller configuration, its value and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerPart {
    /// Which part: `gains`, `discretization`, `derivative_on`, `anti_windup`, `u_limit_v`,
    /// `feedforward`.
    pub part: &'static str,
    /// The value in `servo run`'s option names (`tustin`, `measurement`, `back-calc`, `10`).
    pub value: String,
    /// The value in words (`Tustin`, `derivative on the measurement`, ...).
    pub words: String,
    /// Where it came from (`given with --discretization`, `from the log's metadata`, `default`).
    pub source: String,
}

impl ControllerPart {
    fn new(part: &'static str, value: String, words: String, source: &str) -> ControllerPart {
        ControllerPart {
            part,
            value,
            words,
            source: source.to_string(),
        }
    }
}

/// A PID configuration and where each part of it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedPid {
    pub config: PidConfig,
    /// Gains, discretisation, derivative input, anti-windup and output limit, in that order
    /// (callers may add more, e.g. the feedforward).
    pub parts: Vec<ControllerPart>,
}

impl ResolvedPid {
    /// The part named `part`.
    pub fn part(&self, part: &str) -> Option<&ControllerPart> {
        self.parts.iter().find(|p| p.part == part)
    }

    /// One line, e.g. `K_P = 7.5 V/rad, ... (from gains.toml); Tustin (from the log's metadata); ...`.
    pub fn describe(&self) -> String {
        self.parts
            .iter()
            .map(|p| {
                if p.source.is_empty() {
                    p.words.clone()
                } else {
                    format!("{} ({})", p.words, p.source)
                }
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// Where a PID configuration is taken from. Each part takes the first of: the command-line
/// options, the log's record of the controller that ran, the gains file (its `[pid] kw`,
/// `[pid] derivative_on` and `[design] discretization`), the defaults (backward Euler, derivative on the error, no
/// anti-windup). The gains come from the gains file, else from the log's record.
#[derive(Debug, Clone, Copy)]
pub struct PidSources<'a> {
    pub opts: &'a PidOptions,
    /// The log's record of the controller (compare).
    pub logged: Option<&'a LoggedController>,
    /// The gains file and its name in messages (a path, or "the log's gains").
    pub gains_file: Option<(&'a GainsFile, &'a str)>,
}

const FROM_LOG: &str = "from the log's metadata";
const DEFAULT: &str = "default";

/// The PID configuration of `src` at period `ts_s` [s], limited to +-`u_limit_v` [V] (the value
/// and where it came from; `None`: no limit), with the source of every part.
pub fn pid_config(
    src: &PidSources,
    ts_s: f64,
    u_limit_v: Option<(f64, String)>,
) -> anyhow::Result<ResolvedPid> {
    let (opts, logged) = (src.opts, src.logged);
    let file = src.gains_file.map(|(g, _)| g);
    let label = src.gains_file.map_or("", |(_, l)| l);
    // The output's unit: amps for gains designed for a current drive.
    let out = file.map_or("V", GainsFile::output_unit);
    let mut parts = Vec::new();

    // Gains.
    let (gains, gains_src) = match (file, logged) {
        (Some(g), _) => (
            PidGains {
                kp: g.pid.kp,
                ki: g.pid.ki,
                kd: g.pid.kd,
                tl_s: g.pid.tl_s,
            },
            format!("from {label}"),
        ),
        (None, Some(l)) => (
            PidGains {
                kp: l
                    .kp
                    .ok_or_else(|| anyhow!("the log's controller record has no kp"))?,
                ki: l.ki.unwrap_or(0.0),
                kd: l.kd.unwrap_or(0.0),
                tl_s: l.tl_s.unwrap_or(0.0),
            },
            FROM_LOG.to_string(),
        ),
        (None, None) => bail!("no controller gains: give a gains file (--gains gains.toml)"),
    };
    parts.push(ControllerPart::new(
        "gains",
        format!(
            "kp={},ki={},kd={},tl_s={}",
            gains.kp, gains.ki, gains.kd, gains.tl_s
        ),
        format!(
            "K_P = {:.5} {out}/rad, K_I = {:.5} {out}/(rad s), K_D = {:.5} {out} s/rad, T_L = {:.4e} s at T_s = {ts_s:.4e} s",
            gains.kp, gains.ki, gains.kd, gains.tl_s
        ),
        &gains_src,
    ));

    // Discretisation.
    let design_disc = match file
        .and_then(|g| g.design.as_ref())
        .and_then(|d| d.get("discretization"))
        .and_then(|v| v.as_str())
    {
        Some("tustin") => Some(Discretization::Tustin),
        Some("backward-euler") | Some("backward_euler") => Some(Discretization::BackwardEuler),
        None => None,
        Some(other) => bail!(
            "{label}: [design] discretization = `{other}`; expected `tustin` or `backward-euler`"
        ),
    };
    let design_src = format!("from the [design] of {label}");
    let (discretization, s) = if let Some(d) = opts.discretization.rule() {
        (d, "given with --discretization")
    } else if let Some(d) = logged.and_then(|l| l.discretization).and_then(|d| d.rule()) {
        (d, FROM_LOG)
    } else if let Some(d) = design_disc {
        (d, design_src.as_str())
    } else {
        (Discretization::BackwardEuler, DEFAULT)
    };
    parts.push(ControllerPart::new(
        "discretization",
        DiscretizationArg::from(discretization).name().to_string(),
        match discretization {
            Discretization::BackwardEuler => "backward Euler".into(),
            Discretization::Tustin => "Tustin".into(),
        },
        s,
    ));

    // Derivative input.
    let file_d_src = format!("from {label} [pid] derivative_on");
    let file_d = file
        .and_then(|g| g.pid.derivative_on)
        .map(DerivativeOnArg::from);
    let (derivative_on, s) = match (
        opts.derivative_on,
        logged.and_then(|l| l.derivative_on),
        file_d,
    ) {
        (Some(d), _, _) => (d, "given with --derivative-on"),
        (None, Some(d), _) => (d, FROM_LOG),
        (None, None, Some(d)) => (d, file_d_src.as_str()),
        (None, None, None) => (DerivativeOnArg::Error, DEFAULT),
    };
    parts.push(ControllerPart::new(
        "derivative_on",
        derivative_on.name().to_string(),
        format!("derivative on the {}", derivative_on.name()),
        s,
    ));

    // Anti-windup: the scheme, then K_w for back-calculation.
    let logged_aw = logged
        .and_then(|l| l.anti_windup)
        .filter(|a| *a != AntiWindupArg::Auto);
    let file_kw = file.and_then(|g| g.pid.kw);
    let file_kw_src = format!("from {label} [pid] kw");
    let (scheme, s) = if opts.anti_windup != AntiWindupArg::Auto {
        (opts.anti_windup, "given with --anti-windup".to_string())
    } else if opts.kw.is_some() {
        (AntiWindupArg::BackCalc, "given with --kw".to_string())
    } else if let Some(a) = logged_aw {
        (a, FROM_LOG.to_string())
    } else if file_kw.is_some() {
        (AntiWindupArg::BackCalc, file_kw_src.clone())
    } else {
        (AntiWindupArg::None, DEFAULT.to_string())
    };
    let (anti_windup, words, s) = match scheme {
        AntiWindupArg::Auto | AntiWindupArg::None => {
            (AntiWindup::None, "no anti-windup".to_string(), s)
        }
        AntiWindupArg::Clamping => (
            AntiWindup::Clamping,
            "clamping anti-windup (conditional integration)".to_string(),
            s,
        ),
        AntiWindupArg::BackCalc => {
            let (kw, kw_src) = if let Some(kw) = opts.kw {
                (kw, "given with --kw".to_string())
            } else if let Some(kw) = logged.and_then(|l| l.kw) {
                (kw, FROM_LOG.to_string())
            } else if let Some(kw) = file_kw {
                (kw, file_kw_src)
            } else {
                bail!("--anti-windup back-calc needs K_w: give --kw or `kw` in the gains file")
            };
            let s = if kw_src == s {
                s
            } else {
                format!("{s}; K_w {kw_src}")
            };
            (
                AntiWindup::BackCalculation { kw },
                format!("back-calculation anti-windup, K_w = {kw} 1/s"),
                s,
            )
        }
    };
    parts.push(ControllerPart::new(
        "anti_windup",
        scheme.name().to_string(),
        words,
        &s,
    ));

    // Output limit.
    let mut c = PidConfig::new(gains, ts_s);
    match &u_limit_v {
        Some((l, s)) => {
            c = c.with_symmetric_limit(*l);
            parts.push(ControllerPart::new(
                "u_limit_v",
                l.to_string(),
                format!("output limit +-{l} {out}"),
                s,
            ));
        }
        None => parts.push(ControllerPart::new(
            "u_limit_v",
            "none".into(),
            "no output limit".into(),
            "none known",
        )),
    }
    c.anti_windup = anti_windup;
    c.derivative_on = derivative_on.into();
    c.discretization = discretization;
    c.validate().map_err(|e| anyhow!("controller: {e}"))?;
    Ok(ResolvedPid { config: c, parts })
}

/// The period, the voltage limit and the PID of a run (`servo run`).
#[derive(Debug, Clone, PartialEq)]
pub struct RunController {
    /// Control period T_s [s].
    pub ts_s: f64,
    /// Symmetric limit of the driver input [V].
    pub u_limit_v: f64,
    /// The PID (None without a gains file: open loop).
    pub pid: Option<PidConfig>,
    /// The PID in one line, each part with where it came from ([`ResolvedPid::describe`]).
    pub description: Option<String>,
}

/// The controller of a run: T_s from `ts_s` (`--ts`), else the gains file's `ts_s`, else 1 ms;
/// the limit from `u_limit_v` (`--u-limit`), else the gains file's `u_limit_v`, else 10 V; the
/// PID from the gains file (`gains`: the file and its name in messages) and the options, limited
/// to +-the limit ([`pid_config`]).
pub fn run_controller(
    gains: Option<(&GainsFile, &str)>,
    opts: &PidOptions,
    ts_s: Option<f64>,
    u_limit_v: Option<f64>,
) -> anyhow::Result<RunController> {
    let file = gains.map(|(g, _)| g);
    let u_limit_v = u_limit_v
        .or(file.and_then(|g| g.pid.u_limit_v))
        .unwrap_or(10.0);
    if !(u_limit_v.is_finite() && u_limit_v > 0.0) {
        bail!("--u-limit must be > 0 V, got {u_limit_v}");
    }
    let ts_s = ts_s.or(file.map(|g| g.pid.ts_s)).unwrap_or(1e-3);
    if !(ts_s.is_finite() && ts_s > 0.0 && ts_s <= 0.1) {
        bail!("--ts must be a sample period in (0, 0.1] s, got {ts_s}");
    }
    let pid = gains
        .map(|g| {
            let src = PidSources {
                opts,
                logged: None,
                gains_file: Some(g),
            };
            pid_config(&src, ts_s, Some((u_limit_v, String::new())))
        })
        .transpose()?;
    Ok(RunController {
        ts_s,
        u_limit_v,
        description: pid.as_ref().map(ResolvedPid::describe),
        pid: pid.map(|r| r.config),
    })
}

/// The feedforward of the `--ff` terms `terms` ([`parse_ff`]) with the constants of `model`
/// (None: the nominal Table 2 model).
pub fn feedforward(
    terms: &str,
    model: Option<&crate::model_file::ModelFile>,
) -> anyhow::Result<servo_core::control::Feedforward> {
    use servo_core::control::{Feedforward, FeedforwardParams};
    let cfg = parse_ff(terms)?;
    let plant = model
        .cloned()
        .unwrap_or_default()
        .plant()
        .context("--model")?;
    Feedforward::new(FeedforwardParams::from_plant(&plant), cfg)
        .map_err(|e| anyhow!("feedforward: {e}"))
}

/// Parses `--ff`: a comma list of `inertia` (J_eq and back-EMF), `friction` (viscous and
/// Coulomb), or single terms `viscous`, `coulomb`, `back_emf`; `all`; `none`.
pub fn parse_ff(text: &str) -> anyhow::Result<FeedforwardConfig> {
    let mut c = FeedforwardConfig::OFF;
    c.sign = FeedforwardConfig::FULL.sign;
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match item {
            "inertia" => {
                c.inertia = true;
                c.back_emf = true;
            }
            "friction" => {
                c.viscous = true;
                c.coulomb = true;
            }
            "viscous" => c.viscous = true,
            "coulomb" => c.coulomb = true,
            "back_emf" | "bemf" => c.back_emf = true,
            "all" => c = FeedforwardConfig::FULL,
            "none" => c = FeedforwardConfig::OFF,
            other => bail!("--ff: unknown term `{other}`; use inertia, friction, viscous, coulomb, back_emf, all or none"),
        }
    }
    Ok(c)
}

/// The `--ff` form of a configuration (for logs).
pub fn ff_name(c: &FeedforwardConfig) -> String {
    let mut v = Vec::new();
    for (on, name) in [
        (c.inertia, "inertia"),
        (c.back_emf, "back_emf"),
        (c.viscous, "viscous"),
        (c.coulomb, "coulomb"),
    ] {
        if on {
            v.push(name);
        }
    }
    if v.is_empty() {
        "none".into()
    } else {
        v.join(",")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gains_file::PidSection;

    const P: PidSection = PidSection {
        kp: 7.0,
        ki: 86.0,
        kd: 0.14,
        tl_s: 6.7e-3,
        ts_s: 1e-3,
        kw: Some(30.0),
        u_limit_v: None,
        derivative_on: None,
    };

    fn file(p: PidSection, disc: Option<&str>) -> GainsFile {
        GainsFile {
            pid: p,
            design: disc.map(|d| {
                let mut t = toml::Table::new();
                t.insert("discretization".into(), d.into());
                t
            }),
        }
    }

    /// `servo run`'s use: the gains file and the options, a 10 V limit.
    fn run_cfg(g: &GainsFile, o: &PidOptions) -> anyhow::Result<PidConfig> {
        let src = PidSources {
            opts: o,
            logged: None,
            gains_file: Some((g, "gains.toml")),
        };
        pid_config(&src, 1e-3, Some((10.0, "test".into()))).map(|r| r.config)
    }

    #[test]
    fn pid_options_from_the_gains_file() {
        let c = run_cfg(&file(P, None), &PidOptions::default()).unwrap();
        assert_eq!(c.discretization, Discretization::BackwardEuler);
        assert_eq!(c.derivative_on, DerivativeOn::Error);
        assert_eq!(c.anti_windup, AntiWindup::BackCalculation { kw: 30.0 });
        assert_eq!((c.u_min_v, c.u_max_v), (-10.0, 10.0));
        let p2 = PidSection { kw: None, ..P };
        let c = run_cfg(&file(p2, None), &PidOptions::default()).unwrap();
        assert_eq!(c.anti_windup, AntiWindup::None);
        let o = PidOptions {
            anti_windup: AntiWindupArg::BackCalc,
            ..PidOptions::default()
        };
        let e = format!("{:#}", run_cfg(&file(p2, None), &o).unwrap_err());
        assert!(e.contains("--kw"), "{e}");
        // --kw alone asks for back-calculation.
        let o = PidOptions {
            kw: Some(5.0),
            ..PidOptions::default()
        };
        let c = run_cfg(&file(p2, None), &o).unwrap();
        assert_eq!(c.anti_windup, AntiWindup::BackCalculation { kw: 5.0 });
        // derivative input from the gains file, unless given
        let pm = PidSection {
            derivative_on: Some(DerivativeOn::Measurement),
            ..P
        };
        let c = run_cfg(&file(pm, None), &PidOptions::default()).unwrap();
        assert_eq!(c.derivative_on, DerivativeOn::Measurement);
        let o = PidOptions {
            derivative_on: Some(DerivativeOnArg::Error),
            ..PidOptions::default()
        };
        assert_eq!(
            run_cfg(&file(pm, None), &o).unwrap().derivative_on,
            DerivativeOn::Error
        );
        let c = run_cfg(&file(P, Some("tustin")), &PidOptions::default()).unwrap();
        assert_eq!(c.discretization, Discretization::Tustin);
        assert!(run_cfg(&file(P, Some("zoh")), &PidOptions::default()).is_err());
    }

    #[test]
    fn precedence_flags_log_design_defaults() {
        let g = file(P, Some("tustin"));
        let logged = LoggedController {
            discretization: Some(DiscretizationArg::BackwardEuler),
            derivative_on: Some(DerivativeOnArg::Measurement),
            anti_windup: Some(AntiWindupArg::Clamping),
            ..LoggedController::default()
        };
        let resolve = |o: &PidOptions, l: Option<&LoggedController>| {
            pid_config(
                &PidSources {
                    opts: o,
                    logged: l,
                    gains_file: Some((&g, "g.toml")),
                },
                1e-3,
                None,
            )
            .unwrap()
        };
        // The log beats the gains file's [design] and kw.
        let r = resolve(&PidOptions::default(), Some(&logged));
        assert_eq!(r.config.discretization, Discretization::BackwardEuler);
        assert_eq!(r.config.derivative_on, DerivativeOn::Measurement);
        assert_eq!(r.config.anti_windup, AntiWindup::Clamping);
        assert_eq!(r.part("discretization").unwrap().source, FROM_LOG);
        assert_eq!(r.part("gains").unwrap().source, "from g.toml");
        assert!(r.config.u_max_v.is_infinite());
        // Flags beat the log.
        let o = PidOptions {
            discretization: DiscretizationArg::Tustin,
            derivative_on: Some(DerivativeOnArg::Error),
            anti_windup: AntiWindupArg::BackCalc,
            kw: None,
        };
        let r = resolve(&o, Some(&logged));
        assert_eq!(r.config.discretization, Discretization::Tustin);
        assert_eq!(r.config.derivative_on, DerivativeOn::Error);
        // K_w: not in the log, so from the gains file.
        assert_eq!(
            r.config.anti_windup,
            AntiWindup::BackCalculation { kw: 30.0 }
        );
        let aw = r.part("anti_windup").unwrap();
        assert_eq!(aw.value, "back-calc");
        assert!(
            aw.source.contains("--anti-windup") && aw.source.contains("g.toml"),
            "{aw:?}"
        );
        // Without a log: the [design], then the defaults.
        let r = resolve(&PidOptions::default(), None);
        assert_eq!(r.config.discretization, Discretization::Tustin);
        assert_eq!(r.part("discretization").unwrap().words, "Tustin");
        assert!(
            r.describe()
                .contains("Tustin (from the [design] of g.toml)"),
            "{}",
            r.describe()
        );
        assert_eq!(r.part("derivative_on").unwrap().source, DEFAULT);
    }

    #[test]
    fn logged_controller_round_trip() {
        let mut c = PidConfig::new(
            PidGains {
                kp: 7.0,
                ki: 86.0,
                kd: 0.14,
                tl_s: 6.7e-3,
            },
            1e-3,
        )
        .with_symmetric_limit(9.0);
        c.discretization = Discretization::Tustin;
        c.derivative_on = DerivativeOn::Measurement;
        c.anti_windup = AntiWindup::BackCalculation { kw: 25.0 };
        let ff = parse_ff("inertia").unwrap();
        let rec = LoggedController::of(&c, Some(&ff));
        let text = rec.to_toml().unwrap();
        assert!(
            text.contains("discretization = \"tustin\"") && text.contains("\"back-calc\""),
            "{text}"
        );
        let back = LoggedController::parse(&text).unwrap();
        assert_eq!(back, rec);
        assert!(back.missing().is_empty());
        assert_eq!(back.feedforward.as_deref(), Some("inertia,back_emf"));
        // The record alone rebuilds the controller exactly.
        let r = pid_config(
            &PidSources {
                opts: &PidOptions::default(),
                logged: Some(&back),
                gains_file: None,
            },
            1e-3,
            back.u_limit_v.map(|l| (l, FROM_LOG.to_string())),
        )
        .unwrap();
        assert_eq!(r.config, c);
        // An old or partial record: what is missing is named.
        let old = LoggedController::parse("kp = 1.0\nanti_windup = \"back-calc\"\n").unwrap();
        assert_eq!(
            old.missing(),
            vec![
                "ki",
                "kd",
                "tl_s",
                "ts_s",
                "discretization",
                "derivative_on",
                "kw",
                "feedforward"
            ]
        );
    }

    #[test]
    fn option_names_are_the_serde_and_clap_names() {
        fn check<T: serde::Serialize + Copy>(all: &[T], name: impl Fn(T) -> &'static str) {
            for &v in all {
                assert_eq!(
                    serde_json::to_string(&v).unwrap(),
                    format!("\"{}\"", name(v))
                );
            }
        }
        use AntiWindupArg as A;
        use DiscretizationArg as D;
        check(&[A::Auto, A::None, A::Clamping, A::BackCalc], A::name);
        check(
            &[DerivativeOnArg::Error, DerivativeOnArg::Measurement],
            |d| d.name(),
        );
        check(&[D::Auto, D::BackwardEuler, D::Tustin], D::name);
        #[cfg(feature = "clap")]
        {
            use clap::ValueEnum;
            for a in A::value_variants() {
                assert_eq!(a.to_possible_value().unwrap().get_name(), a.name());
            }
            for d in D::value_variants() {
                assert_eq!(d.to_possible_value().unwrap().get_name(), d.name());
            }
            for d in DerivativeOnArg::value_variants() {
                assert_eq!(d.to_possible_value().unwrap().get_name(), d.name());
            }
        }
    }

    #[test]
    fn feedforward_names() {
        let ff = parse_ff("inertia,friction").unwrap();
        assert!(ff.inertia && ff.viscous && ff.coulomb && ff.back_emf);
        assert_eq!(ff_name(&parse_ff("friction").unwrap()), "viscous,coulomb");
        assert!(parse_ff("magic").is_err());
    }
}
