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

/// The SIMD code path chosen for this process: `"avx2+fma"`, `"neon+fma"` or `"baseline"`.
pub fn simd_level() -> &'static str {
    if !use_fma() {
        "baseline"
    } else if cfg!(target_arch = "aarch64") {
        "neon+fma"
    } else {
        "avx2+fma"
    }
}

/// Defines `pub(crate) fn $name(args)` dispatching to `$imp::<true>` compiled with AVX2 + FMA when
/// available, else `$imp::<false>` for the baseline target.
macro_rules! dispatch {
    ($(#[$m:meta])* fn $name:ident($($a:ident : $t:ty),* $(,)?) => $imp:ident) => {
        $(#[$m])*
        pub(crate) fn $name($($a: $t),*) {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                fn simd($($a: $t),*) {
                    $imp::<true>($($a),*)
                }
                if use_fma() {
                    // SAFETY: the CPU supports AVX2 and FMA (checked by `use_fma`).
                    return unsafe { simd($($a),*) };
                }
            }
            #[cfg(target_arch = "aarch64")]
            {
                return $imp::<true>($($a),*);
            }
            #[allow(unreachable_code)]
            $imp::<false>($($a),*)
        }
    };
}

// ---------------------------------------------------------------------------------------------
// Forward: y = act(z + b) row by row, optionally keeping z.

#[inline(always)]
fn bias_act_impl<const F: bool>(
    act: Activation,
    width: usize,
    bias: &[f32],
    out: &mut [f32],
    keep_z: &mut [f32],
) {
    let bias = &bias[..width];
    match act {
        Activation::Tanh => {
            for row in out.chunks_exact_mut(width) {
                map2(row, bias, |v, b| math::tanh::<F>(v + b));
            }
        }
        Activation::Relu => {
            for row in out.chunks_exact_mut(width) {
                map2(row, bias, |v, b| {
                    let s = v + b;
                    if s > 0.0 { s } else { 0.0 }
                });
            }
        }
        Activation::Identity => {
            for row in out.chunks_exact_mut(width) {
                map2(row, bias, |v, b| v + b);
            }
        }
        Activation::Gelu => {
            for (row, zrow) in out
                .chunks_exact_mut(width)
                .zip(keep_z.chunks_exact_mut(width))
            {
                for ((y, z), &b) in row.iter_mut().zip(zrow.iter_mut()).zip(bias) {
                    let s = *y + b;
                    *z = s;
                    *y = math::gelu::<F>(s);
                }
            }
        }
    }
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

dispatch! {
    /// `out` holds x·Wᵀ (rows of `width`); adds the bias and applies `act` in place. For GELU the
    /// pre-activation is also written to `keep_z` (same length as `out`; unused otherwise).
    fn bias_act(act: Activation, width: usize, bias: &[f32], out: &mut [f32], keep_z: &mut [f32]) => bias_act_impl
}

// ---------------------------------------------------------------------------------------------
// Derivatives of the activation, from the tape (y for tanh/relu, z for gelu).

#[inline(always)]
fn act_derivative_impl<const F: bool>(act: Activation, y: &[f32], z: &[f32], out: &mut [f32]) {
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
fn mul_act_derivative_impl<const F: bool>(act: Activation, y: &[f32], z: &[f32], g: &mut [f32]) {
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
fn scale_rows_impl<const F: bool>(rows: &mut [f32], width: usize, per_row_block: usize, d: &[f32]) {
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
fn add_column_sums_impl<const F: bool>(acc: &mut [f32], m: &[f32]) {
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
fn adam_impl<const F: bool>(
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

/// C (m×n) = β·C + Aᵀ · B, with A stored k×m and B stored k×n row-major (weight gradients:
/// dW = dZᵀ · X summed over the batch).
pub(crate) fn gemm_at_b(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    b: &[f32],
    beta: f32,
    c: &mut [f32],
) {
    assert!(a.len() >= k * m && b.len() >= k * n && c.len() >= m * n);
    // SAFETY: A is read at p·m + i, B at p·n + j, C written at i·n + j.
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            1,
            m as isize,
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
