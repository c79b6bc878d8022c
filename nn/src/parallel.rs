//! Splitting a batch across threads with results independent of the thread count, on threads
//! spawned per call ([`for_each_row_block`], [`in_blocks`]) or on a persistent [`Workers`] pool.

use std::any::Any;
use std::cell::UnsafeCell;
use std::ops::Range;
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering, fence};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::NnError;

/// The contiguous row ranges `0..n_rows` split into `parts` nearly equal blocks (the first
/// `n_rows % parts` blocks get one row more). Blocks may be empty when `n_rows < parts`.
pub fn row_blocks(n_rows: usize, parts: usize) -> Vec<Range<usize>> {
    let parts = parts.max(1);
    let (base, extra) = (n_rows / parts, n_rows % parts);
    let mut start = 0;
    (0..parts)
        .map(|i| {
            let len = base + usize::from(i < extra);
            let r = start..start + len;
            start += len;
            r
        })
        .collect()
}

/// `f` of contiguous blocks of `items`, one block per available core ([`in_n_blocks`]).
pub fn in_blocks<I: Sync, T: Send>(items: &[I], f: impl Fn(&[I]) -> T + Sync) -> Vec<T> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    in_n_blocks(items, cores, f)
}

/// `f` of at most `parts` contiguous blocks of `items` (none empty but a lone one for no
/// items), run on scoped threads (the first on the calling thread) and returned in block order:
/// for an `f` that treats its items independently, the concatenated results do not depend on
/// `parts`.
pub fn in_n_blocks<I: Sync, T: Send>(
    items: &[I],
    parts: usize,
    f: impl Fn(&[I]) -> T + Sync,
) -> Vec<T> {
    let blocks = row_blocks(items.len(), parts.min(items.len()).max(1));
    let f = &f;
    std::thread::scope(|scope| {
        let mut blocks = blocks.into_iter();
        let first = blocks.next().map(|b| &items[b]);
        let handles: Vec<_> = blocks
            .map(|b| {
                let part = &items[b];
                scope.spawn(move || f(part))
            })
            .collect();
        let mut out = Vec::with_capacity(handles.len() + 1);
        out.extend(first.map(f));
        for h in handles {
            // a panic in `f` is a bug, not a data error: re-raise it on this thread
            out.push(h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)));
        }
        out
    })
}

/// Runs `f(rows, out_rows, state)` on one thread per element of `states`, each with a disjoint
/// contiguous block of the rows of `out` (`row_len` values per row) and its own `state` (for
/// example a [`crate::Workspace`], or a whole MPPI rollout's buffers). The first block runs on the
/// calling thread, the others on scoped threads spawned for this call, so call it once per batch
/// (a whole rollout), not once per layer; for repeated calls keep a [`Workers`] pool (starting
/// a thread costs ≈ 0.1 ms here, waking a persistent worker that already sleeps ≈ 0.03 ms).
///
/// Which thread computes a row never changes the row's arithmetic when `f` treats rows
/// independently (as every [`crate::Mlp`] evaluation does), so results are bitwise identical for
/// any number of states. Returns the first error in block order.
pub fn for_each_row_block<T, W, F>(
    out: &mut [T],
    row_len: usize,
    states: &mut [W],
    f: F,
) -> Result<(), NnError>
where
    T: Send,
    W: Send,
    F: Fn(Range<usize>, &mut [T], &mut W) -> Result<(), NnError> + Sync,
{
    let jobs = split_rows(out, row_len, states)?;
    let f = &f;
    std::thread::scope(|scope| {
        let mut jobs = jobs.into_iter();
        let first = jobs.next();
        let handles: Vec<_> = jobs
            .map(|(rows, chunk, state)| scope.spawn(move || f(rows, chunk, state)))
            .collect();
        let mut result = match first {
            Some((rows, chunk, state)) => f(rows, chunk, state),
            None => Ok(()),
        };
        for h in handles {
            let r = match h.join() {
                Ok(r) => r,
                // A panic in `f` is a bug, not a data error: re-raise it on this thread.
                Err(payload) => resume_unwind(payload),
            };
            if result.is_ok() {
                result = r;
            }
        }
        result
    })
}

/// One block of [`split_rows`]: its rows, their part of the output and its state.
type RowJob<'a, T, W> = (Range<usize>, &'a mut [T], &'a mut W);

/// Splits the rows of `out` into one contiguous block per element of `states`.
fn split_rows<'a, T, W>(
    out: &'a mut [T],
    row_len: usize,
    states: &'a mut [W],
) -> Result<Vec<RowJob<'a, T, W>>, NnError> {
    if states.is_empty() {
        return Err(NnError::NoWorkspaces);
    }
    if row_len == 0 {
        return Ok(Vec::new());
    }
    if !out.len().is_multiple_of(row_len) {
        return Err(NnError::RaggedBatch {
            len: out.len(),
            n_in: row_len,
        });
    }
    let blocks = row_blocks(out.len() / row_len, states.len());
    let mut jobs = Vec::with_capacity(blocks.len());
    let mut rest = out;
    for (r, state) in blocks.into_iter().zip(states.iter_mut()) {
        let (head, tail) = rest.split_at_mut(r.len() * row_len);
        jobs.push((r, head, state));
        rest = tail;
    }
    Ok(jobs)
}

/// How long an idle worker of a [`Workers`] pool spins for its next job before it sleeps.
pub const DEFAULT_SPIN: Duration = Duration::from_micros(300);

/// A persistent pool of `threads − 1` worker threads for [`Workers::for_each_row_block`], the
/// calling thread being the last one. Starting a thread costs about 0.1 ms on a small VM, a tenth
/// of a 1 ms MPPI step; the workers here are started once and, between jobs, spin for
/// [`DEFAULT_SPIN`] before they sleep, so a job posted right after the previous one starts within
/// microseconds on a core whose caches still hold the block's buffers.
///
/// Block `i` always runs on worker `i − 1` (block 0 on the caller), so a block's state stays on
/// one thread from call to call, and the results are bitwise those of [`for_each_row_block`].
pub struct Workers {
    shared: Arc<Shared>,
    handles: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for Workers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Workers")
            .field("threads", &self.threads())
            .finish()
    }
}

/// A job as the workers see it: the caller's closure with its lifetime erased. It is only
/// called between [`Workers::run`] posting it and `run` seeing it done, while the closure lives.
type ErasedJob = *const (dyn Fn(usize) + Sync + 'static);

struct Shared {
    slots: Vec<Slot>,
    stop: AtomicBool,
    spin: Duration,
}

/// One worker's mailbox. `posted` and `done` count jobs; the worker has a job while they differ.
struct Slot {
    posted: AtomicUsize,
    done: AtomicUsize,
    job: UnsafeCell<Option<(ErasedJob, usize)>>,
    panic: Mutex<Option<Box<dyn Any + Send>>>,
    /// The worker (for `posted`) or the caller (for `done`) waits on `wake` under `lock`.
    lock: Mutex<()>,
    wake: Condvar,
    worker_asleep: AtomicBool,
    caller_asleep: AtomicBool,
}

// SAFETY: `job` is written by the caller only while the worker is idle (`posted == done`) and
// read by the worker only while it has a job; the release/acquire pair on `posted` and `done`
// orders those accesses. The erased closure is `Sync` and outlives every call of it (`run`
// returns only after every job it posted is done).
unsafe impl Sync for Shared {}
// SAFETY: as above; the raw pointer is only dereferenced under that protocol.
unsafe impl Send for Shared {}

fn lock(m: &Mutex<()>) -> MutexGuard<'_, ()> {
    // The lock guards no data, so a poisoned lock is still a good lock.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Spins until `ready()` for up to `spin`, then sleeps on the slot's condition variable with
/// `asleep` set (the other side wakes it after changing what `ready` reads).
fn wait_until(slot: &Slot, spin: Duration, asleep: &AtomicBool, ready: impl Fn() -> bool) {
    let start = Instant::now();
    let mut n = 0u32;
    while !ready() {
        n = n.wrapping_add(1);
        if !n.is_multiple_of(64) {
            std::hint::spin_loop();
            continue;
        }
        if start.elapsed() < spin {
            // Let the other side run if the scheduler put both threads on one core.
            std::thread::yield_now();
            continue;
        }
        let mut guard = lock(&slot.lock);
        asleep.store(true, Ordering::SeqCst);
        // Pairs with the fence in `notify`: either this thread sees the change or the other
        // side sees `asleep` and wakes it.
        fence(Ordering::SeqCst);
        while !ready() {
            guard = slot
                .wake
                .wait(guard)
                .unwrap_or_else(PoisonError::into_inner);
        }
        asleep.store(false, Ordering::SeqCst);
        return;
    }
}

fn notify(slot: &Slot, asleep: &AtomicBool) {
    fence(Ordering::SeqCst);
    if asleep.load(Ordering::SeqCst) {
        let _guard = lock(&slot.lock);
        slot.wake.notify_all();
    }
}

impl Workers {
    /// A pool for `threads` threads in all (at least 1): `threads − 1` workers are started.
    pub fn new(threads: usize) -> Self {
        Self::with_spin(threads, DEFAULT_SPIN)
    }

    /// As [`Workers::new`], with idle workers spinning for `spin` before they sleep.
    pub fn with_spin(threads: usize, spin: Duration) -> Self {
        let n = threads.max(1) - 1;
        let shared = Arc::new(Shared {
            slots: (0..n)
                .map(|_| Slot {
                    posted: AtomicUsize::new(0),
                    done: AtomicUsize::new(0),
                    job: UnsafeCell::new(None),
                    panic: Mutex::new(None),
                    lock: Mutex::new(()),
                    wake: Condvar::new(),
                    worker_asleep: AtomicBool::new(false),
                    caller_asleep: AtomicBool::new(false),
                })
                .collect(),
            stop: AtomicBool::new(false),
            spin,
        });
        let handles = (0..n)
            .map(|i| {
                let shared = Arc::clone(&shared);
                std::thread::Builder::new()
                    .name(format!("dynlab-worker-{i}"))
                    .spawn(move || worker(&shared, i))
                    .expect("cannot start a worker thread")
            })
            .collect();
        Self { shared, handles }
    }

    /// Threads in all, the caller's included.
    pub fn threads(&self) -> usize {
        self.shared.slots.len() + 1
    }

    /// Runs `f(i)` for `i` in `0..n`: `f(0)` on the calling thread, `f(i)` on worker `i − 1`;
    /// jobs beyond the workers run on the calling thread after `f(0)`. Returns when all are done;
    /// a panic in any job is re-raised here after every job has finished.
    pub fn run(&mut self, n: usize, f: &(dyn Fn(usize) + Sync)) {
        let slots = &self.shared.slots;
        let on_workers = n.saturating_sub(1).min(slots.len());
        // SAFETY: only the lifetime is erased; `run` waits below for every job that holds it.
        let erased: ErasedJob =
            unsafe { std::mem::transmute::<*const (dyn Fn(usize) + Sync + '_), ErasedJob>(f) };
        for (w, slot) in slots.iter().enumerate().take(on_workers) {
            // SAFETY: the worker is idle (`&mut self`: every earlier job is done), so it does not
            // read `job` until `posted` moves.
            unsafe { *slot.job.get() = Some((erased, w + 1)) };
            slot.posted.fetch_add(1, Ordering::SeqCst);
            notify(slot, &slot.worker_asleep);
        }
        let mine = catch_unwind(AssertUnwindSafe(|| {
            f(0);
            for i in on_workers + 1..n {
                f(i);
            }
        }));
        let mut panic = mine.err();
        for slot in slots.iter().take(on_workers) {
            let target = slot.posted.load(Ordering::Relaxed);
            wait_until(slot, self.shared.spin, &slot.caller_asleep, || {
                slot.done.load(Ordering::Acquire) == target
            });
            let p = slot
                .panic
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .take();
            panic = panic.or(p);
        }
        if let Some(p) = panic {
            resume_unwind(p);
        }
    }

    /// [`for_each_row_block`] on this pool: block `i` of `states.len()` runs on worker `i − 1`.
    pub fn for_each_row_block<T, W, F>(
        &mut self,
        out: &mut [T],
        row_len: usize,
        states: &mut [W],
        f: F,
    ) -> Result<(), NnError>
    where
        T: Send,
        W: Send,
        F: Fn(Range<usize>, &mut [T], &mut W) -> Result<(), NnError> + Sync,
    {
        let jobs: Vec<Mutex<Option<RowJob<'_, T, W>>>> = split_rows(out, row_len, states)?
            .into_iter()
            .map(|j| Mutex::new(Some(j)))
            .collect();
        let results: Vec<Mutex<Result<(), NnError>>> =
            jobs.iter().map(|_| Mutex::new(Ok(()))).collect();
        self.run(jobs.len(), &|i| {
            let job = jobs[i]
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .take();
            if let Some((rows, chunk, state)) = job {
                *results[i].lock().unwrap_or_else(PoisonError::into_inner) = f(rows, chunk, state);
            }
        });
        results
            .into_iter()
            .try_for_each(|r| r.into_inner().unwrap_or_else(PoisonError::into_inner))
    }
}

fn worker(shared: &Shared, i: usize) {
    let slot = &shared.slots[i];
    let mut seen = 0;
    loop {
        wait_until(slot, shared.spin, &slot.worker_asleep, || {
            shared.stop.load(Ordering::Acquire) || slot.posted.load(Ordering::Acquire) != seen
        });
        if shared.stop.load(Ordering::Acquire) {
            return;
        }
        seen = slot.posted.load(Ordering::Acquire);
        // SAFETY: `posted` moved, so the caller wrote `job` and waits for `done` before it
        // writes `job` again or lets the closure go.
        if let Some((job, index)) = unsafe { *slot.job.get() } {
            // SAFETY: the closure outlives this call (see `ErasedJob`).
            let r = catch_unwind(AssertUnwindSafe(|| unsafe { (*job)(index) }));
            if let Err(p) = r {
                *slot.panic.lock().unwrap_or_else(PoisonError::into_inner) = Some(p);
            }
        }
        slot.done.store(seen, Ordering::SeqCst);
        notify(slot, &slot.caller_asleep);
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        for slot in &self.shared.slots {
            let _guard = lock(&slot.lock);
            slot.wake.notify_all();
        }
        for h in self.handles.drain(..) {
            // A worker catches every job's panic, so joining cannot fail but for a bug here.
            let _ = h.join();
        }
    }
}
