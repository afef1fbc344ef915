//! A fence around third-party decoders that panic on corrupt input.
//!
//! The `laz` crate (0.12) indexes its arithmetic decoder's tables with values read from the
//! file, so some corrupt LAZ files panic inside it (`decoders.rs`, index out of bounds; found
//! by fuzzing, `fuzz/artifacts/las/laz-decoder-panic-*`). [`catch_silently`] turns such a panic
//! into `None` for the caller to report as a format error. While it runs, the process's panic
//! hook (the binary's bug-report message, or the default one) is not called for a panic on
//! this thread: a wrapping hook, installed once, consults a thread-local flag and otherwise
//! defers to the hook it replaced.

use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe};
use std::sync::Once;

thread_local! {
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

static WRAP_HOOK: Once = Once::new();

/// Runs `f`; a panic inside it yields `None` without calling the panic hook.
pub(crate) fn catch_silently<T>(f: impl FnOnce() -> T) -> Option<T> {
    WRAP_HOOK.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let result = panic::catch_unwind(AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    result.ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_none_and_values_pass_through() {
        assert_eq!(catch_silently(|| 7), Some(7));
        let v: Vec<u8> = vec![1, 2];
        let i = v.len() + 3;
        assert_eq!(catch_silently(|| v[i]), None);
        // The flag is cleared again: a nested call and a later call behave the same.
        assert_eq!(
            catch_silently(|| catch_silently(|| v[i]).is_none()),
            Some(true)
        );
        assert_eq!(catch_silently(|| v[0]), Some(1));
    }
}
