//! Cooperative cancellation of long work (a calibration, a diagnosis): a caller that can be
//! interrupted (the Python package on Ctrl-C) runs the work inside [`with_check`], and the long loops
//! poll [`checkpoint`] between steps: the Levenberg–Marquardt iterations ([`crate::lm::minimize`]),
//! the stages of [`crate::fit::fit`] and each candidate fit of
//! [`crate::select::diagnose::diagnose`]. Once the check says stop, every later checkpoint on that thread
//! says so too (the answer is kept), and the work returns [`CalibError::Cancelled`].
//!
//! The check belongs to the calling thread (Python runs its signal handlers on the main thread
//! only). Work whose loops run on rayon's threads (the candidate fits of a diagnosis round, the
//! cross-validation folds) goes through [`relayed`]: the calling thread keeps polling its check and
//! each part polls a [`Relay`] that carries the answer. Work run without a check (the command line,
//! the tests) is never cancelled, and a checkpoint then costs one thread-local read.
//!
//! ```
//! use calib::cancel::{checkpoint, with_check};
//! use std::{cell::Cell, rc::Rc};
//! let calls = Rc::new(Cell::new(0));
//! let counter = calls.clone();
//! let stop_at_third = move || { counter.set(counter.get() + 1); counter.get() >= 3 };
//! let steps = with_check(stop_at_third, || (0..10).take_while(|_| checkpoint().is_ok()).count());
//! assert_eq!((steps, calls.get()), (2, 3));
//! assert!(checkpoint().is_ok()); // outside `with_check`: never cancelled
//! ```

use crate::error::{CalibError, Result};
use std::cell::{Cell, RefCell};
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

thread_local! {
    /// The checks installed by [`with_check`] on this thread, innermost last.
    static CHECKS: RefCell<Vec<Rc<dyn Fn() -> bool>>> = const { RefCell::new(Vec::new()) };
    /// Set once a check said stop inside the current outermost [`with_check`].
    static STOPPED: Cell<bool> = const { Cell::new(false) };
}

/// Runs `work` with `check` (whether to stop; it may be called often, every LM iteration) polled at
/// every [`checkpoint`] on this thread. Nested calls poll the innermost check; the stop answer of any
/// check is kept until the outermost call returns.
pub fn with_check<R>(check: impl Fn() -> bool + 'static, work: impl FnOnce() -> R) -> R {
    /// Pops the check when `work` returns or unwinds.
    struct Pop;
    impl Drop for Pop {
        fn drop(&mut self) {
            CHECKS.with(|c| {
                let mut c = c.borrow_mut();
                c.pop();
                if c.is_empty() {
                    STOPPED.with(|s| s.set(false));
                }
            });
        }
    }
    CHECKS.with(|c| c.borrow_mut().push(Rc::new(check)));
    let _pop = Pop;
    work()
}

/// `Err(CalibError::Cancelled)` when the current thread's check (see [`with_check`]) says stop,
/// now or before; `Ok(())` otherwise, and always outside `with_check`.
pub fn checkpoint() -> Result<()> {
    if STOPPED.with(Cell::get) {
        return Err(CalibError::Cancelled);
    }
    // The check is called after the borrow of CHECKS ended, so a check may itself run work.
    let Some(check) = CHECKS.with(|c| c.borrow().last().cloned()) else {
        return Ok(());
    };
    if check() {
        STOPPED.with(|s| s.set(true));
        return Err(CalibError::Cancelled);
    }
    Ok(())
}

/// How often [`relayed`] polls the calling thread's check while the work runs elsewhere.
const RELAY_POLL: std::time::Duration = std::time::Duration::from_millis(20);

/// Carries the calling thread's stop to work that runs on other threads ([`relayed`]).
#[derive(Clone, Debug)]
pub struct Relay(Arc<AtomicBool>);

impl Relay {
    /// A relay that starts as this thread's check stands ([`stopped`]); [`relayed`] feeds it from
    /// the calling thread's check, other callers by [`Relay::stop`] (work on a thread of its own
    /// beside theirs, stopped when they give up).
    pub(crate) fn new() -> Self {
        Relay(Arc::new(AtomicBool::new(stopped())))
    }

    /// Says stop to the work under this relay, at its next checkpoint.
    pub(crate) fn stop(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Runs `work` (on any thread) with a check that says stop once the calling thread's check of
    /// [`relayed`] said so.
    pub fn run<R>(&self, work: impl FnOnce() -> R) -> R {
        let flag = self.0.clone();
        with_check(move || flag.load(Ordering::Relaxed), work)
    }
}

/// Runs `work`, which spreads its parts over rayon's threads with each part inside [`Relay::run`],
/// so that the calling thread's check still stops it: the calling thread waits, polling its check
/// every 20 ms, while `work` runs on a scoped thread; once the check says stop, every part stops at
/// its next checkpoint, and the calling thread is stopped too when `work` returns. Without a check
/// on the calling thread (the command line, the tests), `work` runs right there.
///
/// Called on one of rayon's threads (a relayed part that spreads its own work), `work` runs right
/// there too: a pool thread that waited would hold a thread its own parts may need (two of them
/// waiting on a two-thread pool would wait for ever). Its parts then see a stop said before, not
/// one said while they run; the part around them sees it at its next checkpoint.
///
/// A part stolen by a rayon thread while it waits inside a relayed part runs under that part's
/// check: two independent works on the pool at once (two Python threads) can see each other's
/// stop.
pub fn relayed<R: Send>(work: impl FnOnce(&Relay) -> R + Send) -> R {
    let relay = Relay::new();
    if CHECKS.with(|c| c.borrow().is_empty()) || rayon::current_thread_index().is_some() {
        return work(&relay);
    }
    let caller = std::thread::current();
    let out = std::thread::scope(|s| {
        let running = s.spawn(|| {
            let out = work(&relay);
            caller.unpark();
            out
        });
        while !running.is_finished() {
            if checkpoint().is_err() {
                relay.stop();
            }
            std::thread::park_timeout(RELAY_POLL);
        }
        running.join()
    });
    match out {
        Ok(r) => r,
        Err(panic) => std::panic::resume_unwind(panic),
    }
}

/// True when [`checkpoint`] would say stop without asking the check again.
pub fn stopped() -> bool {
    STOPPED.with(Cell::get)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stop_is_kept_until_the_outermost_call_returns() {
        with_check(
            || false,
            || {
                assert!(checkpoint().is_ok());
                with_check(|| true, || assert!(checkpoint().is_err()));
                // The inner check said stop: the outer work stops too.
                assert!(stopped());
                assert!(matches!(checkpoint(), Err(CalibError::Cancelled)));
            },
        );
        assert!(!stopped());
        assert!(checkpoint().is_ok());
    }

    #[test]
    fn a_panic_inside_pops_the_check() {
        let r = std::panic::catch_unwind(|| with_check(|| true, || panic!("boom")));
        assert!(r.is_err());
        assert!(checkpoint().is_ok());
    }

    #[test]
    fn a_relay_carries_the_stop_to_other_threads() {
        use rayon::prelude::*;
        use std::sync::atomic::AtomicUsize;
        // The caller's check says stop on its third call; parts on rayon's threads poll a
        // checkpoint until they see it (each part would otherwise spin for ever).
        let calls = Rc::new(Cell::new(0));
        let counter = calls.clone();
        let polls = AtomicUsize::new(0);
        let stopped_parts = with_check(
            move || {
                counter.set(counter.get() + 1);
                counter.get() >= 3
            },
            || {
                let n = relayed(|relay| {
                    (0..4)
                        .into_par_iter()
                        .filter(|_| {
                            relay.run(|| {
                                while checkpoint().is_ok() {
                                    polls.fetch_add(1, Ordering::Relaxed);
                                    std::thread::yield_now();
                                }
                                true
                            })
                        })
                        .count()
                });
                // The caller is stopped too once the work returns.
                assert!(stopped());
                n
            },
        );
        assert_eq!(stopped_parts, 4);
        assert_eq!(calls.get(), 3);
        assert!(!stopped());
    }

    #[test]
    fn relayed_work_inside_relayed_parts_does_not_wait_for_the_pool() {
        use rayon::prelude::*;
        // Every pool thread runs a relayed part that relays work of its own: with the pool's
        // threads all waiting this would never end.
        let n = rayon::current_num_threads() * 2;
        let total: usize = with_check(
            || false,
            || {
                relayed(|outer| {
                    (0..n)
                        .into_par_iter()
                        .map(|_| {
                            outer.run(|| {
                                relayed(|inner| {
                                    (0..4)
                                        .into_par_iter()
                                        .map(|k| inner.run(|| k))
                                        .sum::<usize>()
                                })
                            })
                        })
                        .sum()
                })
            },
        );
        assert_eq!(total, n * 6);
    }

    #[test]
    fn without_a_check_a_relayed_work_runs_on_the_calling_thread() {
        let here = std::thread::current().id();
        let (there, ok) = relayed(|relay| {
            (
                std::thread::current().id(),
                relay.run(|| checkpoint().is_ok()),
            )
        });
        assert_eq!(there, here);
        assert!(ok);
    }

    #[test]
    fn other_threads_are_not_cancelled() {
        with_check(
            || true,
            || {
                assert!(checkpoint().is_err());
                let other = std::thread::spawn(|| checkpoint().is_ok()).join().unwrap();
                assert!(other);
            },
        );
    }
}
