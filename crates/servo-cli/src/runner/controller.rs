//! The controller of a run from the gains file and the command-line options: PID options and
//! the feedforward selection (`--ff inertia,friction`).

use crate::gains_file::GainsFile;
use anyhow::{anyhow, bail};
use servo_core::control::{
    AntiWindup, DerivativeOn, Discretization, FeedforwardConfig, PidConfig, PidGains,
};

/// Anti-windup choice on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AntiWindupArg {
    /// The gains file decides: back-calculation when it has `kw`, else none.
    Auto,
    None,
    /// Conditional integration.
    Clamping,
    /// Back-calculation with gain K_w (`kw` of the gains file or --kw).
    BackCalc,
}

/// Derivative input on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DerivativeOnArg {
    Error,
    Measurement,
}

/// Discretisation on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DiscretizationArg {
    /// As the gains were designed (`[design] discretization` of the gains file), else
    /// backward Euler.
    Auto,
    BackwardEuler,
    Tustin,
}

/// Options of the PID beyond its gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidOptions {
    pub anti_windup: AntiWindupArg,
    /// Overrides the gains file's K_w [1/s].
    pub kw: Option<f64>,
    pub derivative_on: DerivativeOnArg,
    pub discretization: DiscretizationArg,
}

impl Default for PidOptions {
    fn default() -> Self {
        PidOptions {
            anti_windup: AntiWindupArg::Auto,
            kw: None,
            derivative_on: DerivativeOnArg::Error,
            discretization: DiscretizationArg::Auto,
        }
    }
}

/// The PID configuration of a gains file with `opts`, at period `ts_s` [s], limited to
/// +-`u_limit_v` [V].
pub fn pid_config(
    g: &GainsFile,
    opts: &PidOptions,
    ts_s: f64,
    u_limit_v: f64,
) -> anyhow::Result<PidConfig> {
    let p = &g.pid;
    let kw = opts.kw.or(p.kw);
    let anti_windup = match opts.anti_windup {
        AntiWindupArg::Auto => kw.map_or(AntiWindup::None, |kw| AntiWindup::BackCalculation { kw }),
        AntiWindupArg::None => AntiWindup::None,
        AntiWindupArg::Clamping => AntiWindup::Clamping,
        AntiWindupArg::BackCalc => AntiWindup::BackCalculation {
            kw: kw.ok_or_else(|| {
                anyhow!("--anti-windup back-calc needs K_w: give --kw or `kw` in the gains file")
            })?,
        },
    };
    let mut c = PidConfig::new(
        PidGains {
            kp: p.kp,
            ki: p.ki,
            kd: p.kd,
            tl_s: p.tl_s,
        },
        ts_s,
    )
    .with_symmetric_limit(u_limit_v);
    c.anti_windup = anti_windup;
    c.derivative_on = match opts.derivative_on {
        DerivativeOnArg::Error => DerivativeOn::Error,
        DerivativeOnArg::Measurement => DerivativeOn::Measurement,
    };
    c.discretization = match opts.discretization {
        DiscretizationArg::Auto => match g.design.as_ref().and_then(|d| d.get("discretization")).and_then(|v| v.as_str()) {
            Some("tustin") => Discretization::Tustin,
            Some("backward-euler") | Some("backward_euler") | None => Discretization::BackwardEuler,
            Some(other) => bail!("gains file: [design] discretization = `{other}`; expected `tustin` or `backward-euler`"),
        },
        DiscretizationArg::BackwardEuler => Discretization::BackwardEuler,
        DiscretizationArg::Tustin => Discretization::Tustin,
    };
    c.validate().map_err(|e| anyhow!("controller: {e}"))?;
    Ok(c)
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

    #[test]
    fn pid_options_and_ff() {
        use crate::gains_file::PidSection;
        let p = PidSection {
            kp: 7.0,
            ki: 86.0,
            kd: 0.14,
            tl_s: 6.7e-3,
            ts_s: 1e-3,
            kw: Some(30.0),
            u_limit_v: None,
        };
        let g = |p: PidSection| GainsFile {
            pid: p,
            design: None,
        };
        let c = pid_config(&g(p), &PidOptions::default(), 1e-3, 10.0).unwrap();
        assert_eq!(c.discretization, Discretization::BackwardEuler);
        assert_eq!(c.anti_windup, AntiWindup::BackCalculation { kw: 30.0 });
        assert_eq!((c.u_min_v, c.u_max_v), (-10.0, 10.0));
        let p2 = PidSection { kw: None, ..p };
        assert_eq!(
            pid_config(&g(p2), &PidOptions::default(), 1e-3, 10.0)
                .unwrap()
                .anti_windup,
            AntiWindup::None
        );
        let o = PidOptions {
            anti_windup: AntiWindupArg::BackCalc,
            ..PidOptions::default()
        };
        assert!(format!("{:#}", pid_config(&g(p2), &o, 1e-3, 10.0).unwrap_err()).contains("--kw"));
        let mut d = toml::Table::new();
        d.insert("discretization".into(), "tustin".into());
        let gt = GainsFile {
            pid: p,
            design: Some(d),
        };
        assert_eq!(
            pid_config(&gt, &PidOptions::default(), 1e-3, 10.0)
                .unwrap()
                .discretization,
            Discretization::Tustin
        );
        let ff = parse_ff("inertia,friction").unwrap();
        assert!(ff.inertia && ff.viscous && ff.coulomb && ff.back_emf);
        assert_eq!(ff_name(&parse_ff("friction").unwrap()), "viscous,coulomb");
        assert!(parse_ff("magic").is_err());
    }
}
