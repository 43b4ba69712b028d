//! Thread helpers of the fit and the diagnosis: a parallel map over a shared queue, a count of
//! the working threads, and a split of two independent parts onto an idle core. At the bottom of
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
#[cfg(feature = "std")]
pub(crate) fn on_two_threads<A: Send, B: Send>(
    fa: impl FnOnce() -> A + Send,
    fb: impl FnOnce() -> B + Send,
) -> (A, B) {
    std::thread::scope(|s| {
        let h = s.spawn(fb);
        let a = fa();
        match h.join() {
            Ok(b) => (a, b),
            Err(e) => std::panic::resume_unwind(e),
        }
    })
}
