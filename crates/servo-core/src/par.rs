//! Thread helpers of the fit and the diagnosis: a parallel map over a shared queue, a count of
//! the working threads, and a split of two independent parts onto an idle core (handed to a
//! helper thread kept between splits: the crate's one `unsafe` block). At the bottom of
//! the crate (it imports nothing of it), so that the fit, the effects' hooks and the diagnosis
//! share one count of busy cores.

use alloc::vec::Vec;

/// `f` over `items`, on up to four threads (std builds, `parallel`) taking items from a shared
/// queue in order, else in turn; results in the order of `items`.
pub(crate) fn par_map<T: Sync, R: Send>(
    items: &[T],
    parallel: bool,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    #[cfg(feature = "std")]
    if parallel && items.len() > 1 {
        let threads = std::thread::available_parallelism()
            .map_or(2, |n| n.get())
            .clamp(1, 4)
            .min(items.len());
        let next = core::sync::atomic::AtomicUsize::new(0);
        let mut out: Vec<Option<R>> = items.iter().map(|_| None).collect();
        let mut panicked = None;
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads)
                .map(|_| {
                    let (f, next) = (&f, &next);
                    s.spawn(move || {
                        let mut done = Vec::new();
                        loop {
                            let i = next.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
                            let Some(item) = items.get(i) else { break };
                            let _busy = Busy::hold();
                            done.push((i, f(item)));
                        }
                        done
                    })
                })
                .collect();
            for h in handles {
                match h.join() {
                    Ok(v) => {
                        for (i, r) in v {
                            out[i] = Some(r);
                        }
                    }
                    Err(e) => panicked = Some(e),
                }
            }
        });
        if let Some(e) = panicked {
            // A bug, not a data problem: surface it as the serial run would.
            std::panic::resume_unwind(e);
        }
        return out.into_iter().flatten().collect();
    }
    let _ = parallel;
    items.iter().map(f).collect()
}

/// Threads of the fit and the diagnosis working right now: the workers of [`par_map`] while they run an
/// item, and the second half of a split cost evaluation ([`idle_core`]).
#[cfg(feature = "std")]
static BUSY: core::sync::atomic::AtomicUsize = core::sync::atomic::AtomicUsize::new(0);

/// One working thread counted in [`BUSY`] while held.
#[cfg(feature = "std")]
pub(crate) struct Busy;

#[cfg(feature = "std")]
impl Busy {
    fn hold() -> Busy {
        BUSY.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
        Busy
    }
}

#[cfg(feature = "std")]
impl Drop for Busy {
    fn drop(&mut self) {
        BUSY.fetch_sub(1, core::sync::atomic::Ordering::Relaxed);
    }
}

/// A core no thread of a diagnosis works on, counted busy while the returned guard is held;
/// `None` when every core is taken. Independent work inside one task (the segments of one
/// simulation cost, [`crate::fit::oe::prediction_cost_stepped`]) runs on it: the serial parts
/// of a diagnosis and its last task, which would leave the other cores idle, then use them.
/// The caller, when it is a worker of [`par_map`], is already counted.
#[cfg(feature = "std")]
pub(crate) fn idle_core() -> Option<Busy> {
    use core::sync::atomic::Ordering;
    // Read once: the query reads the scheduler's affinity and the cgroup's quota.
    static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    let cores = *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let mut now = BUSY.load(Ordering::Relaxed);
    loop {
        // The caller itself works on one core (counted or not).
        if now.max(1) + 1 > cores {
            return None;
        }
        match BUSY.compare_exchange_weak(now, now + 1, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return Some(Busy),
            Err(v) => now = v,
        }
    }
}

/// `(fa(), fb())`: on two threads when a core is idle (std builds, see [`idle_core`]), else in
/// turn; the results are the same either way. For independent parts of the serial work of a
/// diagnosis (preparing the data set), which would otherwise leave a core idle.
pub(crate) fn join<A: Send, B: Send>(
    fa: impl FnOnce() -> A + Send,
    fb: impl FnOnce() -> B + Send,
) -> (A, B) {
    #[cfg(feature = "std")]
    if let Some(_held) = idle_core() {
        return on_two_threads(fa, fb);
    }
    (fa(), fb())
}

/// `(fa(), fb())`, `fb` on a second thread: for a caller that already holds an [`idle_core`]
/// for it. A panic in `fb` (a bug, not a data problem) is raised here as the serial run would.
///
/// The second thread is one of [`helper`]'s, kept between calls: a thread started for each call
/// began its work 0.7 ms late on average on the 2-core test machine (40 % of 400 starts over
/// 0.5 ms in one diagnosis of the real friction ramps), a tenth of a typical split cost.
#[cfg(feature = "std")]
pub(crate) fn on_two_threads<A: Send, B: Send>(
    fa: impl FnOnce() -> A + Send,
    fb: impl FnOnce() -> B + Send,
) -> (A, B) {
    helper::on_two_threads(fa, fb)
}

/// The threads [`on_two_threads`] hands its second part to, kept between calls.
#[cfg(feature = "std")]
mod helper {
    use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
    use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
    use std::sync::Mutex;
    use std::time::{Duration, Instant};

    /// A part handed to a helper, its borrows erased ([`on_two_threads`] waits for it).
    type Job = Box<dyn FnOnce() + Send + 'static>;

    /// How long a thread waiting for the other (a helper for its next part, a caller for the
    /// helper's result) keeps polling before it sleeps: the parts of one split cost end within
    /// a millisecond or two of each other, and a sleeping thread was woken late on this VM.
    const SPIN: Duration = Duration::from_millis(2);

    /// Idle helpers, each the sending end of its thread's queue.
    static IDLE: Mutex<Vec<Sender<Job>>> = Mutex::new(Vec::new());

    /// An idle helper, or a new one; `None` when no thread can be started.
    fn take() -> Option<Sender<Job>> {
        if let Some(h) = IDLE.lock().ok().and_then(|mut v| v.pop()) {
            return Some(h);
        }
        let (tx, rx) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name("servo-helper".into())
            .spawn(move || {
                while let Some(job) = next(&rx) {
                    job();
                }
            })
            .ok()?;
        Some(tx)
    }

    /// Returns `h` to the idle helpers.
    fn give_back(h: Sender<Job>) {
        if let Ok(mut v) = IDLE.lock() {
            v.push(h);
        }
    }

    /// The next value on `rx`, polled for [`SPIN`] before sleeping; `None` once its sender is
    /// gone.
    fn next<T>(rx: &Receiver<T>) -> Option<T> {
        let t0 = Instant::now();
        loop {
            for _ in 0..64 {
                match rx.try_recv() {
                    Ok(v) => return Some(v),
                    Err(TryRecvError::Disconnected) => return None,
                    Err(TryRecvError::Empty) => std::hint::spin_loop(),
                }
            }
            if t0.elapsed() > SPIN {
                return rx.recv().ok();
            }
        }
    }

    /// [`super::on_two_threads`].
    pub(super) fn on_two_threads<A: Send, B: Send>(
        fa: impl FnOnce() -> A + Send,
        fb: impl FnOnce() -> B + Send,
    ) -> (A, B) {
        let Some(helper) = take() else {
            // No thread to be had: in turn.
            return (fa(), fb());
        };
        let (tx, rx) = mpsc::sync_channel::<std::thread::Result<B>>(1);
        let job = move || {
            let r = catch_unwind(AssertUnwindSafe(fb));
            // Its last use of anything borrowed: `fb` and its result are moved out by now.
            let _ = tx.send(r);
        };
        let job: Box<dyn FnOnce() + Send + '_> = Box::new(job);
        // SAFETY: the job borrows what `fb` borrows, which lives until this function returns.
        // The job runs at most once, on the helper (or below, here, if the helper were gone),
        // and ends by sending its result (a panic in `fb` is caught and sent too); this
        // function does not return or unwind before it has received that result, or learnt
        // that the job was dropped unrun (the channel disconnected). Both happen after the
        // job's last use of anything borrowed.
        let job: Job = unsafe { std::mem::transmute::<Box<dyn FnOnce() + Send + '_>, Job>(job) };
        let sent = helper.send(job);
        let a = catch_unwind(AssertUnwindSafe(fa));
        let b = match sent {
            Ok(()) => next(&rx),
            // The helper is gone (it never is: a job's panic is caught): run the job here.
            Err(mpsc::SendError(job)) => {
                job();
                next(&rx)
            }
        };
        if b.is_some() {
            give_back(helper);
        }
        match (a, b) {
            (Ok(a), Some(Ok(b))) => (a, b),
            (Err(e), _) | (_, Some(Err(e))) => resume_unwind(e),
            (Ok(_), None) => panic!("a helper thread dropped its part of a split unrun"),
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    #[test]
    fn both_parts_run_on_borrowed_data_and_the_helper_is_kept() {
        let data: Vec<u64> = (0..10_000).collect();
        let (a, b) = on_two_threads(
            || data[..5_000].iter().sum::<u64>(),
            || {
                (
                    data[5_000..].iter().sum::<u64>(),
                    std::thread::current().id(),
                )
            },
        );
        assert_eq!(a + b.0, data.iter().sum::<u64>());
        assert_ne!(
            b.1,
            std::thread::current().id(),
            "the second part ran on another thread"
        );
        // Later calls (one at a time, as a serial refinement makes them) find an idle helper:
        // one of the few threads kept (other tests may hold one at the same time), not a new
        // one each time.
        let helpers: Vec<(Option<String>, std::thread::ThreadId)> = (0..20)
            .map(|k| {
                let helper = || {
                    let t = std::thread::current();
                    (t.name().map(String::from), t.id())
                };
                on_two_threads(|| k, helper).1
            })
            .collect();
        assert!(
            helpers
                .iter()
                .all(|h| h.0.as_deref() == Some("servo-helper")),
            "{helpers:?}"
        );
        let mut ids: Vec<_> = helpers.iter().map(|h| h.1).collect();
        ids.sort_by_key(|id| format!("{id:?}"));
        ids.dedup();
        assert!(ids.len() <= 4, "{} threads for 20 calls", ids.len());
    }

    #[test]
    fn a_panic_in_either_part_is_raised_after_both_ended() {
        let done = core::sync::atomic::AtomicBool::new(false);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            on_two_threads(
                || panic!("first part"),
                || {
                    std::thread::sleep(std::time::Duration::from_millis(20));
                    done.store(true, core::sync::atomic::Ordering::SeqCst);
                },
            )
        }));
        assert!(r.is_err());
        assert!(
            done.load(core::sync::atomic::Ordering::SeqCst),
            "returned before the helper ended"
        );
        let r =
            std::panic::catch_unwind(|| on_two_threads(|| 1, || -> u32 { panic!("second part") }));
        let msg = r
            .err()
            .and_then(|e| e.downcast_ref::<&str>().map(|s| s.to_string()));
        assert_eq!(msg.as_deref(), Some("second part"));
        // The helpers still serve.
        assert_eq!(on_two_threads(|| 2, || 3), (2, 3));
    }
}
