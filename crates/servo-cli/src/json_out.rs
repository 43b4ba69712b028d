//! Where a command's `--json` object goes: printed on stdout (the CLI), or, inside
//! [`capture`], handed back to the caller instead (the Python binding, `python/`): one code
//! path builds the JSON for both, so the package's `.to_dict()` and the CLI's `--json` never
//! drift apart.

use serde_json::Value;
use std::cell::RefCell;

thread_local! {
    /// The objects emitted on this thread inside [`capture`]; `None` outside it.
    static CAPTURED: RefCell<Option<Vec<Value>>> = const { RefCell::new(None) };
}

/// Prints `v` pretty on stdout (a closed pipe drops it, as `outln!`), or keeps it for the
/// enclosing [`capture`] on this thread.
pub fn emit(v: &Value) -> anyhow::Result<()> {
    let kept = CAPTURED.with(|c| match c.borrow_mut().as_mut() {
        Some(list) => {
            list.push(v.clone());
            true
        }
        None => false,
    });
    if !kept {
        outln!("{}", serde_json::to_string_pretty(v)?);
    }
    Ok(())
}

/// Runs `f` with this thread's [`emit`]s kept instead of printed; returns its result and the
/// objects emitted, in order. Nested captures keep to the innermost.
pub fn capture<R>(f: impl FnOnce() -> R) -> (R, Vec<Value>) {
    let outer = CAPTURED.with(|c| c.replace(Some(Vec::new())));
    /// Restores the outer capture even when `f` unwinds.
    struct Restore(Option<Option<Vec<Value>>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            if let Some(outer) = self.0.take() {
                CAPTURED.with(|c| *c.borrow_mut() = outer);
            }
        }
    }
    let mut restore = Restore(Some(outer));
    let r = f();
    let outer = restore.0.take().unwrap_or_default();
    let got = CAPTURED.with(|c| c.replace(outer)).unwrap_or_default();
    (r, got)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn captured_objects_come_back_in_order_and_nest() {
        let ((), outer) = capture(|| {
            emit(&serde_json::json!({"a": 1})).unwrap();
            let ((), inner) = capture(|| emit(&serde_json::json!({"b": 2})).unwrap());
            assert_eq!(inner, vec![serde_json::json!({"b": 2})]);
            emit(&serde_json::json!({"c": 3})).unwrap();
        });
        assert_eq!(
            outer,
            vec![serde_json::json!({"a": 1}), serde_json::json!({"c": 3})]
        );
    }
}
