//! Slice kernels (element-wise activations, their derivatives, bias and column sums, GEMM
//! wrappers), compiled twice: once for the baseline target and once with AVX2 + FMA enabled, chosen
//! at run time.
//!
//! Why run-time dispatch rather than `-C target-cpu=native`: the default x86-64 target only has
//! SSE2 (4 lanes, no FMA), and the element-wise tanh dominates these tiny networks, so 8-lane FMA
//! code is worth about 2× here (measured by `cargo bench -p dynlab-nn`). Committing
//! `target-cpu=native` to the repository would make binaries that crash with SIGILL on an older
//! CPU and would change every crate's codegen; `#[target_feature]` on these few functions plus a
//! cached CPU check gives the same speed on AVX2 machines and stays correct elsewhere. The choice
//! is made once per process, so results are reproducible within a machine (FMA rounds once where
//! a separate multiply and add round twice, so the last bit may differ between machines with and
//! without FMA).

use std::sync::OnceLock;

use crate::Activation;
use crate::math;

/// Whether this process uses the AVX2 + FMA code path (x86-64 with both features), or FMA on
/// AArch64 (always present there).
pub fn use_fma() -> bool {
    static FMA: OnceLock<bool> = OnceLock::new();
    *FMA.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
        }
        #[cfg(target_arch = "aarch64")]
        {
            true
        }
        #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
        {
            false
        }
    })
}

/// Whether this process uses the AVX-512 code path (x86-64 with AVX-512F and VL besides AVX2 and
/// FMA). It runs exactly the same arithmetic as the AVX2 + FMA path (every output element is the
/// same sequence of fused multiply–adds), 16 lanes at a time instead of 8, so results are
/// bit-identical between the two. Setting the environment variable `DYNLAB_NO_AVX512` (read
/// once, at the first call) forces the AVX2 path, to compare the two.
pub fn use_avx512() -> bool {
    static AVX512: OnceLock<bool> = OnceLock::new();
    *AVX512.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            use_fma()
                && std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::env::var_os("DYNLAB_NO_AVX512").is_none()
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    })
}

/// The SIMD code path chosen for this process: `"avx512"`, `"avx2+fma"`, `"neon+fma"` or
/// `"baseline"`.
pub fn simd_level() -> &'static str {
    if !use_fma() {
        "baseline"
    } else if cfg!(target_arch = "aarch64") {
        "neon+fma"
    } else if use_avx512() {
        "avx512"
    } else {
        "avx2+fma"
    }
}

/// Defines `pub(crate) fn $name(args)` dispatching to `$imp::<true, true>` compiled with AVX-512,
/// `$imp::<true, false>` compiled with AVX2 + FMA, or `$imp::<false, false>` for the baseline
/// target (`<FMA, WIDE>`: fused multiply–add, 16-lane registers for the block shapes).
macro_rules! dispatch {
    ($(#[$m:meta])* fn $name:ident($($a:ident : $t:ty),* $(,)?) => $imp:ident) => {
        $(#[$m])*
        pub(crate) fn $name($($a: $t),*) {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                fn simd($($a: $t),*) {
                    $imp::<true, false>($($a),*)
                }
                #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                fn simd512($($a: $t),*) {
                    $imp::<true, true>($($a),*)
                }
                if use_avx512() {
                    // SAFETY: the CPU supports AVX-512F/VL, AVX2 and FMA (checked by `use_avx512`).
                    return unsafe { simd512($($a),*) };
                }
                if use_fma() {
                    // SAFETY: the CPU supports AVX2 and FMA (checked by `use_fma`).
                    return unsafe { simd($($a),*) };
                }
            }
            #[cfg(target_arch = "aarch64")]
            {
                return $imp::<true, false>($($a),*);
            }
            #[allow(unreachable_code)]
            $imp::<false, false>($($a),*)
        }
    };
}

/// `row[j] = f(row[j], other[j])` in chunks of 8 so the body is one vector iteration.
#[inline(always)]
fn map2(row: &mut [f32], other: &[f32], f: impl Fn(f32, f32) -> f32) {
    let mut rc = row.chunks_exact_mut(8);
    let mut oc = other.chunks_exact(8);
    for (r, o) in (&mut rc).zip(&mut oc) {
        for k in 0..8 {
            r[k] = f(r[k], o[k]);
        }
    }
    for (r, &o) in rc.into_remainder().iter_mut().zip(oc.remainder()) {
        *r = f(*r, o);
    }
}

// ---------------------------------------------------------------------------------------------
// Derivatives of the activation, from the tape (y for tanh/relu, z for gelu).

#[inline(always)]
fn act_derivative_impl<const F: bool, const W: bool>(
    act: Activation,
    y: &[f32],
    z: &[f32],
    out: &mut [f32],
) {
    match act {
        Activation::Tanh => {
            for (d, &y) in out.iter_mut().zip(y) {
                *d = fmadd_neg::<F>(y, y, 1.0);
            }
        }
        Activation::Relu => {
            for (d, &y) in out.iter_mut().zip(y) {
                *d = if y > 0.0 { 1.0 } else { 0.0 };
            }
        }
        Activation::Identity => out.fill(1.0),
        Activation::Gelu => {
            for (d, &z) in out.iter_mut().zip(z) {
                *d = math::gelu_derivative::<F>(z);
            }
        }
    }
}

/// c − a·b, fused when `F`.
#[inline(always)]
fn fmadd_neg<const F: bool>(a: f32, b: f32, c: f32) -> f32 {
    math::fmadd::<F>(-a, b, c)
}

dispatch! {
    /// `out = act'(·)` element-wise from the tape: the output `y` (tanh, relu) or the
    /// pre-activation `z` (gelu).
    fn act_derivative(act: Activation, y: &[f32], z: &[f32], out: &mut [f32]) => act_derivative_impl
}

#[inline(always)]
fn mul_act_derivative_impl<const F: bool, const W: bool>(
    act: Activation,
    y: &[f32],
    z: &[f32],
    g: &mut [f32],
) {
    match act {
        Activation::Tanh => {
            for (g, &y) in g.iter_mut().zip(y) {
                *g *= fmadd_neg::<F>(y, y, 1.0);
            }
        }
        Activation::Relu => {
            for (g, &y) in g.iter_mut().zip(y) {
                *g = if y > 0.0 { *g } else { 0.0 };
            }
        }
        Activation::Identity => {}
        Activation::Gelu => {
            for (g, &z) in g.iter_mut().zip(z) {
                *g *= math::gelu_derivative::<F>(z);
            }
        }
    }
}

dispatch! {
    /// `g ⊙= act'(·)` element-wise (the backward step through an activation).
    fn mul_act_derivative(act: Activation, y: &[f32], z: &[f32], g: &mut [f32]) => mul_act_derivative_impl
}

#[inline(always)]
fn scale_rows_impl<const F: bool, const W: bool>(
    rows: &mut [f32],
    width: usize,
    per_row_block: usize,
    d: &[f32],
) {
    // rows is (blocks × per_row_block) rows of `width`; row r of block b is multiplied by d[b].
    for (block, dv) in rows
        .chunks_exact_mut(per_row_block * width)
        .zip(d.chunks_exact(width))
    {
        for row in block.chunks_exact_mut(width) {
            map2(row, dv, |r, d| r * d);
        }
    }
}

dispatch! {
    /// For Jacobians: `rows` holds `per_row_block` rows of length `width` for every sample; each
    /// is multiplied element-wise by that sample's row of `d`.
    fn scale_rows(rows: &mut [f32], width: usize, per_row_block: usize, d: &[f32]) => scale_rows_impl
}

#[inline(always)]
fn add_column_sums_impl<const F: bool, const W: bool>(acc: &mut [f32], m: &[f32]) {
    let width = acc.len();
    for row in m.chunks_exact(width) {
        map2(acc, row, |a, r| a + r);
    }
}

dispatch! {
    /// `acc[j] += Σ_rows m[row, j]` (bias gradients), rows summed in order.
    fn add_column_sums(acc: &mut [f32], m: &[f32]) => add_column_sums_impl
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn adam_impl<const F: bool, const W: bool>(
    params: &mut [f32],
    grads: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    coefs: [f32; 7],
) {
    let [beta1, beta2, step, inv_sqrt_bc2, eps, l2, decoupled] = coefs;
    let one_m_b1 = 1.0 - beta1;
    let one_m_b2 = 1.0 - beta2;
    for (((p, &g), m), v) in params
        .iter_mut()
        .zip(grads)
        .zip(m.iter_mut())
        .zip(v.iter_mut())
    {
        let g = math::fmadd::<F>(l2, *p, g);
        *m = math::fmadd::<F>(beta1, *m, one_m_b1 * g);
        *v = math::fmadd::<F>(beta2, *v, one_m_b2 * g * g);
        let denom = math::fmadd::<F>(v.sqrt(), inv_sqrt_bc2, eps);
        *p = math::fmadd::<F>(-decoupled, *p, *p) - step * *m / denom;
    }
}

dispatch! {
    /// One Adam update over the flat slices; `coefs` = [β1, β2, lr/(1−β1ᵗ), 1/√(1−β2ᵗ), ε,
    /// L2 weight decay added to the gradient, decoupled decay lr·λ].
    fn adam_update(params: &mut [f32], grads: &[f32], m: &mut [f32], v: &mut [f32], coefs: [f32; 7]) => adam_impl
}

// ---------------------------------------------------------------------------------------------
// GEMM on matrixmultiply (row-major, contiguous). Shapes are internal invariants: the public API
// checks every user-provided length before calling these, so a failed assert is a bug here.

/// C (m×n) = β·C + A (m×k) · Bᵀ, with B stored n×k row-major (a weight matrix [out, in]).
pub(crate) fn gemm_a_bt(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    b: &[f32],
    beta: f32,
    c: &mut [f32],
) {
    assert!(a.len() >= m * k && b.len() >= n * k && c.len() >= m * n);
    // SAFETY: the asserts above bound every access: A is read at i·k + p (i < m, p < k), B at
    // j·k + p (j < n), C written at i·n + j.
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            k as isize,
            1,
            b.as_ptr(),
            1,
            k as isize,
            beta,
            c.as_mut_ptr(),
            n as isize,
            1,
        );
    }
}

/// C (m×n) = β·C + A (m×k) · B (k×n), all row-major.
pub(crate) fn gemm_a_b(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    b: &[f32],
    beta: f32,
    c: &mut [f32],
) {
    assert!(a.len() >= m * k && b.len() >= k * n && c.len() >= m * n);
    // SAFETY: as above; B is read at p·n + j.
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            k as isize,
            1,
            b.as_ptr(),
            n as isize,
            1,
            beta,
            c.as_mut_ptr(),
            n as isize,
            1,
        );
    }
}

#[inline(always)]
fn tanh_in_place_impl<const F: bool, const W: bool>(x: &mut [f32]) {
    let mut chunks = x.chunks_exact_mut(8);
    for c in &mut chunks {
        for v in c.iter_mut() {
            *v = math::tanh::<F>(*v);
        }
    }
    for v in chunks.into_remainder() {
        *v = math::tanh::<F>(*v);
    }
}

dispatch! {
    /// `x = tanh(x)` element-wise with the rational approximation.
    fn tanh_in_place(x: &mut [f32]) => tanh_in_place_impl
}

// ---------------------------------------------------------------------------------------------
// Fused forward layer: out = act(A·Wᵀ + b), with Wᵀ packed k × n_pad (n_pad a multiple of NR).
//
// A register-blocked kernel: MR rows × NR columns of the output stay in registers while the
// k-loop broadcasts one element of each A row and multiplies it by NR contiguous packed weights;
// bias initialises the accumulators and the activation is applied on the registers before the
// single store. Compared with a general GEMM this needs no packing of A (the activations), wastes
// no work on the 3-wide output layer beyond one NR block, and saves a pass over memory for the
// activation. Every output element is computed as bias + Σ_p a_p·w_p in increasing p with the same
// (fused or unfused) multiply–add whatever block it falls in, so a row's result does not depend on
// the batch size or on how a batch is split across threads.

/// Output columns per register block (two AVX2 vectors). A narrower block for the 3-wide output
/// layer (8 rows × 1 vector) measured 7 % slower on the MPPI rollout: it needs one broadcast per
/// FMA.
pub(crate) const NR: usize = 16;
/// Rows per register block: 4 rows × 2 vectors = 8 accumulators (of 16 AVX2 registers).
const MR: usize = 4;

/// Packs `w` ([n, k] row-major) as Wᵀ into `wt` (k × n_pad, zero-padded) and the bias into
/// `bias_pad` (n_pad). Returns n_pad.
pub(crate) fn pack_transposed(
    w: &[f32],
    bias: &[f32],
    n: usize,
    k: usize,
    wt: &mut Vec<f32>,
    bias_pad: &mut Vec<f32>,
) -> usize {
    let n_pad = n.div_ceil(NR) * NR;
    wt.clear();
    wt.resize(k * n_pad, 0.0);
    for (o, row) in w.chunks_exact(k).enumerate().take(n) {
        for (p, &v) in row.iter().enumerate() {
            wt[p * n_pad + o] = v;
        }
    }
    bias_pad.clear();
    bias_pad.extend_from_slice(&bias[..n]);
    bias_pad.resize(n_pad, 0.0);
    n_pad
}

#[inline(always)]
fn act_block<const F: bool, const C: usize>(act: Activation, acc: &mut [f32; C]) {
    match act {
        Activation::Tanh => acc.iter_mut().for_each(|v| *v = math::tanh::<F>(*v)),
        Activation::Relu => acc
            .iter_mut()
            .for_each(|v| *v = if *v > 0.0 { *v } else { 0.0 }),
        Activation::Gelu => acc.iter_mut().for_each(|v| *v = math::gelu::<F>(*v)),
        Activation::Identity => {}
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn dense_block<const F: bool, const R: usize, const C: usize>(
    act: Activation,
    i: usize,
    k: usize,
    n: usize,
    n_pad: usize,
    a: &[f32],
    wt: &[f32],
    bias_pad: &[f32],
    out: &mut [f32],
    z: &mut [f32],
) {
    let rows: [&[f32]; R] = std::array::from_fn(|r| &a[(i + r) * k..(i + r + 1) * k]);
    let keep_z = act.needs_preactivation();
    for jb in (0..n_pad).step_by(C) {
        let mut acc = [[0.0f32; C]; R];
        let b0: &[f32; C] = bias_pad[jb..jb + C].try_into().unwrap_or(&[0.0; C]);
        for accr in acc.iter_mut() {
            *accr = *b0;
        }
        assert!(jb + C <= n_pad && wt.len() >= k * n_pad);
        for p in 0..k {
            // SAFETY: p < k and jb + C ≤ n_pad (asserted), so the C floats from p·n_pad + jb lie
            // within wt (length ≥ k·n_pad); [f32; C] has the alignment of f32. (A checked slice
            // with a fallible conversion kept the accumulators in memory across iterations.)
            let b: &[f32; C] = unsafe { &*wt.as_ptr().add(p * n_pad + jb).cast::<[f32; C]>() };
            for r in 0..R {
                // SAFETY: every `rows[r]` has exactly `k` elements (sliced above; the caller's
                // `a` holds m × k) and `p < k` (`take(k)`). Indexing without the check matters:
                // with 8 rows the checks were a third of the loop's instructions.
                let av = unsafe { *rows[r].get_unchecked(p) };
                for q in 0..C {
                    acc[r][q] = math::fmadd::<F>(av, b[q], acc[r][q]);
                }
            }
        }
        let full = jb + C <= n;
        let cols = C.min(n - jb);
        for (r, accr) in acc.iter_mut().enumerate() {
            let o = (i + r) * n + jb;
            if full {
                // Fixed-length copies compile to vector stores (a variable length calls memcpy).
                if keep_z {
                    z[o..o + C].copy_from_slice(accr);
                }
                act_block::<F, C>(act, accr);
                out[o..o + C].copy_from_slice(accr);
            } else {
                if keep_z {
                    store_partial::<C>(&mut z[o..o + cols], accr);
                }
                act_block::<F, C>(act, accr);
                store_partial::<C>(&mut out[o..o + cols], accr);
            }
        }
    }
}

/// `dst = acc[..dst.len()]` (`dst.len() < C`): whole vectors of [`NR`] as fixed-length copies,
/// the rest through a one-vector copy, so `acc` is only ever indexed at constant positions (a
/// variable-length copy from it called `memcpy` per row, and dynamic indexing would keep the
/// accumulators in memory).
#[inline(always)]
fn store_partial<const C: usize>(dst: &mut [f32], acc: &[f32; C]) {
    let cols = dst.len();
    for v in 0..C / NR {
        let c0 = v * NR;
        if c0 >= cols {
            break;
        }
        let mut src = [0.0f32; NR];
        src.copy_from_slice(&acc[c0..c0 + NR]);
        if c0 + NR <= cols {
            dst[c0..c0 + NR].copy_from_slice(&src);
        } else {
            for (d, s) in dst[c0..].iter_mut().zip(src.iter()) {
                *d = *s;
            }
        }
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn dense_forward_impl<const F: bool, const W: bool>(
    act: Activation,
    m: usize,
    k: usize,
    n: usize,
    n_pad: usize,
    a: &[f32],
    wt: &[f32],
    bias_pad: &[f32],
    out: &mut [f32],
    z: &mut [f32],
) {
    let mut i = 0;
    if W {
        // AVX-512 with at most 7 registers per output row: the whole padded row in one block of
        // 12–14 accumulators, so each packed weight vector loaded serves 2–6 rows and each
        // broadcast 2–7 vectors (the 8 × 16 block below loads one broadcast per FMA and is limited
        // by loads). Same arithmetic per element, so the result is bitwise that of any block.
        macro_rules! whole_rows {
            ($r:literal, $c:literal) => {{
                while i + $r <= m {
                    dense_block::<F, $r, $c>(act, i, k, n, n_pad, a, wt, bias_pad, out, z);
                    i += $r;
                }
                while i < m {
                    dense_block::<F, 1, $c>(act, i, k, n, n_pad, a, wt, bias_pad, out, z);
                    i += 1;
                }
                return;
            }};
        }
        match if act == Activation::Identity && k * n_pad <= 64 * 112 {
            n_pad
        } else {
            0
        } {
            112 => whole_rows!(2, 112),
            96 => whole_rows!(2, 96),
            80 => whole_rows!(2, 80),
            64 => whole_rows!(3, 64),
            48 => whole_rows!(4, 48),
            32 => whole_rows!(6, 32),
            _ => {}
        }
        // One row (a batch-1 forward: the sequential rollouts of a controller) of a layer 64 or
        // 32·j wide: the row's whole 64 (or 32) columns as independent accumulators, so the k
        // dependent FMAs of each column vector overlap instead of running one vector after the
        // other (latency-bound). Same arithmetic per element: bitwise the 16-column blocks.
        // (Not 64 columns under tanh: its polynomial in registers spilled in wider blocks.)
        if m == 1 {
            match n_pad {
                64 if act != Activation::Tanh => {
                    dense_block::<F, 1, 64>(act, 0, k, n, n_pad, a, wt, bias_pad, out, z)
                }
                p if p % 32 == 0 => {
                    dense_block::<F, 1, 32>(act, 0, k, n, n_pad, a, wt, bias_pad, out, z)
                }
                _ => dense_block::<F, 1, NR>(act, 0, k, n, n_pad, a, wt, bias_pad, out, z),
            }
            return;
        }
        // AVX-512: one 16-lane register per row, so twice the rows for 8 accumulators.
        while i + 2 * MR <= m {
            dense_block::<F, { 2 * MR }, NR>(act, i, k, n, n_pad, a, wt, bias_pad, out, z);
            i += 2 * MR;
        }
    }
    while i + MR <= m {
        dense_block::<F, MR, NR>(act, i, k, n, n_pad, a, wt, bias_pad, out, z);
        i += MR;
    }
    // The last rows (fewer than MR) in one block: in a block of R rows each column vector is a
    // chain of R dependent FMAs, so rows one at a time would each take as long as a whole block.
    // (Whole padded rows in registers instead spill in the activation: 20× slower per row.)
    match m - i {
        0 => {}
        1 => dense_block::<F, 1, NR>(act, i, k, n, n_pad, a, wt, bias_pad, out, z),
        2 => dense_block::<F, 2, NR>(act, i, k, n, n_pad, a, wt, bias_pad, out, z),
        _ => dense_block::<F, 3, NR>(act, i, k, n, n_pad, a, wt, bias_pad, out, z),
    }
}

dispatch! {
    /// `out (m×n) = act(a (m×k) · Wᵀ + b)` with `wt`, `bias_pad` from [`pack_transposed`]; for
    /// GELU the pre-activation is also written to `z` (m×n), otherwise `z` may be empty.
    #[allow(clippy::too_many_arguments)]
    fn dense_forward(act: Activation, m: usize, k: usize, n: usize, n_pad: usize, a: &[f32], wt: &[f32], bias_pad: &[f32], out: &mut [f32], z: &mut [f32]) => dense_forward_impl
}

// ---------------------------------------------------------------------------------------------
// Layouts for the reverse-mode products, which run on the forward layer's register-blocked kernel
// (`dense_forward` with the identity activation and a zero bias): dA = dZ·W reads W padded to
// n_pad columns, dW = dZᵀ·A reads dZᵀ and A padded. Copying these operands costs ≈ 1 % of the
// product and nothing is allocated after the first call (the general GEMM used before packed both
// operands into a buffer it allocated on every call).

/// Pads `w` ([k, n] row-major) to k × n_pad (n_pad a multiple of [`NR`], zero columns) in `wp`,
/// the layout `dense_forward` reads its weights in. Returns n_pad.
pub(crate) fn pack_padded(w: &[f32], k: usize, n: usize, wp: &mut Vec<f32>) -> usize {
    let n_pad = n.div_ceil(NR) * NR;
    // Grow only (no clearing pass): every row is written in full below.
    if wp.len() < k * n_pad {
        wp.resize(k * n_pad, 0.0);
    }
    for (dst, src) in wp.chunks_exact_mut(n_pad).zip(w.chunks_exact(n)).take(k) {
        dst[..n].copy_from_slice(src);
        dst[n..].fill(0.0);
    }
    n_pad
}

/// One register block of [`gemm_tn_add`]: rows `i..i + R` of `C`, columns `jb..jb + NC`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tn_block<const F: bool, const R: usize, const NC: usize>(
    i: usize,
    jb: usize,
    k: usize,
    n: usize,
    a: &[f32],
    lda: usize,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    unit: usize,
) {
    let mut acc = [[0.0f32; NC]; R];
    let (ap, bp) = (a.as_ptr(), b.as_ptr());
    for p in 0..k {
        // SAFETY: `gemm_tn_add` asserts b.len() ≥ (k − 1)·ldb + n_pad (and the bound on `a` used
        // below); here p < k and jb + NC ≤ n_pad, so the NC floats read from b are in bounds.
        // [f32; NC] has the alignment of f32.
        let bv: &[f32; NC] = unsafe { &*bp.add(p * ldb + jb).cast::<[f32; NC]>() };
        let arow = unsafe { ap.add(p * lda + i) };
        for (r, accr) in acc.iter_mut().enumerate() {
            // SAFETY: i + r < m and unit ≥ 1, so p·lda + i + r·unit ≤ (k − 1)·lda + (m − 1)·unit
            // < a.len() (asserted by `gemm_tn_add`).
            let av = unsafe { *arow.add(r * unit) };
            for q in 0..NC {
                accr[q] = math::fmadd::<F>(av, bv[q], accr[q]);
            }
        }
    }
    // Through a tile written at constant indices only: a run-time-length access to `acc` itself
    // would keep the accumulators in memory during the k-loop (measured: gathers, 2× slower).
    let mut tile = [0.0f32; TILE];
    for (r, accr) in acc.iter().enumerate() {
        tile[r * NC..(r + 1) * NC].copy_from_slice(accr);
    }
    let cols = NC.min(n - jb);
    for r in 0..R {
        let o = (i + r) * n + jb;
        for (d, s) in c[o..o + cols].iter_mut().zip(&tile[r * NC..r * NC + cols]) {
            *d += *s;
        }
    }
}

/// Floats of the largest register block of [`gemm_tn_add`] (2 rows × 112, 8 rows × 16).
const TILE: usize = 2 * 112;

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn gemm_tn_add_impl<const F: bool, const W: bool>(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    lda: usize,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
) {
    let n_pad = n.div_ceil(NR) * NR;
    if m == 0 || k == 0 || n == 0 {
        return;
    }
    assert!(lda >= m && a.len() >= (k - 1) * lda + m);
    assert!(ldb >= n && b.len() >= (k - 1) * ldb + n_pad);
    assert!(c.len() >= m * n);
    // The R values of A a block multiplies are adjacent in memory; known to be adjacent, they
    // made the compiler vectorise across the rows (8-lane FMAs with the accumulators transposed
    // and gathers: 2× slower). An opaque unit stride keeps them scalar broadcasts.
    let unit = std::hint::black_box(1usize);
    assert!(unit >= 1 && a.len() > (k - 1) * lda + (m - 1) * unit);
    let mut i = 0;
    if W {
        // AVX-512, at most 7 vectors per row: whole rows of 2–6 in 12–14 accumulators (each
        // B vector loaded serves several rows), as in `dense_forward`.
        macro_rules! whole_rows {
            ($r:literal, $c:literal) => {{
                while i + $r <= m {
                    tn_block::<F, $r, $c>(i, 0, k, n, a, lda, b, ldb, c, unit);
                    i += $r;
                }
                while i < m {
                    tn_block::<F, 1, $c>(i, 0, k, n, a, lda, b, ldb, c, unit);
                    i += 1;
                }
                return;
            }};
        }
        match n_pad {
            112 => whole_rows!(2, 112),
            96 => whole_rows!(2, 96),
            80 => whole_rows!(2, 80),
            64 => whole_rows!(3, 64),
            48 => whole_rows!(4, 48),
            32 => whole_rows!(6, 32),
            _ => {}
        }
        while i + 2 * MR <= m {
            for jb in (0..n_pad).step_by(NR) {
                tn_block::<F, { 2 * MR }, NR>(i, jb, k, n, a, lda, b, ldb, c, unit);
            }
            i += 2 * MR;
        }
    }
    while i + MR <= m {
        for jb in (0..n_pad).step_by(NR) {
            tn_block::<F, MR, NR>(i, jb, k, n, a, lda, b, ldb, c, unit);
        }
        i += MR;
    }
    while i < m {
        for jb in (0..n_pad).step_by(NR) {
            tn_block::<F, 1, NR>(i, jb, k, n, a, lda, b, ldb, c, unit);
        }
        i += 1;
    }
}

dispatch! {
    /// `C (m × n, row-major) += Aᵀ · B` for `A` stored k × m (row stride `lda`) and `B` k × n (row
    /// stride `ldb`), both read in place: the parameter gradient dW += dZᵀ·X of a layer with no
    /// transposed or padded copies. `B`'s rows are read over `n` rounded up to a multiple of
    /// [`NR`] (lanes beyond `n` are never stored), so `b` needs that many floats of slack after
    /// its last row. Every element of C gets `c + (Σ_p a_p·b_p)` with the sum from 0 in
    /// increasing `p` in one fused multiply–add chain: the rounding of computing the product on
    /// its own and then adding it to C.
    #[allow(clippy::too_many_arguments)]
    fn gemm_tn_add(m: usize, k: usize, n: usize, a: &[f32], lda: usize, b: &[f32], ldb: usize, c: &mut [f32]) => gemm_tn_add_impl
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `gemm_tn_add` against the scalar fused multiply–add chain it promises, bit for bit, on
    /// shapes that hit every block kind (whole rows, 8 × 16, 4 × 16, single rows, partial
    /// columns), with `b` holding exactly the slack the kernel may read.
    #[test]
    fn gemm_tn_add_is_c_plus_the_in_order_product() {
        let mut rng = crate::rng::SplitMix64::new(11);
        for &m in &[1usize, 3, 5, 8, 13, 100] {
            for &n in &[1usize, 6, 16, 17, 33, 100, 112] {
                for &k in &[1usize, 7, 64] {
                    let (lda, ldb) = (m + 2, n + 1);
                    let n_pad = n.div_ceil(NR) * NR;
                    let a: Vec<f32> = (0..(k - 1) * lda + m)
                        .map(|_| rng.uniform_symmetric(1.0))
                        .collect();
                    let b: Vec<f32> = (0..(k - 1) * ldb + n_pad)
                        .map(|_| rng.uniform_symmetric(1.0))
                        .collect();
                    let c0: Vec<f32> = (0..m * n).map(|_| rng.uniform_symmetric(1.0)).collect();
                    let mut c = c0.clone();
                    gemm_tn_add(m, k, n, &a, lda, &b, ldb, &mut c);
                    for i in 0..m {
                        for j in 0..n {
                            let mut acc = 0.0f32;
                            for p in 0..k {
                                acc = if use_fma() {
                                    math::fmadd::<true>(a[p * lda + i], b[p * ldb + j], acc)
                                } else {
                                    math::fmadd::<false>(a[p * lda + i], b[p * ldb + j], acc)
                                };
                            }
                            let want = c0[i * n + j] + acc;
                            assert_eq!(
                                c[i * n + j].to_bits(),
                                want.to_bits(),
                                "m {m} n {n} k {k} at ({i}, {j})"
                            );
                        }
                    }
                }
            }
        }
    }
}
