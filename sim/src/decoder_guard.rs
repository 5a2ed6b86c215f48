//! Panics of third-party decoders turned into errors.
//!
//! A corrupt file can make a decoder (the parquet crate's, for one) panic instead of returning an
//! error. [`contain`] runs such a decoder and returns the panic as an `Err` with its message, so the
//! caller can name the file in a one-line error. [`install_quiet_hook`] (called once by the command
//! line at start) keeps the default panic report off stderr while a contained decoder runs on that
//! thread; every other panic is reported as before.

use std::cell::Cell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Once;

thread_local! {
    /// Set while [`contain`] runs on this thread.
    static CONTAINED: Cell<bool> = const { Cell::new(false) };
}

/// Runs `decode`; a panic inside it becomes `Err(message)`. The caller's data must not be used after
/// an `Err` (it may be half-filled); everything `decode` owns is dropped.
pub fn contain<R>(decode: impl FnOnce() -> R) -> Result<R, String> {
    let outer = CONTAINED.with(|c| c.replace(true));
    let out = catch_unwind(AssertUnwindSafe(decode));
    CONTAINED.with(|c| c.set(outer));
    out.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "the decoder panicked".into())
    })
}

/// Wraps the current panic hook so that panics inside [`contain`] print nothing (their message
/// reaches the caller as an error instead). Idempotent.
pub fn install_quiet_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !CONTAINED.with(Cell::get) {
                previous(info);
            }
        }));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_its_message_and_a_value_passes_through() {
        install_quiet_hook();
        assert_eq!(contain(|| 7), Ok(7));
        let err = contain(|| -> u8 { panic!("bad page header at {}", 12) }).unwrap_err();
        assert_eq!(err, "bad page header at 12");
        assert_eq!(
            contain(|| -> u8 { std::panic::panic_any(3u8) }).unwrap_err(),
            "the decoder panicked"
        );
        // The flag is reset: later panics are reported (and caught here by the test harness).
        assert!(!CONTAINED.with(Cell::get));
    }
}
