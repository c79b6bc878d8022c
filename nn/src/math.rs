//! Branch-free scalar approximations of `tanh`, `exp`, `erfc` and GELU that LLVM vectorises.
//!
//! Every function here is `#[inline(always)]`, uses only `+ − × ÷`, comparisons that compile to
//! `min`/`max`/blend, and integer bit manipulation, so a loop over a slice compiles to packed SIMD
//! code (8 lanes with AVX2). The accuracy figures are checked by the tests in `nn/tests/math.rs`
//! against `f64` references on dense grids.
//!
//! The polynomial coefficients were fitted for this crate (least squares with Lawson re-weighting
//! towards the minimax solution, in `f64`, then rounded to `f32`).
//!
//! The `FMA` const parameter selects fused multiply–add (`f32::mul_add`, one rounding, only fast
//! where the CPU has FMA) or a separate multiply and add. Both are deterministic; they differ in
//! the last bit, so one process always uses the same choice (see [`crate::simd_level`]).

/// Clamp point of the rational tanh: beyond |x| = 9, tanh(x) rounds to ±1 in `f32`.
pub const TANH_CLAMP: f32 = 9.0;

// tanh(x) ≈ x · P(x²) / Q(x²) on [−9, 9] (degree 4 in x² over degree 4 in x²).
const TANH_P: [f32; 5] = [
    0.999_999_94,
    0.133_733_36,
    0.003_486_693_1,
    2.047_184_2e-5,
    1.318_131e-8,
];
const TANH_Q: [f32; 5] = [
    1.0,
    0.467_066_35,
    0.025_842_534,
    0.000_327_148_53,
    7.702_065_5e-7,
];

// e^r ≈ 1 + r + r² · E(r) on r ∈ [−ln2/2, ln2/2] (relative error 3e-9 before rounding).
const EXP_E: [f32; 5] = [
    0.499_999_94,
    0.166_665_21,
    0.041_668_39,
    0.008_368_71,
    0.001_381_461_3,
];

// erfc(z) ≈ t · exp(−z² + G(t)), t = 1 / (1 + z/2), z ≥ 0 (relative error 5e-8 before rounding,
// fitted on z ∈ [0, 10]; below that erfc underflows anyway).
const ERFC_G: [f32; 10] = [
    -1.265_441_4,
    0.998_492_54,
    0.387_899_76,
    0.028_356_567,
    0.020_198_638,
    -0.116_794_55,
    -0.651_237_5,
    1.122_390_9,
    -0.666_057_94,
    0.142_193_15,
];

/// a·b + c, fused when `FMA`.
#[inline(always)]
pub fn fmadd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

#[inline(always)]
fn horner<const FMA: bool, const N: usize>(c: &[f32; N], x: f32) -> f32 {
    let mut acc = c[N - 1];
    let mut i = N - 1;
    while i > 0 {
        i -= 1;
        acc = fmadd::<FMA>(acc, x, c[i]);
    }
    acc
}

/// `min(max(x, lo), hi)` written so that it compiles to `minps`/`maxps` without a branch (a NaN
/// input passes through unchanged, so NaN propagates through every function here).
#[inline(always)]
fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    let x = if x < lo { lo } else { x };
    if x > hi { hi } else { x }
}

/// Rational approximation of tanh, maximum absolute error 3.5e-7 over all of ℝ (3.0e-7 with FMA),
/// odd by construction, |tanh(x)| ≤ 1; for |x| ≥ 9 it returns ±0.99999994 (one `f32` step below 1).
///
/// Its derivative is taken from the output as 1 − y² (the exact tanh derivative at the
/// approximate value); the difference to the derivative of the rational function itself is below
/// 1e-6, far under `f32` finite-difference noise.
#[inline(always)]
pub fn tanh<const FMA: bool>(x: f32) -> f32 {
    let x = clamp(x, -TANH_CLAMP, TANH_CLAMP);
    let u = x * x;
    let p = horner::<FMA, 5>(&TANH_P, u);
    let q = horner::<FMA, 5>(&TANH_Q, u);
    let y = x * p / q;
    clamp(y, -1.0, 1.0)
}

/// e^x with relative error ≈ 2e-7 for x ∈ [−87, 88]; above 88 it returns e^88, below −87 exactly 0
/// (no denormals).
#[inline(always)]
pub fn exp<const FMA: bool>(x: f32) -> f32 {
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that n · LN2_HI is exact for |n| < 2^9.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5 · 2^23: adding it rounds to the nearest integer and leaves the integer in the low bits.
    const ROUND: f32 = 12_582_912.0;
    let x_in = x;
    let x = clamp(x, -87.0, 88.0);
    let t = fmadd::<FMA>(x, LOG2_E, ROUND);
    let n = t - ROUND;
    let r = fmadd::<FMA>(-n, LN2_HI, x);
    let r = fmadd::<FMA>(-n, LN2_LO, r);
    let e = horner::<FMA, 5>(&EXP_E, r);
    let p = fmadd::<FMA>(r * r, e, r) + 1.0;
    // 2^n from the integer in t's mantissa: n ∈ [−126, 127] after the clamp.
    let ni = (t.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let scale = f32::from_bits((ni.wrapping_add(127) as u32) << 23);
    if x_in < -87.0 { 0.0 } else { p * scale }
}

/// erfc(z) for z ≥ 0 with small relative error (≈ 3e-7 where erfc is a normal `f32`), as
/// t·exp(−z² + G(t)), t = 1/(1 + z/2).
#[inline(always)]
pub fn erfc_nonneg<const FMA: bool>(z: f32) -> f32 {
    let t = 1.0 / fmadd::<FMA>(0.5, z, 1.0);
    let g = horner::<FMA, 10>(&ERFC_G, t);
    t * exp::<FMA>(fmadd::<FMA>(-z, z, g))
}

/// Φ(x), the standard normal cumulative distribution, as ½·erfc(−x/√2), branch-free.
#[inline(always)]
pub fn normal_cdf<const FMA: bool>(x: f32) -> f32 {
    let z = x.abs() * std::f32::consts::FRAC_1_SQRT_2;
    let tail = 0.5 * erfc_nonneg::<FMA>(z);
    if x < 0.0 { tail } else { 1.0 - tail }
}

/// φ(x), the standard normal density.
#[inline(always)]
pub fn normal_pdf<const FMA: bool>(x: f32) -> f32 {
    const INV_SQRT_2PI: f32 = 0.398_942_3;
    INV_SQRT_2PI * exp::<FMA>(-0.5 * x * x)
}

/// GELU in its exact (erf) form, x·Φ(x) — the form PyTorch's `nn.GELU()` uses by default, not the
/// tanh approximation.
#[inline(always)]
pub fn gelu<const FMA: bool>(x: f32) -> f32 {
    x * normal_cdf::<FMA>(x)
}

/// d/dx GELU(x) = Φ(x) + x·φ(x).
#[inline(always)]
pub fn gelu_derivative<const FMA: bool>(x: f32) -> f32 {
    fmadd::<FMA>(x, normal_pdf::<FMA>(x), normal_cdf::<FMA>(x))
}

/// Runtime-dispatched scalar tanh (the same arithmetic the vector kernels use in this process).
pub fn tanh_f32(x: f32) -> f32 {
    if crate::kernels::use_fma() {
        tanh::<true>(x)
    } else {
        tanh::<false>(x)
    }
}

/// Runtime-dispatched scalar exact-form GELU.
pub fn gelu_f32(x: f32) -> f32 {
    if crate::kernels::use_fma() {
        gelu::<true>(x)
    } else {
        gelu::<false>(x)
    }
}

/// Runtime-dispatched scalar GELU derivative.
pub fn gelu_derivative_f32(x: f32) -> f32 {
    if crate::kernels::use_fma() {
        gelu_derivative::<true>(x)
    } else {
        gelu_derivative::<false>(x)
    }
}

/// Runtime-dispatched scalar e^x (see [`exp`]).
pub fn exp_f32(x: f32) -> f32 {
    if crate::kernels::use_fma() {
        exp::<true>(x)
    } else {
        exp::<false>(x)
    }
}

/// `x ← tanh(x)` over a slice with the runtime-selected SIMD kernel (the loop the forward pass
/// uses; exposed for benchmarks and for callers with their own buffers).
pub fn tanh_slice(x: &mut [f32]) {
    crate::kernels::tanh_in_place(x);
}
