//! `--add NAME[:key=value,...]`: a catalogue effect or a user-defined one from `--effects`.

use anyhow::anyhow;
use servo_core::fit::EffectToFit;

/// An effect given to `--add`: from the catalogue, or user-defined (from `--effects`) with its
/// unknown parameters NaN.
pub use servo_core::compare::logs::AddEffect as Added;

/// Parsing `--add`.
pub trait ParseAdded: Sized {
    /// Parses `name[:key=value,...]`: a user effect of `library` when the name is one, else a
    /// catalogue effect.
    fn parse(spec: &str, library: &crate::effects_file::EffectsFile) -> anyhow::Result<Self>;
}

impl ParseAdded for Added {
    /// Parses `name[:key=value,...]`: a user effect of `library` when the name is one, else a
    /// catalogue effect.
    fn parse(spec: &str, library: &crate::effects_file::EffectsFile) -> anyhow::Result<Added> {
        let (name, rest) = match spec.split_once(':') {
            Some((n, r)) => (n.trim(), Some(r)),
            None => (spec.trim(), None),
        };
        let Some(def) = library.get(name) else {
            return EffectToFit::parse(spec).map(Added::Catalogue).map_err(|e| {
                if library.defs.is_empty() {
                    anyhow!("--add {spec}: {e}")
                } else {
                    anyhow!(
                        "--add {spec}: {e}; the effects files define {}",
                        library.names()
                    )
                }
            });
        };
        let mut active = def.active();
        for v in active.values.iter_mut() {
            *v = f64::NAN;
        }
        for item in rest.into_iter().flat_map(|r| r.split(',')).map(str::trim) {
            if item.is_empty() {
                continue;
            }
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| anyhow!("--add {spec}: expected key=value, got `{item}`"))?;
            let x: f64 = v.trim().parse().map_err(|_| {
                anyhow!(
                    "--add {spec}: `{}` needs a number, got `{}`",
                    k.trim(),
                    v.trim()
                )
            })?;
            active
                .set(k.trim(), x)
                .map_err(|e| anyhow!("--add {spec}: {e}"))?;
        }
        Ok(Added::Custom(active))
    }
}
