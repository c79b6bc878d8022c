//! The multilayer perceptron: architecture, parameters, forward pass, reverse mode (VJP), forward
//! mode (JVP) and batched input Jacobians.

use std::ops::Range;
use std::sync::OnceLock;

use crate::kernels::{self, gemm_a_b, gemm_a_bt};
use crate::rng::SplitMix64;
use crate::{Activation, NnError};

thread_local! {
    /// The two layer-gradient buffers of [`Mlp::backward`] on this thread (taken for a call and
    /// put back after it).
    static SCRATCH: std::cell::Cell<(Vec<f32>, Vec<f32>)> =
        const { std::cell::Cell::new((Vec::new(), Vec::new())) };
}

/// Batch rows per block of the weight-gradient product (the padded layer input of a block,
/// 64 × 112 floats for the pushing network, stays in the L1 cache).
const KC: usize = 64;

/// Layer sizes and hidden activations of an [`Mlp`].
///
/// `sizes = [n_in, h_1, …, h_{L−1}, n_out]` describes `L = sizes.len() − 1` affine layers; hidden
/// layer `l` (all but the last) is followed by `activations[l]`, the last is linear.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MlpSpec {
    sizes: Vec<usize>,
    activations: Vec<Activation>,
}

impl MlpSpec {
    /// A network with the given layer sizes and one activation per hidden layer
    /// (`activations.len() == sizes.len() − 2`).
    pub fn new(sizes: &[usize], activations: &[Activation]) -> Result<Self, NnError> {
        if sizes.len() < 2 {
            return Err(NnError::InvalidArchitecture {
                reason: format!(
                    "need at least an input and an output size, got sizes {sizes:?} \
                     (for example [6, 100, 100, 3])"
                ),
            });
        }
        if let Some(i) = sizes.iter().position(|&s| s == 0) {
            return Err(NnError::InvalidArchitecture {
                reason: format!(
                    "layer size {i} is zero in {sizes:?}: every layer needs at least one unit"
                ),
            });
        }
        if activations.len() != sizes.len() - 2 {
            return Err(NnError::InvalidArchitecture {
                reason: format!(
                    "{} hidden layers (sizes {sizes:?}) need {} activations, got {}",
                    sizes.len() - 2,
                    sizes.len() - 2,
                    activations.len()
                ),
            });
        }
        Ok(Self {
            sizes: sizes.to_vec(),
            activations: activations.to_vec(),
        })
    }

    /// `n_in → hidden[0] → … → n_out` with the same activation after every hidden layer.
    pub fn uniform(
        n_in: usize,
        hidden: &[usize],
        n_out: usize,
        activation: Activation,
    ) -> Result<Self, NnError> {
        let mut sizes = Vec::with_capacity(hidden.len() + 2);
        sizes.push(n_in);
        sizes.extend_from_slice(hidden);
        sizes.push(n_out);
        Self::new(&sizes, &vec![activation; hidden.len()])
    }

    /// Layer sizes `[n_in, h_1, …, n_out]`.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// One activation per hidden layer.
    pub fn activations(&self) -> &[Activation] {
        &self.activations
    }

    /// Number of parameters (weights and biases).
    pub fn n_params(&self) -> usize {
        self.sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
    }
}

/// How [`Mlp::new`] draws the initial weights (biases start at zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Init {
    /// Xavier (Glorot) uniform: U(±g·√(6/(fan_in + fan_out))), g the activation's gain (5/3 for
    /// tanh, √2 for ReLU/GELU, 1 for the linear output layer).
    XavierUniform,
    /// Kaiming (He) uniform: U(±g·√(3/fan_in)) with the same gains.
    KaimingUniform,
    /// Xavier for layers followed by tanh or nothing, Kaiming for ReLU and GELU.
    #[default]
    Auto,
}

/// Where one affine layer lives in the flat parameter vector.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LayerShape {
    /// Input width.
    pub n_in: usize,
    /// Output width.
    pub n_out: usize,
    /// Range of the weight matrix, `[n_out, n_in]` row-major (PyTorch's `nn.Linear.weight`).
    pub weight: Range<usize>,
    /// Range of the bias vector `[n_out]`.
    pub bias: Range<usize>,
    /// Activation after this layer (`Identity` for the output layer).
    pub activation: Activation,
}

/// Borrowed parameters of one layer.
#[derive(Debug, Clone, Copy)]
pub struct LayerView<'a> {
    /// `[n_out, n_in]` row-major.
    pub weight: &'a [f32],
    /// `[n_out]`.
    pub bias: &'a [f32],
    /// Input width.
    pub n_in: usize,
    /// Output width.
    pub n_out: usize,
    /// Activation after this layer.
    pub activation: Activation,
}

/// Which automatic-differentiation mode [`Mlp::jacobian_with`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum JacobianMode {
    /// Reverse mode when `n_out ≤ n_in`, forward mode otherwise (fewer propagated rows).
    #[default]
    Auto,
    /// Propagate `n_out` cotangents per sample from the output back to the input.
    Reverse,
    /// Propagate `n_in` tangents per sample from the input to the output.
    Forward,
}

/// A multilayer perceptron in `f32` with all parameters in one flat vector.
///
/// Layout of [`Mlp::params`]: for each layer in order, the weight `[n_out, n_in]` row-major then
/// the bias `[n_out]` — the order of PyTorch's `nn.Sequential(Linear, act, Linear, …).parameters()`,
/// so an optimiser, a checkpoint or a gradient is one slice.
///
/// Batches are row-major `batch × width` slices. Every evaluation goes through a [`Workspace`]
/// that owns the buffers (grown on first use, then reused without allocating) and records the
/// activations needed by [`Mlp::backward`].
///
/// The network also keeps its weights in the layouts the kernels read (transposed and padded),
/// packed on the first evaluation after a parameter change and shared by every workspace and
/// thread until the next: every parameter write goes through [`Mlp::params_mut`] (or creates a
/// network), which drops the packing. So an MPPI step packs each layer once per model, and a
/// training step once per parameter update (not once per workspace: an RK4 step has four).
#[derive(Debug, Clone)]
pub struct Mlp {
    spec: MlpSpec,
    layers: Vec<LayerShape>,
    params: Vec<f32>,
    /// The packed weights for the current parameter values (empty until first needed).
    packed: OnceLock<Packed>,
}

/// Every layer's weights in the layouts the kernels read, for one set of parameter values.
#[derive(Debug, Clone, Default)]
struct Packed {
    /// Per layer: Wᵀ and bias for the forward kernel.
    fwd: Vec<PackedLayer>,
    /// Per layer: W padded for the input-gradient product of `backward`.
    bwd: Vec<PackedLayer>,
    /// Zeros, the bias of the input-gradient product (as long as the widest padded layer).
    zeros: Vec<f32>,
}

impl PartialEq for Mlp {
    fn eq(&self, other: &Self) -> bool {
        self.spec == other.spec && self.layers == other.layers && self.params == other.params
    }
}

impl Mlp {
    /// A network with weights drawn by `init` from `seed` (the same on every platform: SplitMix64
    /// and exactly rounded `f64` arithmetic) and zero biases.
    pub fn new(spec: MlpSpec, init: Init, seed: u64) -> Self {
        let mut mlp = Self::zeros(spec);
        let mut rng = SplitMix64::new(seed);
        for layer in &mlp.layers {
            let fan_in = layer.n_in as f64;
            let fan_out = layer.n_out as f64;
            let gain = layer.activation.xavier_gain();
            let kaiming = match init {
                Init::XavierUniform => false,
                Init::KaimingUniform => true,
                Init::Auto => matches!(layer.activation, Activation::Relu | Activation::Gelu),
            };
            let bound = if kaiming {
                gain * (3.0 / fan_in).sqrt()
            } else {
                gain * (6.0 / (fan_in + fan_out)).sqrt()
            };
            for w in &mut mlp.params[layer.weight.clone()] {
                *w = rng.uniform_symmetric(bound);
            }
        }
        mlp
    }

    /// A network with all parameters zero (to be loaded).
    pub fn zeros(spec: MlpSpec) -> Self {
        let mut layers = Vec::with_capacity(spec.sizes.len() - 1);
        let mut offset = 0;
        let n_layers = spec.sizes.len() - 1;
        for l in 0..n_layers {
            let (n_in, n_out) = (spec.sizes[l], spec.sizes[l + 1]);
            let weight = offset..offset + n_in * n_out;
            let bias = weight.end..weight.end + n_out;
            offset = bias.end;
            let activation = if l + 1 < n_layers {
                spec.activations[l]
            } else {
                Activation::Identity
            };
            layers.push(LayerShape {
                n_in,
                n_out,
                weight,
                bias,
                activation,
            });
        }
        Self {
            params: vec![0.0; offset],
            layers,
            spec,
            packed: OnceLock::new(),
        }
    }

    /// The architecture.
    pub fn spec(&self) -> &MlpSpec {
        &self.spec
    }

    /// Layer sizes `[n_in, …, n_out]`.
    pub fn sizes(&self) -> &[usize] {
        &self.spec.sizes
    }

    /// Input width.
    pub fn n_in(&self) -> usize {
        self.spec.sizes[0]
    }

    /// Output width.
    pub fn n_out(&self) -> usize {
        self.spec.sizes[self.spec.sizes.len() - 1]
    }

    /// Number of affine layers.
    pub fn n_layers(&self) -> usize {
        self.layers.len()
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.params.len()
    }

    /// Where each layer's weight and bias live in [`Mlp::params`].
    pub fn layer_shapes(&self) -> &[LayerShape] {
        &self.layers
    }

    /// All parameters, flat (see the type's documentation for the layout).
    pub fn params(&self) -> &[f32] {
        &self.params
    }

    /// All parameters, flat and mutable (for an optimiser step). Drops the packed weights, so
    /// the next evaluation packs the new values.
    pub fn params_mut(&mut self) -> &mut [f32] {
        self.packed = OnceLock::new();
        &mut self.params
    }

    /// Layer `l`'s weight and bias, or `None` past the last layer.
    pub fn layer(&self, l: usize) -> Option<LayerView<'_>> {
        self.layers.get(l).map(|s| LayerView {
            weight: &self.params[s.weight.clone()],
            bias: &self.params[s.bias.clone()],
            n_in: s.n_in,
            n_out: s.n_out,
            activation: s.activation,
        })
    }

    /// A fresh workspace for this architecture (buffers grow on first use).
    pub fn workspace(&self) -> Workspace {
        Workspace::new(&self.spec)
    }

    fn check_workspace(&self, ws: &Workspace) -> Result<(), NnError> {
        if ws.sizes != self.spec.sizes || ws.activations != self.spec.activations {
            return Err(NnError::WorkspaceMismatch {
                workspace: ws.sizes.clone(),
                network: self.spec.sizes.clone(),
            });
        }
        Ok(())
    }

    fn batch_of(&self, x: &[f32]) -> Result<usize, NnError> {
        let n_in = self.n_in();
        if !x.len().is_multiple_of(n_in) {
            return Err(NnError::RaggedBatch { len: x.len(), n_in });
        }
        Ok(x.len() / n_in)
    }

    /// Evaluates the network on a batch `x` (`batch × n_in`, row-major) and returns the outputs
    /// (`batch × n_out`), keeping in `ws` what [`Mlp::backward`] needs.
    pub fn forward<'w>(&self, x: &[f32], ws: &'w mut Workspace) -> Result<&'w [f32], NnError> {
        self.check_workspace(ws)?;
        let batch = self.batch_of(x)?;
        ws.reserve(batch);
        ws.batch = None;
        ws.x[..x.len()].copy_from_slice(x);
        let packs = self.packed();
        for (l, layer) in self.layers.iter().enumerate() {
            let (input, rest) = ws.a.split_at_mut(l);
            let input: &[f32] = if l == 0 { &ws.x } else { &input[l - 1] };
            let out = &mut rest[0][..batch * layer.n_out];
            let packed = &packs.fwd[l];
            let z_len = if layer.activation.needs_preactivation() {
                batch * layer.n_out
            } else {
                0
            };
            kernels::dense_forward(
                layer.activation,
                batch,
                layer.n_in,
                layer.n_out,
                packed.n_pad,
                &input[..batch * layer.n_in],
                &packed.w,
                &packed.bias,
                out,
                &mut ws.z[l][..z_len],
            );
        }
        ws.batch = Some(batch);
        Ok(ws.output())
    }

    /// Reverse mode (vector–Jacobian product) through the forward pass recorded in `ws`.
    ///
    /// `dy` is ∂loss/∂y (`batch × n_out`). The parameter gradient ∂loss/∂θ = dyᵀ·∂y/∂θ is
    /// **added** to `grad` (length [`Mlp::n_params`], same layout as the parameters), so
    /// several backward passes (a batch split in pieces, the stages of an ODE solver) accumulate;
    /// zero it at the start of a step. If `dx` is given, ∂loss/∂x (`batch × n_in`) is written to
    /// it (overwriting). The parameters must not change between `forward` and `backward`.
    pub fn backward(
        &self,
        ws: &mut Workspace,
        dy: &[f32],
        grad: &mut [f32],
        dx: Option<&mut [f32]>,
    ) -> Result<(), NnError> {
        self.check_workspace(ws)?;
        let batch = ws.batch.ok_or(NnError::NoTape)?;
        check_len("dy", batch * self.n_out(), dy.len())?;
        check_len("grad", self.params.len(), grad.len())?;
        if let Some(dx) = &dx {
            check_len("dx", batch * self.n_in(), dx.len())?;
        }
        let packs = self.packed();
        // The layer gradients are scratch, not tape: one pair of buffers per thread serves every
        // workspace (the 4·k stage workspaces of a NeuralODE chunk), so they stay in cache
        // instead of each workspace's own pair being touched once per training step.
        let (mut cur, mut next) = SCRATCH.with(|c| c.take());
        let width = self.spec.sizes.iter().copied().max().unwrap_or(0);
        grow(&mut cur, batch * width);
        grow(&mut next, batch * width);
        let mut dx = dx;
        for (l, layer) in self.layers.iter().enumerate().rev() {
            let (n_in, n_out) = (layer.n_in, layer.n_out);
            // dz of this layer: dy for the output layer, else the scratch buffer.
            let dz: &[f32] = if l + 1 == self.layers.len() {
                dy
            } else {
                &cur[..batch * n_out]
            };
            let input: &[f32] = if l == 0 { &ws.x } else { &ws.a[l - 1] };
            // dW += dzᵀ·input, (n_out × rows) · (rows × n_in), in blocks of KC batch rows so that
            // the input block stays in L1. Both operands are read in place (dz transposed, the
            // input rows over their padded width: the workspace keeps `NR` floats of slack after
            // each buffer for that) and each block's product is added to `grad` as it is stored.
            let mut p0 = 0;
            while p0 < batch {
                let kc = KC.min(batch - p0);
                kernels::gemm_tn_add(
                    n_out,
                    kc,
                    n_in,
                    &dz[p0 * n_out..],
                    n_out,
                    &input[p0 * n_in..],
                    n_in,
                    &mut grad[layer.weight.clone()],
                );
                p0 += kc;
            }
            kernels::add_column_sums(&mut grad[layer.bias.clone()], dz);
            // d(input) = dz·W: (batch × n_out) · (n_out × n_in).
            let target: &mut [f32] = if l > 0 {
                &mut next[..batch * n_in]
            } else if let Some(dx) = dx.take() {
                dx
            } else {
                continue;
            };
            let packed = &packs.bwd[l];
            let zeros = &packs.zeros[..packed.n_pad];
            kernels::dense_forward(
                Activation::Identity,
                batch,
                n_out,
                n_in,
                packed.n_pad,
                dz,
                &packed.w,
                zeros,
                target,
                &mut [],
            );
            if l > 0 {
                let prev = &self.layers[l - 1];
                let z_len = if prev.activation.needs_preactivation() {
                    batch * n_in
                } else {
                    0
                };
                kernels::mul_act_derivative(
                    prev.activation,
                    &ws.a[l - 1][..batch * n_in],
                    &ws.z[l - 1][..z_len],
                    &mut next[..batch * n_in],
                );
                std::mem::swap(&mut cur, &mut next);
            }
        }
        SCRATCH.with(|c| c.set((cur, next)));
        Ok(())
    }

    /// The packed weights of the current parameters (packed here on first use).
    fn packed(&self) -> &Packed {
        self.packed.get_or_init(|| {
            let mut p = Packed::default();
            for layer in &self.layers {
                let w = &self.params[layer.weight.clone()];
                let mut f = PackedLayer::default();
                f.n_pad = kernels::pack_transposed(
                    w,
                    &self.params[layer.bias.clone()],
                    layer.n_out,
                    layer.n_in,
                    &mut f.w,
                    &mut f.bias,
                );
                p.fwd.push(f);
                let mut b = PackedLayer::default();
                b.n_pad = kernels::pack_padded(w, layer.n_out, layer.n_in, &mut b.w);
                p.bwd.push(b);
            }
            let widest = p.bwd.iter().map(|b| b.n_pad).max().unwrap_or(0);
            p.zeros = vec![0.0; widest];
            p
        })
    }

    /// Forward mode (Jacobian–vector product): returns `(y, dy)` with y = f(x) and dy = J(x)·dx,
    /// one tangent `dx` per sample (`dx` has the shape of `x`). Also records `ws` for `backward`.
    pub fn jvp<'w>(
        &self,
        x: &[f32],
        dx: &[f32],
        ws: &'w mut Workspace,
    ) -> Result<(&'w [f32], &'w [f32]), NnError> {
        check_len("dx", x.len(), dx.len())?;
        self.forward(x, ws)?;
        let batch = ws.batch.ok_or(NnError::NoTape)?;
        let width = self.spec.sizes.iter().copied().max().unwrap_or(0);
        grow(&mut ws.g0, batch * width);
        grow(&mut ws.g1, batch * width);
        let mut cur = std::mem::take(&mut ws.g0);
        let mut next = std::mem::take(&mut ws.g1);
        for (l, layer) in self.layers.iter().enumerate() {
            let (n_in, n_out) = (layer.n_in, layer.n_out);
            let t: &[f32] = if l == 0 { dx } else { &cur[..batch * n_in] };
            let u = &mut next[..batch * n_out];
            gemm_a_bt(
                batch,
                n_in,
                n_out,
                t,
                &self.params[layer.weight.clone()],
                0.0,
                u,
            );
            let z_len = if layer.activation.needs_preactivation() {
                batch * n_out
            } else {
                0
            };
            kernels::mul_act_derivative(
                layer.activation,
                &ws.a[l][..batch * n_out],
                &ws.z[l][..z_len],
                u,
            );
            std::mem::swap(&mut cur, &mut next);
        }
        ws.g0 = cur;
        ws.g1 = next;
        let n = batch * self.n_out();
        let ws: &'w Workspace = ws;
        Ok((&ws.a[self.layers.len() - 1][..n], &ws.g0[..n]))
    }

    /// Input Jacobians ∂f/∂x of every sample: `batch × n_out × n_in` row-major, choosing forward
    /// or reverse mode by shape. The outputs f(x) are left in `ws` ([`Workspace::output`]).
    pub fn jacobian<'w>(&self, x: &[f32], ws: &'w mut Workspace) -> Result<&'w [f32], NnError> {
        self.jacobian_with(x, ws, JacobianMode::Auto)
    }

    /// [`Mlp::jacobian`] with an explicit differentiation mode (both give the same Jacobian up to
    /// rounding; the tests check that they agree).
    pub fn jacobian_with<'w>(
        &self,
        x: &[f32],
        ws: &'w mut Workspace,
        mode: JacobianMode,
    ) -> Result<&'w [f32], NnError> {
        self.forward(x, ws)?;
        let batch = ws.batch.ok_or(NnError::NoTape)?;
        let (n_in, n_out) = (self.n_in(), self.n_out());
        let reverse = match mode {
            JacobianMode::Auto => n_out <= n_in,
            JacobianMode::Reverse => true,
            JacobianMode::Forward => false,
        };
        let n_layers = self.layers.len();
        // act' of every hidden layer for every sample.
        for (l, layer) in self.layers[..n_layers - 1].iter().enumerate() {
            let len = batch * layer.n_out;
            let z_len = if layer.activation.needs_preactivation() {
                len
            } else {
                0
            };
            // grown here, not in `reserve`: only Jacobians need it (training never touches it)
            grow(&mut ws.deriv[l], len);
            kernels::act_derivative(
                layer.activation,
                &ws.a[l][..len],
                &ws.z[l][..z_len],
                &mut ws.deriv[l][..len],
            );
        }
        let jac_len = batch * n_out * n_in;
        let rows_per_sample = if reverse { n_out } else { n_in };
        let max_width = self.spec.sizes.iter().copied().max().unwrap_or(0);
        grow(&mut ws.jac, jac_len);
        grow(&mut ws.j0, batch * rows_per_sample * max_width);
        grow(&mut ws.j1, batch * rows_per_sample * max_width);
        let mut cur = std::mem::take(&mut ws.j0);
        let mut next = std::mem::take(&mut ws.j1);
        let rows = batch * rows_per_sample;
        if reverse {
            // Row (b, o) starts as e_oᵀ; through the output layer it becomes W_L[o, :].
            let last = &self.layers[n_layers - 1];
            let w = &self.params[last.weight.clone()];
            for block in cur[..rows * last.n_in].chunks_exact_mut(n_out * last.n_in) {
                block.copy_from_slice(w);
            }
            for l in (0..n_layers - 1).rev() {
                let layer = &self.layers[l];
                let width = layer.n_out;
                kernels::scale_rows(
                    &mut cur[..rows * width],
                    width,
                    n_out,
                    &ws.deriv[l][..batch * width],
                );
                let w = &self.params[layer.weight.clone()];
                gemm_a_b(
                    rows,
                    width,
                    layer.n_in,
                    &cur[..rows * width],
                    w,
                    0.0,
                    &mut next[..rows * layer.n_in],
                );
                std::mem::swap(&mut cur, &mut next);
            }
            ws.jac[..jac_len].copy_from_slice(&cur[..jac_len]);
        } else {
            // Row (b, i) starts as e_iᵀ; through the first layer it becomes W_1[:, i]ᵀ.
            let first = &self.layers[0];
            let w = &self.params[first.weight.clone()];
            for block in cur[..rows * first.n_out].chunks_exact_mut(n_in * first.n_out) {
                for (i, row) in block.chunks_exact_mut(first.n_out).enumerate() {
                    for (o, r) in row.iter_mut().enumerate() {
                        *r = w[o * n_in + i];
                    }
                }
            }
            for l in 0..n_layers {
                let layer = &self.layers[l];
                if l > 0 {
                    let w = &self.params[layer.weight.clone()];
                    gemm_a_bt(
                        rows,
                        layer.n_in,
                        layer.n_out,
                        &cur[..rows * layer.n_in],
                        w,
                        0.0,
                        &mut next[..rows * layer.n_out],
                    );
                    std::mem::swap(&mut cur, &mut next);
                }
                if l + 1 < n_layers {
                    let width = layer.n_out;
                    kernels::scale_rows(
                        &mut cur[..rows * width],
                        width,
                        n_in,
                        &ws.deriv[l][..batch * width],
                    );
                }
            }
            // cur holds rows (b, i) of length n_out: J[b][o][i] = cur[(b·n_in + i)·n_out + o].
            for (jb, cb) in ws.jac[..jac_len]
                .chunks_exact_mut(n_out * n_in)
                .zip(cur.chunks_exact(n_in * n_out))
            {
                for o in 0..n_out {
                    for i in 0..n_in {
                        jb[o * n_in + i] = cb[i * n_out + o];
                    }
                }
            }
        }
        ws.j0 = cur;
        ws.j1 = next;
        Ok(&ws.jac[..jac_len])
    }

    /// Evaluates a large batch on several threads: `x` is split into `workspaces.len()`
    /// contiguous row blocks, each evaluated by [`Mlp::forward`] with its own workspace on its own
    /// thread (the first on the calling thread), and the outputs written to `out`
    /// (`batch × n_out`). Every row goes through exactly the same arithmetic whatever the split,
    /// so the result is bitwise independent of the number of threads.
    pub fn forward_parallel(
        &self,
        x: &[f32],
        out: &mut [f32],
        workspaces: &mut [Workspace],
    ) -> Result<(), NnError> {
        let batch = self.batch_of(x)?;
        check_len("out", batch * self.n_out(), out.len())?;
        for ws in workspaces.iter() {
            self.check_workspace(ws)?;
        }
        let n_in = self.n_in();
        let n_out = self.n_out();
        crate::parallel::for_each_row_block(out, n_out, workspaces, |rows, out, ws| {
            let y = self.forward(&x[rows.start * n_in..rows.end * n_in], ws)?;
            out.copy_from_slice(y);
            Ok(())
        })
    }
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<(), NnError> {
    if expected != got {
        return Err(NnError::ShapeMismatch {
            what,
            expected,
            got,
        });
    }
    Ok(())
}

fn grow(v: &mut Vec<f32>, len: usize) {
    if v.len() < len {
        v.resize(len, 0.0);
    }
}

/// One layer's weights in a kernel layout (row length `n_pad`, a multiple of the register block).
#[derive(Debug, Clone, Default)]
struct PackedLayer {
    w: Vec<f32>,
    bias: Vec<f32>,
    n_pad: usize,
}

/// Buffers for evaluating and differentiating one [`Mlp`] architecture: the batch input, every
/// layer's output (and pre-activation where GELU needs it), and scratch for backward, JVP and
/// Jacobians. Buffers grow to the largest batch seen and are then reused, so a training or
/// control loop does not allocate after its first iteration.
#[derive(Debug, Clone)]
pub struct Workspace {
    sizes: Vec<usize>,
    activations: Vec<Activation>,
    batch: Option<usize>,
    capacity: usize,
    x: Vec<f32>,
    a: Vec<Vec<f32>>,
    z: Vec<Vec<f32>>,
    deriv: Vec<Vec<f32>>,
    g0: Vec<f32>,
    g1: Vec<f32>,
    j0: Vec<f32>,
    j1: Vec<f32>,
    jac: Vec<f32>,
}

impl Workspace {
    /// An empty workspace for `spec` (same as [`Mlp::workspace`]).
    pub fn new(spec: &MlpSpec) -> Self {
        let n_layers = spec.sizes.len() - 1;
        Self {
            sizes: spec.sizes.clone(),
            activations: spec.activations.clone(),
            batch: None,
            capacity: 0,
            x: Vec::new(),
            a: vec![Vec::new(); n_layers],
            z: vec![Vec::new(); n_layers],
            deriv: vec![Vec::new(); n_layers],
            g0: Vec::new(),
            g1: Vec::new(),
            j0: Vec::new(),
            j1: Vec::new(),
            jac: Vec::new(),
        }
    }

    /// Grows the buffers for batches up to `batch` rows (done automatically; calling it up front
    /// moves the allocation out of a timed loop).
    pub fn reserve(&mut self, batch: usize) {
        if batch <= self.capacity {
            return;
        }
        let n_layers = self.sizes.len() - 1;
        // `NR` floats of slack after the input and every layer output: `backward` reads their
        // rows over the padded width (the extra lanes are never stored).
        grow(&mut self.x, batch * self.sizes[0] + kernels::NR);
        for l in 0..n_layers {
            let width = self.sizes[l + 1];
            grow(&mut self.a[l], batch * width + kernels::NR);
            let hidden = l + 1 < n_layers;
            if hidden && self.activations[l].needs_preactivation() {
                grow(&mut self.z[l], batch * width);
            }
        }
        self.capacity = batch;
    }

    /// Batch size of the last forward pass, if one was recorded.
    pub fn batch(&self) -> Option<usize> {
        self.batch
    }

    /// Outputs of the last forward pass (`batch × n_out`), empty if there was none.
    pub fn output(&self) -> &[f32] {
        match self.batch {
            Some(b) => {
                let n_out = self.sizes[self.sizes.len() - 1];
                &self.a[self.a.len() - 1][..b * n_out]
            }
            None => &[],
        }
    }

    /// Outputs of hidden layer `l` in the last forward pass (`batch × h_l`), if any.
    pub fn hidden(&self, l: usize) -> Option<&[f32]> {
        let b = self.batch?;
        let width = *self.sizes.get(l + 1)?;
        Some(&self.a.get(l)?[..b * width])
    }
}
