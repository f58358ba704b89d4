//! Fixed-size f32 neural networks: dense layers and two-hidden-layer tanh MLPs with const-generic
//! sizes, their forward pass, Jacobian–vector product (JVP) and vector–Jacobian product (VJP).
//!
//! The model needs the input Jacobians for ∂H/∂q (a VJP through the J⁻¹ head, paper eq. 1) and for
//! d/dt M⁻¹(q) (a JVP along q̇, paper eq. 2). Everything here is allocation-free and panic-free:
//! loops run over zipped fixed-size arrays, so no index can fail.
//!
//! Weights are stored row-major by output (`weight[o][i]`), as PyTorch's and burn's `Linear`
//! store their transpose; the host exporter writes them in this layout.

use crate::fpu;
use serde::de::{Error as _, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The hidden-layer activation (a fitted rational tanh, [`fpu::tanh`]).
pub use crate::fpu::tanh;

/// Softplus log(1 + eˣ), computed without overflow; used for positive diagonals.
#[inline]
pub fn softplus(x: f32) -> f32 {
    if x > 20.0 {
        x
    } else {
        libm::log1pf(libm::expf(x))
    }
}

/// A dense (affine) layer y = W x + b with `I` inputs and `O` outputs.
///
/// `repr(C)`: its memory is the weights row by row then the biases, f32 each with no padding,
/// the order of [`Dense::params_mut`] (see [`crate::model::ModelWeights`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Dense<const I: usize, const O: usize> {
    /// `weight[o][i]`: the weight from input `i` to output `o`.
    pub weight: [[f32; I]; O],
    /// The bias of each output.
    pub bias: [f32; O],
}

impl<const I: usize, const O: usize> Default for Dense<I, O> {
    fn default() -> Self {
        Self::ZERO
    }
}

impl<const I: usize, const O: usize> Dense<I, O> {
    /// A layer with all weights and biases zero.
    pub const ZERO: Self = Self {
        weight: [[0.0; I]; O],
        bias: [0.0; O],
    };

    /// Number of parameters (weights and biases).
    pub const PARAMS: usize = I * O + O;

    /// y = W x + b, each output one chain of fused multiply–adds from its bias in input order
    /// ([`fpu::affine`]): bit-identical on the MCU and the host, one instruction per multiply–add on
    /// the M4F.
    #[inline]
    pub fn forward(&self, x: &[f32; I]) -> [f32; O] {
        fpu::affine(&self.weight, &self.bias, x)
    }

    /// [`Dense::forward`] written into `y` ([`fpu::affine_into`]).
    #[inline]
    pub fn forward_into(&self, x: &[f32; I], y: &mut [f32; O]) {
        fpu::affine_into(&self.weight, &self.bias, x, y)
    }

    /// tanh(W x + b) elementwise ([`fpu::affine_tanh`]): the same bits as [`Dense::forward`]
    /// followed by [`tanh`], in one kernel on the M4F.
    #[inline]
    pub fn forward_tanh(&self, x: &[f32; I]) -> [f32; O] {
        fpu::affine_tanh(&self.weight, &self.bias, x)
    }

    /// The linear part only, dy = W dx (the layer's Jacobian applied to a tangent).
    #[inline]
    pub fn linear(&self, dx: &[f32; I]) -> [f32; O] {
        let mut y = [0.0; O];
        for (yo, row) in y.iter_mut().zip(self.weight.iter()) {
            *yo = dot(row, dx);
        }
        y
    }

    /// The transposed linear part, dx = Wᵀ dy (the layer's VJP).
    #[inline]
    pub fn linear_transpose(&self, dy: &[f32; O]) -> [f32; I] {
        let mut dx = [0.0; I];
        for (row, &g) in self.weight.iter().zip(dy.iter()) {
            for (d, &w) in dx.iter_mut().zip(row.iter()) {
                *d += w * g;
            }
        }
        dx
    }

    /// True if every weight and bias is finite.
    pub fn is_finite(&self) -> bool {
        self.bias.iter().all(|v| v.is_finite())
            && self.weight.iter().flatten().all(|v| v.is_finite())
    }

    /// Every parameter in serialization order: the weights row by row (`weight[o][i]`), then
    /// the biases.
    pub fn params_mut(&mut self) -> impl Iterator<Item = &mut f32> {
        self.weight.iter_mut().flatten().chain(self.bias.iter_mut())
    }
}

#[inline]
fn dot<const N: usize>(a: &[f32; N], b: &[f32; N]) -> f32 {
    a.iter().zip(b.iter()).fold(0.0, |acc, (x, y)| acc + x * y)
}

#[inline]
fn map<const N: usize>(x: [f32; N], f: impl Fn(f32) -> f32) -> [f32; N] {
    let mut y = x;
    for v in y.iter_mut() {
        *v = f(*v);
    }
    y
}

#[inline]
fn hadamard<const N: usize>(a: &[f32; N], b: &[f32; N]) -> [f32; N] {
    let mut y = *a;
    for (v, w) in y.iter_mut().zip(b.iter()) {
        *v *= w;
    }
    y
}

/// tanh′ expressed through the activation value t = tanh(z): 1 − t².
#[inline]
fn tanh_slope<const N: usize>(t: &[f32; N]) -> [f32; N] {
    map(*t, |v| 1.0 - v * v)
}

/// The two hidden layers, tanh(l1(tanh(l0(x)))): one function for every output width, so the
/// model's three heads share one copy of the M4F kernels (about 1.2 KB of flash) for a call each.
#[inline(never)]
fn hidden<const I: usize, const H: usize>(
    l0: &Dense<I, H>,
    l1: &Dense<H, H>,
    x: &[f32; I],
) -> [f32; H] {
    l1.forward_tanh(&l0.forward_tanh(x))
}

/// A multilayer perceptron `I → H → H → O`: two tanh hidden layers of width `H`, linear output.
///
/// `repr(C)`: its memory is its layers in order, the order of [`Mlp::params_mut`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[repr(C)]
pub struct Mlp<const I: usize, const H: usize, const O: usize> {
    /// Input layer.
    pub l0: Dense<I, H>,
    /// Second hidden layer.
    pub l1: Dense<H, H>,
    /// Linear output layer.
    pub l2: Dense<H, O>,
}

impl<const I: usize, const H: usize, const O: usize> Mlp<I, H, O> {
    /// An all-zero network (its output is zero everywhere).
    pub const ZERO: Self = Self {
        l0: Dense::ZERO,
        l1: Dense::ZERO,
        l2: Dense::ZERO,
    };

    /// The network's shape `[inputs, hidden, outputs]`, as stored in the weight blob's header.
    pub const DIMS: [u16; 3] = [I as u16, H as u16, O as u16];

    /// Number of parameters.
    pub const PARAMS: usize = Dense::<I, H>::PARAMS + Dense::<H, H>::PARAMS + Dense::<H, O>::PARAMS;

    /// Multiply–adds of one forward pass.
    pub const MACS: usize = I * H + H * H + H * O;

    /// y = l2(tanh(l1(tanh(l0(x))))).
    #[inline]
    pub fn forward(&self, x: &[f32; I]) -> [f32; O] {
        self.l2.forward(&hidden(&self.l0, &self.l1, x))
    }

    /// [`Mlp::forward`] written into `y`.
    #[inline]
    pub fn forward_into(&self, x: &[f32; I], y: &mut [f32; O]) {
        self.l2.forward_into(&hidden(&self.l0, &self.l1, x), y)
    }

    /// Forward pass and Jacobian–vector product: returns `(y, J dx)` with J = ∂y/∂x at `x`.
    pub fn jvp(&self, x: &[f32; I], dx: &[f32; I]) -> ([f32; O], [f32; O]) {
        let h0 = self.l0.forward_tanh(x);
        let d0 = hadamard(&tanh_slope(&h0), &self.l0.linear(dx));
        let h1 = self.l1.forward_tanh(&h0);
        let d1 = hadamard(&tanh_slope(&h1), &self.l1.linear(&d0));
        (self.l2.forward(&h1), self.l2.linear(&d1))
    }

    /// Forward pass and vector–Jacobian product: returns `(y, Jᵀ dy)`, the gradient of `dy · y`
    /// with respect to the input.
    pub fn vjp(&self, x: &[f32; I], dy: &[f32; O]) -> ([f32; O], [f32; I]) {
        let h0 = self.l0.forward_tanh(x);
        let h1 = self.l1.forward_tanh(&h0);
        let y = self.l2.forward(&h1);
        let g1 = hadamard(&tanh_slope(&h1), &self.l2.linear_transpose(dy));
        let g0 = hadamard(&tanh_slope(&h0), &self.l1.linear_transpose(&g1));
        (y, self.l0.linear_transpose(&g0))
    }

    /// True if every parameter is finite.
    pub fn is_finite(&self) -> bool {
        self.l0.is_finite() && self.l1.is_finite() && self.l2.is_finite()
    }

    /// Every parameter in serialization order: layer by layer, each as [`Dense::params_mut`].
    pub fn params_mut(&mut self) -> impl Iterator<Item = &mut f32> {
        self.l0
            .params_mut()
            .chain(self.l1.params_mut())
            .chain(self.l2.params_mut())
    }
}

// ---- serde: a layer is a flat tuple of I·O weights (row-major) then O biases, f32 each. ----
// Arrays longer than 32 have no derived serde impls, and a tuple has no length prefix in
// postcard, so this is also the most compact encoding.

impl<const I: usize, const O: usize> Serialize for Dense<I, O> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(Self::PARAMS)?;
        for v in self.weight.iter().flatten() {
            t.serialize_element(v)?;
        }
        for v in self.bias.iter() {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

struct DenseVisitor<const I: usize, const O: usize>;

impl<'de, const I: usize, const O: usize> Visitor<'de> for DenseVisitor<I, O> {
    type Value = Dense<I, O>;

    fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
        write!(
            f,
            "{} f32 values of a {}x{} dense layer",
            Dense::<I, O>::PARAMS,
            O,
            I
        )
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut layer = Dense::<I, O>::ZERO;
        let slots = layer
            .weight
            .iter_mut()
            .flatten()
            .chain(layer.bias.iter_mut());
        for (n, slot) in slots.enumerate() {
            *slot = seq
                .next_element()?
                .ok_or_else(|| A::Error::invalid_length(n, &self))?;
        }
        Ok(layer)
    }
}

impl<'de, const I: usize, const O: usize> Deserialize<'de> for Dense<I, O> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_tuple(Self::PARAMS, DenseVisitor::<I, O>)
    }
}

impl<const I: usize, const H: usize, const O: usize> Serialize for Mlp<I, H, O> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        (&self.l0, &self.l1, &self.l2).serialize(s)
    }
}

impl<'de, const I: usize, const H: usize, const O: usize> Deserialize<'de> for Mlp<I, H, O> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let (l0, l1, l2) = <(Dense<I, H>, Dense<H, H>, Dense<H, O>)>::deserialize(d)?;
        Ok(Self { l0, l1, l2 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 → 2 → 2 → 1 network small enough to evaluate by hand.
    fn tiny() -> Mlp<2, 2, 1> {
        Mlp {
            l0: Dense {
                weight: [[1.0, 0.0], [0.5, -1.0]],
                bias: [0.0, 0.25],
            },
            l1: Dense {
                weight: [[1.0, 1.0], [0.0, 2.0]],
                bias: [0.0, -0.5],
            },
            l2: Dense {
                weight: [[2.0, -1.0]],
                bias: [0.1],
            },
        }
    }

    #[test]
    fn forward_matches_hand_computation() {
        let x = [0.5f32, 1.0];
        // h0 = tanh([0.5, 0.25 + 0.25 - 1.0]) = tanh([0.5, -0.5])
        let a = libm::tanhf(0.5);
        let h0 = [a, -a];
        // h1 = tanh([h0₀ + h0₁, 2 h0₁ - 0.5]) = tanh([0, -2a - 0.5])
        let h1 = [0.0f32, libm::tanhf(-2.0 * a - 0.5)];
        let expected = 2.0 * h1[0] - h1[1] + 0.1;
        let y = tiny().forward(&x);
        assert!((y[0] - expected).abs() < 1e-6, "{} vs {}", y[0], expected);
        let _ = h0;
    }
}
