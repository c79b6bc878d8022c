//! Thread-count invariance: a batch split over any number of threads gives bitwise the same
//! result as one thread.

mod common;

use common::data;
use dynlab_nn::parallel::{Workers, for_each_row_block, in_n_blocks, row_blocks};
use dynlab_nn::{Activation, Init, Mlp, MlpSpec, NnError};

#[test]
fn forward_parallel_is_bitwise_independent_of_thread_count() {
    for act in [Activation::Tanh, Activation::Gelu] {
        let mlp = Mlp::new(
            MlpSpec::uniform(6, &[100, 100], 3, act).unwrap(),
            Init::Auto,
            3,
        );
        for batch in [1000, 997, 5] {
            let x = data(batch as u64, batch * 6, -2.0, 2.0);
            let mut reference = vec![0.0; batch * 3];
            mlp.forward_parallel(&x, &mut reference, &mut [mlp.workspace()])
                .unwrap();
            // Also equal to the plain forward pass.
            assert_eq!(
                mlp.forward(&x, &mut mlp.workspace()).unwrap(),
                &reference[..]
            );
            for threads in 2..=5 {
                let mut ws: Vec<_> = (0..threads).map(|_| mlp.workspace()).collect();
                let mut out = vec![f32::NAN; batch * 3];
                mlp.forward_parallel(&x, &mut out, &mut ws).unwrap();
                assert!(
                    out.iter()
                        .zip(&reference)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{act}, batch {batch}, {threads} threads differ from 1 thread"
                );
            }
        }
    }
}

#[test]
fn rollouts_split_by_rows_are_bitwise_independent_of_thread_count() {
    // An MPPI-style use: each thread rolls out its own samples for 10 steps of s ← s + f(s, u).
    let mlp = Mlp::new(
        MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).unwrap(),
        Init::Auto,
        4,
    );
    let n = 301;
    let u = data(5, n * 3, -1.0, 1.0);
    let rollout = |threads: usize| {
        let mut states = vec![0.0f32; n * 3];
        let mut ws: Vec<_> = (0..threads)
            .map(|_| (mlp.workspace(), Vec::new()))
            .collect();
        for_each_row_block(
            &mut states,
            3,
            &mut ws,
            |rows, s, (ws, x): &mut (_, Vec<f32>)| {
                for _ in 0..10 {
                    x.clear();
                    for (r, row) in rows.clone().zip(s.chunks(3)) {
                        x.extend_from_slice(row);
                        x.extend_from_slice(&u[r * 3..r * 3 + 3]);
                    }
                    let ds = mlp.forward(x, ws)?;
                    for (s, d) in s.iter_mut().zip(ds) {
                        *s += 0.1 * d;
                    }
                }
                Ok(())
            },
        )
        .unwrap();
        states
    };
    let one = rollout(1);
    assert!(one.iter().any(|&v| v != 0.0));
    for threads in [2, 3, 4, 7] {
        assert_eq!(rollout(threads), one, "{threads} threads");
    }
}

#[test]
fn row_blocks_cover_rows_once() {
    for (n, p) in [(10, 3), (2, 5), (0, 2), (1000, 2), (7, 1)] {
        let b = row_blocks(n, p);
        assert_eq!(b.len(), p);
        assert_eq!(b.iter().map(|r| r.len()).sum::<usize>(), n);
        assert!(b.windows(2).all(|w| w[0].end == w[1].start));
        let (lo, hi) = (
            b.iter().map(|r| r.len()).min().unwrap(),
            b.iter().map(|r| r.len()).max().unwrap(),
        );
        assert!(hi - lo <= 1);
    }
}

#[test]
fn parallel_errors_are_reported() {
    let mlp = Mlp::new(
        MlpSpec::uniform(2, &[4], 1, Activation::Tanh).unwrap(),
        Init::Auto,
        1,
    );
    let mut out = vec![0.0; 4];
    assert!(matches!(
        mlp.forward_parallel(&[0.0; 8], &mut out, &mut []),
        Err(NnError::NoWorkspaces)
    ));
    assert!(matches!(
        mlp.forward_parallel(&[0.0; 8], &mut out[..3], &mut [mlp.workspace()]),
        Err(NnError::ShapeMismatch { what: "out", .. })
    ));
    // An error inside one block comes back as the call's error.
    let mut states = [(); 3];
    let r = for_each_row_block(&mut out, 1, &mut states, |rows, _, _| {
        if rows.start >= 2 {
            Err(NnError::NoTape)
        } else {
            Ok(())
        }
    });
    assert!(matches!(r, Err(NnError::NoTape)));
}

#[test]
fn worker_pool_matches_spawned_threads_across_calls_and_sleeps() {
    let mlp = Mlp::new(
        MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).unwrap(),
        Init::Auto,
        5,
    );
    let batch = 203;
    let x = data(9, batch * 6, -2.0, 2.0);
    let mut reference = vec![0.0; batch * 3];
    mlp.forward_parallel(&x, &mut reference, &mut [mlp.workspace()])
        .unwrap();
    for threads in [1, 2, 3] {
        // A short spin, so that some calls find the workers asleep.
        let mut pool = Workers::with_spin(threads, std::time::Duration::from_micros(50));
        assert_eq!(pool.threads(), threads);
        // More blocks than threads: the extra blocks run on the calling thread.
        let mut ws: Vec<_> = (0..threads + 1).map(|_| mlp.workspace()).collect();
        for call in 0..40 {
            if call % 10 == 9 {
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            let mut out = vec![f32::NAN; batch * 3];
            pool.for_each_row_block(&mut out, 3, &mut ws, |rows, out, ws| {
                out.copy_from_slice(mlp.forward(&x[rows.start * 6..rows.end * 6], ws)?);
                Ok(())
            })
            .unwrap();
            assert!(
                out.iter()
                    .zip(&reference)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{threads} threads, call {call}"
            );
        }
    }
}

#[test]
fn worker_pool_reports_errors_and_re_raises_panics() {
    let mut pool = Workers::new(3);
    let mut out = vec![0.0f32; 6];
    let mut states = [(); 3];
    let r = pool.for_each_row_block(&mut out, 1, &mut states, |rows, _, _| {
        if rows.start >= 2 {
            Err(NnError::NoTape)
        } else {
            Ok(())
        }
    });
    assert!(matches!(r, Err(NnError::NoTape)));
    assert!(matches!(
        pool.for_each_row_block(&mut out, 4, &mut states, |_, _, _| Ok(())),
        Err(NnError::RaggedBatch { .. })
    ));
    let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        pool.run(3, &|i| assert!(i != 2, "job {i} fails"));
    }));
    let msg = caught.expect_err("the worker's panic reaches the caller");
    assert_eq!(msg.downcast_ref::<String>().unwrap(), "job 2 fails");
    // The pool still works after a job panicked.
    let hits = std::sync::atomic::AtomicUsize::new(0);
    pool.run(3, &|_| {
        hits.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    });
    assert_eq!(hits.into_inner(), 3);
}

#[test]
fn blocks_cover_the_items_in_order_for_any_number_of_parts() {
    let items: Vec<u32> = (0..11).collect();
    let squares: Vec<u32> = items.iter().map(|x| x * x).collect();
    for parts in 0..=13 {
        let blocks = in_n_blocks(&items, parts, |b| {
            b.iter().map(|x| x * x).collect::<Vec<_>>()
        });
        assert!(blocks.len() <= parts.max(1), "{parts} parts: {blocks:?}");
        assert!(
            blocks.iter().all(|b| !b.is_empty()),
            "{parts} parts: {blocks:?}"
        );
        assert_eq!(blocks.concat(), squares, "{parts} parts");
    }
    let none: Vec<Vec<u32>> = in_n_blocks(&[], 4, |b: &[u32]| b.to_vec());
    assert_eq!(none, [Vec::<u32>::new()]);
}
