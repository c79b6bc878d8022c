//! Splitting a batch across threads with results independent of the thread count.

use std::ops::Range;

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

/// Runs `f(rows, out_rows, state)` on one thread per element of `states`, each with a disjoint
/// contiguous block of the rows of `out` (`row_len` values per row) and its own `state` (for
/// example a [`crate::Workspace`], or a whole MPPI rollout's buffers). The first block runs on the
/// calling thread, the others on scoped threads spawned for this call, so spawn once per batch
/// (a whole rollout), not once per layer.
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
    if states.is_empty() {
        return Err(NnError::NoWorkspaces);
    }
    if row_len == 0 {
        return Ok(());
    }
    if !out.len().is_multiple_of(row_len) {
        return Err(NnError::RaggedBatch {
            len: out.len(),
            n_in: row_len,
        });
    }
    let blocks = row_blocks(out.len() / row_len, states.len());
    let mut chunks = Vec::with_capacity(blocks.len());
    let mut rest = out;
    for r in &blocks {
        let (head, tail) = rest.split_at_mut(r.len() * row_len);
        chunks.push(head);
        rest = tail;
    }
    let f = &f;
    std::thread::scope(|scope| {
        let mut jobs = blocks.into_iter().zip(chunks).zip(states.iter_mut());
        let first = jobs.next();
        let handles: Vec<_> = jobs
            .map(|((rows, chunk), state)| scope.spawn(move || f(rows, chunk, state)))
            .collect();
        let mut result = match first {
            Some(((rows, chunk), state)) => f(rows, chunk, state),
            None => Ok(()),
        };
        for h in handles {
            let r = match h.join() {
                Ok(r) => r,
                // A panic in `f` is a bug, not a data error: re-raise it on this thread.
                Err(payload) => std::panic::resume_unwind(payload),
            };
            if result.is_ok() {
                result = r;
            }
        }
        result
    })
}
