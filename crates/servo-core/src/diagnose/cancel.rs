//! An optional cancel hook for a long diagnosis: a shared flag that the caller sets (from a
//! signal handler, a UI, the Python binding on Ctrl-C) and the diagnosis reads between its
//! stages and candidates, returning [`FitError::Cancelled`] instead of finishing.
//!
//! The flag is read, never written, by the library; a diagnosis without one
//! ([`Cancel::default`], the default of [`super::DiagnoseOptions`]) never stops early. A
//! candidate fit already running finishes first: the latency is that of one candidate (well
//! under a second to a few seconds on minutes of logs).

use crate::fit::FitError;
use alloc::sync::Arc;
use core::sync::atomic::{AtomicBool, Ordering};

/// A cancel flag shared with the caller, or none.
#[derive(Debug, Clone, Default)]
pub struct Cancel(Option<Arc<AtomicBool>>);

impl Cancel {
    /// A hook reading `flag`: the diagnosis stops at its next check once it is `true`.
    pub fn on(flag: Arc<AtomicBool>) -> Cancel {
        Cancel(Some(flag))
    }

    /// Whether the caller asked to stop.
    pub fn requested(&self) -> bool {
        self.0.as_ref().is_some_and(|f| f.load(Ordering::Relaxed))
    }

    /// `Err(FitError::Cancelled)` once the caller asked to stop.
    pub fn check(&self) -> Result<(), FitError> {
        if self.requested() {
            Err(FitError::Cancelled)
        } else {
            Ok(())
        }
    }
}

/// Two hooks are equal when both are absent or both read the same flag (options compare equal
/// whatever the flag's value now).
impl PartialEq for Cancel {
    fn eq(&self, other: &Cancel) -> bool {
        match (&self.0, &other.0) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::{diagnose, DiagnoseOptions};
    use crate::fit::tests::{open_loop_log, truth};

    #[test]
    fn a_set_flag_stops_the_diagnosis_with_cancelled() {
        let truth = truth();
        let log = open_loop_log(&truth, 6.0, 3, true);
        let flag = Arc::new(AtomicBool::new(true));
        let opts = DiagnoseOptions {
            cancel: Cancel::on(flag.clone()),
            ..DiagnoseOptions::default()
        };
        let model = crate::plant::Plant::from_params(truth.params).unwrap();
        assert_eq!(
            diagnose(core::slice::from_ref(&log), &model, &opts).err(),
            Some(FitError::Cancelled)
        );
        // The same options with the flag cleared run to the end.
        flag.store(false, Ordering::Relaxed);
        assert!(diagnose(&[log], &model, &opts).is_ok());
    }

    #[test]
    fn hooks_compare_by_flag() {
        let f = Arc::new(AtomicBool::new(false));
        assert_eq!(Cancel::on(f.clone()), Cancel::on(f.clone()));
        assert_ne!(Cancel::on(f), Cancel::on(Arc::new(AtomicBool::new(false))));
        assert_eq!(Cancel::default(), Cancel::default());
        assert!(!Cancel::default().requested());
    }
}
