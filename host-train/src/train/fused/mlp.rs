//! One MLP head: its parameters, gradient, forward pass and reverse pass.

use super::*;

/// One head's parameters (the burn layout: `w0[i][o]` is input i → hidden o).
#[derive(Clone, Debug)]
pub(super) struct Head<const O: usize> {
    pub(super) w0: [[f32; H]; 9],
    pub(super) b0: [f32; H],
    pub(super) w1: [[f32; H]; H],
    pub(super) b1: [f32; H],
    pub(super) w2: [[f32; O]; H],
    pub(super) b2: [f32; O],
}

impl<const O: usize> Head<O> {
    /// From six flattened tensors in [`crate::train::tensor_model::TMlp::tensors`] order.
    pub(super) fn from_flat(t: &[Vec<f32>]) -> Option<Self> {
        fn mat<const R: usize, const C: usize>(v: &[f32]) -> Option<[[f32; C]; R]> {
            (v.len() == R * C)
                .then(|| std::array::from_fn(|r| std::array::from_fn(|c| v[r * C + c])))
        }
        fn vec<const C: usize>(v: &[f32]) -> Option<[f32; C]> {
            (v.len() == C).then(|| std::array::from_fn(|c| v[c]))
        }
        Some(Self {
            w0: mat(t.first()?)?,
            b0: vec(t.get(1)?)?,
            w1: mat(t.get(2)?)?,
            b1: vec(t.get(3)?)?,
            w2: mat(t.get(4)?)?,
            b2: vec(t.get(5)?)?,
        })
    }
}

/// One head's gradient, lane by lane (summed over the lanes at the end).
#[derive(Clone, Debug)]
pub(super) struct HeadGrad<const O: usize> {
    pub(super) w0: [[V; H]; 9],
    pub(super) b0: [V; H],
    pub(super) w1: [[V; H]; H],
    pub(super) b1: [V; H],
    pub(super) w2: [[V; O]; H],
    pub(super) b2: [V; O],
}

impl<const O: usize> HeadGrad<O> {
    pub(super) fn zero() -> Self {
        Self {
            w0: [[V::ZERO; H]; 9],
            b0: [V::ZERO; H],
            w1: [[V::ZERO; H]; H],
            b1: [V::ZERO; H],
            w2: [[V::ZERO; O]; H],
            b2: [V::ZERO; O],
        }
    }

    /// The six flattened tensors (lanes summed).
    pub(super) fn flat(&self) -> [Vec<f32>; 6] {
        fn sum(v: &V) -> f32 {
            v.0.iter().sum()
        }
        [
            self.w0.iter().flatten().map(sum).collect(),
            self.b0.iter().map(sum).collect(),
            self.w1.iter().flatten().map(sum).collect(),
            self.b1.iter().map(sum).collect(),
            self.w2.iter().flatten().map(sum).collect(),
            self.b2.iter().map(sum).collect(),
        ]
    }
}

/// A head's hidden activations and output at one point.
#[derive(Clone, Copy, Debug)]
pub(super) struct Tr<const O: usize> {
    pub(super) h0: [V; H],
    pub(super) h1: [V; H],
    pub(super) y: [V; O],
}

impl<const O: usize> Tr<O> {
    pub(super) const ZERO: Self = Self {
        h0: [V::ZERO; H],
        h1: [V::ZERO; H],
        y: [V::ZERO; O],
    };
}

#[inline(always)]
pub(super) fn mlp_fwd<const O: usize>(w: &Head<O>, x: &[V; 9], t: &mut Tr<O>) {
    let mut z: [V; H] = vs(|o| V::splat(w.b0[o]));
    for (xi, row) in x.iter().zip(&w.w0) {
        for (z, wv) in z.iter_mut().zip(row) {
            *z += *xi * *wv;
        }
    }
    for (h, z) in t.h0.iter_mut().zip(&z) {
        *h = z.tanh();
    }
    let mut z: [V; H] = vs(|o| V::splat(w.b1[o]));
    for (hi, row) in t.h0.iter().zip(&w.w1) {
        for (z, wv) in z.iter_mut().zip(row) {
            *z += *hi * *wv;
        }
    }
    for (h, z) in t.h1.iter_mut().zip(&z) {
        *h = z.tanh();
    }
    let mut y: [V; O] = vs(|o| V::splat(w.b2[o]));
    for (hi, row) in t.h1.iter().zip(&w.w2) {
        for (y, wv) in y.iter_mut().zip(row) {
            *y += *hi * *wv;
        }
    }
    t.y = y;
}

/// The reverse of a dense layer y = xᵀ W (W `[R][C]`) for the weights and the input: with the
/// output adjoint `yb` [C], adds x_r yb_c to `gw[r][c]` and returns the input adjoint
/// xb_r = `xb0[r]` + Σ_c yb_c W[r][c] (`xb0`: what the input already carries).
#[inline(always)]
pub(super) fn dense_back<const R: usize, const C: usize>(
    w: &[[f32; C]; R],
    x: &[V; R],
    yb: &[V; C],
    xb0: &[V; R],
    gw: &mut [[V; C]; R],
) -> [V; R] {
    let mut xb = *xb0;
    for r in 0..R {
        let xr = x[r];
        let mut s = xb[r];
        for c in 0..C {
            gw[r][c] += xr * yb[c];
            s += yb[c] * w[r][c];
        }
        xb[r] = s;
    }
    xb
}

/// The reverse of the transposed layer d = W u (W `[R][C]`, u [C], as in a VJP) for the
/// weights and u: with the adjoint `db` [R] of d and `u` recorded, adds db_r u_c to
/// `gw[r][c]` and returns u's adjoint ub_c = Σ_r db_r W[r][c].
#[inline(always)]
pub(super) fn dense_t_back<const R: usize, const C: usize>(
    w: &[[f32; C]; R],
    u: &[V; C],
    db: &[V; R],
    gw: &mut [[V; C]; R],
) -> [V; C] {
    let mut ub = [V::ZERO; C];
    for r in 0..R {
        let dr = db[r];
        for c in 0..C {
            gw[r][c] += dr * u[c];
            ub[c] += dr * w[r][c];
        }
    }
    ub
}

/// The reverse of [`mlp_fwd`] with output adjoint `yb` and extra adjoints of the hidden
/// activations `h1x`, `h0x` (from the VJP's use of them); adds the input's adjoint to `xb`.
#[inline(always)]
pub(super) fn mlp_back<const O: usize>(
    w: &Head<O>,
    x: &[V; 9],
    t: &Tr<O>,
    yb: &[V; O],
    h1x: &[V; H],
    h0x: &[V; H],
    g: &mut HeadGrad<O>,
    xb: &mut [V; 9],
) {
    for (b, y) in g.b2.iter_mut().zip(yb) {
        *b += *y;
    }
    let h1b = dense_back(&w.w2, &t.h1, yb, h1x, &mut g.w2);
    let mut z1b = [V::ZERO; H];
    for j in 0..H {
        z1b[j] = h1b[j] * t.h1[j].one_minus_sq();
        g.b1[j] += z1b[j];
    }
    let h0b = dense_back(&w.w1, &t.h0, &z1b, h0x, &mut g.w1);
    let mut z0b = [V::ZERO; H];
    for i in 0..H {
        z0b[i] = h0b[i] * t.h0[i].one_minus_sq();
        g.b0[i] += z0b[i];
    }
    *xb = dense_back(&w.w0, x, &z0b, xb, &mut g.w0);
}
