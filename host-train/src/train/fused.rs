//! The training loss and its exact gradient as one hand-fused CPU kernel in plain f32, without
//! burn: [`super::model`]'s equations (paper eq. 1 and 2 in (q, 𝔭), RK4, the TSE(3) loss of
//! [`super::model::window_loss`]) for a minibatch of windows, with the reverse pass (adjoints)
//! written out, the second-order term through the J⁻¹ head's VJP (∂H/∂R) included.
//!
//! Eight windows run in lockstep, one per lane of [`V`] (an `[f32; 8]` whose element-wise ops
//! LLVM vectorizes), and the windows are split over the cores with `std::thread::scope`. The
//! burn path ([`super::r#loop::batch_loss`] under autodiff) stays the reference it is tested
//! against (`host-train/tests/train_parity.rs`).
//!
//! Layout of the parameters: the 18 MLP tensors in [`super::model::TModel::tensors`] order
//! (weights `[in, out]`, biases `[1, out]`, flattened row-major), then the per-flight tensor
//! `[M, p]` or `[M, p + 4]` (the a_j, then the rotor gain deviations δηⱼ).

// The kernel indexes small fixed-size arrays the way the equations do (i, j, k), and the
// reverse passes take every array they update.
#![allow(clippy::needless_range_loop, clippy::too_many_arguments)]

use super::data::Windows;
use hamflight::model::learned::{
    rot_input, CONTROL_SCALE, INERTIA_INV_EPS, INERTIA_INV_SCALE_PER_KG_M2, TORQUE_SCALE_NM,
    WRENCH_SCALE,
};
use hamflight::model::{FEATURES, GRAVITY_M_S2, HIDDEN};
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// Windows per lane group.
const LANES: usize = 8;
const H: usize = HIDDEN;
const P: usize = FEATURES;
const OI: usize = 6;
const OG: usize = 24;
const OD: usize = 6 * P;
/// Rotor gains per flight.
const NR: usize = 4;
/// l index k → row-major position in L (the lower triangle).
const L_POS: [usize; 6] = [0, 3, 4, 6, 7, 8];

/// One value per window of a lane group.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(32))]
struct V([f32; LANES]);

impl V {
    const ZERO: V = V([0.0; LANES]);

    #[inline(always)]
    fn splat(x: f32) -> V {
        V([x; LANES])
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> V {
        let mut o = [0.0; LANES];
        for (o, x) in o.iter_mut().zip(self.0) {
            *o = f(x);
        }
        V(o)
    }

    #[inline(always)]
    fn tanh(self) -> V {
        self.map(tanh_f32)
    }

    /// 1 − x².
    #[inline(always)]
    fn one_minus_sq(self) -> V {
        V::splat(1.0) - self * self
    }
}

macro_rules! lane_op {
    ($tr:ident, $f:ident, $op:tt, $tra:ident, $fa:ident) => {
        impl $tr for V {
            type Output = V;
            #[inline(always)]
            fn $f(self, r: V) -> V {
                let mut o = [0.0; LANES];
                for k in 0..LANES {
                    o[k] = self.0[k] $op r.0[k];
                }
                V(o)
            }
        }
        impl $tr<f32> for V {
            type Output = V;
            #[inline(always)]
            fn $f(self, r: f32) -> V {
                let mut o = [0.0; LANES];
                for k in 0..LANES {
                    o[k] = self.0[k] $op r;
                }
                V(o)
            }
        }
        impl $tra for V {
            #[inline(always)]
            fn $fa(&mut self, r: V) {
                *self = *self $op r;
            }
        }
    };
}
lane_op!(Add, add, +, AddAssign, add_assign);
lane_op!(Sub, sub, -, SubAssign, sub_assign);
lane_op!(Mul, mul, *, MulAssign, mul_assign);
lane_op!(Div, div, /, DivAssign, div_assign);

impl Neg for V {
    type Output = V;
    #[inline(always)]
    fn neg(self) -> V {
        self.map(|x| -x)
    }
}

/// tanh in f32 by a branch-free rational approximation (odd degree-13 over even degree-6
/// polynomial on [−7.9, 7.9], ±1 outside), so that the lanes vectorize; within a few ulp of
/// `f32::tanh` (tested).
#[inline(always)]
fn tanh_f32(a: f32) -> f32 {
    let x = a.clamp(-7.905_311, 7.905_311);
    let x2 = x * x;
    let p = (((((-2.760_768_5e-16 * x2 + 2.000_188e-13) * x2 - 8.604_672e-11) * x2
        + 5.122_297e-8)
        * x2
        + 1.485_722_4e-5)
        * x2
        + 6.372_619_3e-4)
        * x2
        + 4.893_524_6e-3;
    let q = ((1.198_258_4e-6 * x2 + 1.185_347_1e-4) * x2 + 2.268_434_6e-3) * x2 + 4.893_525e-3;
    let t = x * p / q;
    if a.abs() < 4e-4 {
        a
    } else {
        t
    }
}

/// `[f(0), …, f(N − 1)]`, always inlined: std's `array::from_fn` and `map` may be left as calls,
/// and a called function is compiled without the kernel's target features (measured: 9 % of
/// an epoch at batch 128 went to such a call).
#[inline(always)]
fn vs<const N: usize>(f: impl Fn(usize) -> V) -> [V; N] {
    let mut o = [V::ZERO; N];
    for (i, o) in o.iter_mut().enumerate() {
        *o = f(i);
    }
    o
}

/// c = a × b.
#[inline(always)]
fn cross(a: &[V; 3], b: &[V; 3]) -> [V; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
fn add3(acc: &mut [V], d: &[V; 3]) {
    for (a, d) in acc.iter_mut().zip(d) {
        *a += *d;
    }
}

/// One head's parameters (the burn layout: `w0[i][o]` is input i → hidden o).
#[derive(Clone, Debug)]
struct Head<const O: usize> {
    w0: [[f32; H]; 9],
    b0: [f32; H],
    w1: [[f32; H]; H],
    b1: [f32; H],
    w2: [[f32; O]; H],
    b2: [f32; O],
}

impl<const O: usize> Head<O> {
    /// From six flattened tensors in [`super::model::TMlp::tensors`] order.
    fn from_flat(t: &[Vec<f32>]) -> Option<Self> {
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
struct HeadGrad<const O: usize> {
    w0: [[V; H]; 9],
    b0: [V; H],
    w1: [[V; H]; H],
    b1: [V; H],
    w2: [[V; O]; H],
    b2: [V; O],
}

impl<const O: usize> HeadGrad<O> {
    fn zero() -> Self {
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
    fn flat(&self) -> [Vec<f32>; 6] {
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
struct Tr<const O: usize> {
    h0: [V; H],
    h1: [V; H],
    y: [V; O],
}

impl<const O: usize> Tr<O> {
    const ZERO: Self = Self {
        h0: [V::ZERO; H],
        h1: [V::ZERO; H],
        y: [V::ZERO; O],
    };
}

#[inline(always)]
fn mlp_fwd<const O: usize>(w: &Head<O>, x: &[V; 9], t: &mut Tr<O>) {
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
fn dense_back<const R: usize, const C: usize>(
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
fn dense_t_back<const R: usize, const C: usize>(
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
fn mlp_back<const O: usize>(
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

/// Constants of the equations.
#[derive(Clone, Debug)]
struct K {
    mass_kg: f32,
    dt_s: f32,
    vel_weight: f32,
    /// Row form of A⁻¹ S: rotors[j] = Σᵢ u_norm[i] rfu[i][j].
    rfu: [[f32; NR]; NR],
    /// Row form of S⁻¹ A: u_norm[c] = Σⱼ rotors[j] ufr[j][c].
    ufr: [[f32; NR]; NR],
    cinv: [f32; 4],
}

impl K {
    fn new(mass_kg: f32, dt_s: f32, vel_weight: f32) -> Self {
        let (rfu, ufr) = super::export::normalized_rotor_maps();
        Self {
            mass_kg,
            dt_s,
            vel_weight,
            rfu,
            ufr,
            cinv: CONTROL_SCALE.map(|c| 1.0 / c),
        }
    }
}

/// The three heads' parameters.
struct Nets {
    i: Head<OI>,
    g: Head<OG>,
    d: Head<OD>,
}

/// The three heads' gradients.
struct Grads {
    i: HeadGrad<OI>,
    g: HeadGrad<OG>,
    d: HeadGrad<OD>,
    /// Per-flight gradient, flattened `[M, width]`.
    per_flight: Vec<f32>,
    loss: f64,
}

/// The heads at one rotation (one point of the window's integration).
#[derive(Clone, Copy, Debug)]
struct Point {
    /// q's rows (R row-major).
    x: [V; 9],
    ti: Tr<OI>,
    tg: Tr<OG>,
    td: Tr<OD>,
    /// L, row-major.
    l: [V; 9],
    /// J⁻¹, row-major.
    j: [V; 9],
}

impl Point {
    const ZERO: Self = Self {
        x: [V::ZERO; 9],
        ti: Tr::ZERO,
        tg: Tr::ZERO,
        td: Tr::ZERO,
        l: [V::ZERO; 9],
        j: [V::ZERO; 9],
    };
}

#[inline(always)]
fn eval_point(n: &Nets, x: &[V; 9], pt: &mut Point) {
    pt.x = *x;
    mlp_fwd(&n.i, x, &mut pt.ti);
    mlp_fwd(&n.g, x, &mut pt.tg);
    mlp_fwd(&n.d, x, &mut pt.td);
    let mut l = [V::ZERO; 9];
    for (k, &pos) in L_POS.iter().enumerate() {
        l[pos] = pt.ti.y[k];
    }
    pt.l = l;
    for i in 0..3 {
        for j in 0..3 {
            let mut s = l[i * 3] * l[j * 3];
            s += l[i * 3 + 1] * l[j * 3 + 1];
            s += l[i * 3 + 2] * l[j * 3 + 2];
            if i == j {
                s += V::splat(INERTIA_INV_EPS);
            }
            pt.j[i * 3 + j] = s * INERTIA_INV_SCALE_PER_KG_M2;
        }
    }
}

/// The adjoints gathered at a point for its heads.
#[derive(Clone, Copy, Debug)]
struct PointAdj {
    /// ∂ℓ/∂J⁻¹ and ∂ℓ/∂L (direct uses), row-major.
    j: [V; 9],
    l: [V; 9],
    yg: [V; OG],
    yd: [V; OD],
    /// The J⁻¹ head's hidden activations' adjoints from the VJP.
    h0x: [V; H],
    h1x: [V; H],
}

impl PointAdj {
    const ZERO: Self = Self {
        j: [V::ZERO; 9],
        l: [V::ZERO; 9],
        yg: [V::ZERO; OG],
        yd: [V::ZERO; OD],
        h0x: [V::ZERO; H],
        h1x: [V::ZERO; H],
    };
}

/// Backpropagates a point's gathered adjoints through its heads; returns ∂ℓ/∂q (q's rows).
#[inline(always)]
fn point_back(n: &Nets, pt: &Point, a: &PointAdj, g: &mut Grads) -> [V; 9] {
    // J⁻¹ = s (L Lᵀ + ε I): L̄ += s (J̄ + J̄ᵀ) L.
    let mut lb = a.l;
    for i in 0..3 {
        for k in 0..3 {
            let mut s = V::ZERO;
            for j in 0..3 {
                s += (a.j[i * 3 + j] + a.j[j * 3 + i]) * pt.l[j * 3 + k];
            }
            lb[i * 3 + k] += s * INERTIA_INV_SCALE_PER_KG_M2;
        }
    }
    let yib: [V; OI] = vs(|k| lb[L_POS[k]]);
    let zero = [V::ZERO; H];
    let mut xb = [V::ZERO; 9];
    mlp_back(&n.i, &pt.x, &pt.ti, &yib, &a.h1x, &a.h0x, &mut g.i, &mut xb);
    mlp_back(&n.g, &pt.x, &pt.tg, &a.yg, &zero, &zero, &mut g.g, &mut xb);
    mlp_back(&n.d, &pt.x, &pt.td, &a.yd, &zero, &zero, &mut g.d, &mut xb);
    xb
}

/// The integrated state (q, 𝔭), or its derivative, or an adjoint of either.
#[derive(Clone, Copy, Debug)]
struct St {
    p: [V; 3],
    r: [V; 9],
    pv: [V; 3],
    pw: [V; 3],
}

impl St {
    const ZERO: Self = Self {
        p: [V::ZERO; 3],
        r: [V::ZERO; 9],
        pv: [V::ZERO; 3],
        pw: [V::ZERO; 3],
    };

    /// self + h d.
    #[inline(always)]
    fn axpy(&self, h: f32, d: &St) -> St {
        let mut o = *self;
        o.add_scaled(h, d);
        o
    }

    #[inline(always)]
    fn add_scaled(&mut self, h: f32, d: &St) {
        for (a, b) in self.p.iter_mut().zip(&d.p) {
            *a += *b * h;
        }
        for (a, b) in self.r.iter_mut().zip(&d.r) {
            *a += *b * h;
        }
        for (a, b) in self.pv.iter_mut().zip(&d.pv) {
            *a += *b * h;
        }
        for (a, b) in self.pw.iter_mut().zip(&d.pw) {
            *a += *b * h;
        }
    }
}

/// What the reverse pass of one right-hand side needs.
#[derive(Clone, Copy, Debug)]
struct Rhs {
    pv: [V; 3],
    pw: [V; 3],
    w: [V; 3],
    v: [V; 3],
    oa: [V; 6],
    z: [V; 3],
    dy: [V; 6],
    a1: [V; H],
    g1: [V; H],
    a0: [V; H],
    g0: [V; H],
    d: [V; 9],
}

impl Rhs {
    const ZERO: Self = Self {
        pv: [V::ZERO; 3],
        pw: [V::ZERO; 3],
        w: [V::ZERO; 3],
        v: [V::ZERO; 3],
        oa: [V::ZERO; 6],
        z: [V::ZERO; 3],
        dy: [V::ZERO; 6],
        a1: [V::ZERO; H],
        g1: [V::ZERO; H],
        a0: [V::ZERO; H],
        g0: [V::ZERO; H],
        d: [V::ZERO; 9],
    };
}

/// Paper eq. 1 in (q, 𝔭) at the point `pt` (q) with momenta `pv`, `pw`:
/// [`super::model::phase_rhs_with`].
#[inline(always)]
fn rhs(
    k: &K,
    n: &Nets,
    pt: &Point,
    pv: &[V; 3],
    pw: &[V; 3],
    un: &[V; 4],
    a: &[V; P],
    rec: &mut Rhs,
) -> St {
    let m = k.mass_kg;
    let r = &pt.x;
    let jm = &pt.j;
    let w: [V; 3] = vs(|i| jm[i * 3] * pw[0] + jm[i * 3 + 1] * pw[1] + jm[i * 3 + 2] * pw[2]);
    let v: [V; 3] = vs(|i| pv[i] / m);
    let gy = &pt.tg.y;
    let gu: [V; 6] = vs(|row| {
        let mut s = V::ZERO;
        for c in 0..4 {
            s += gy[row * 4 + c] * un[c];
        }
        s * WRENCH_SCALE[row]
    });
    let feat = &pt.td.y;
    let oa: [V; 6] = vs(|row| {
        let mut s = V::ZERO;
        for c in 0..P {
            s += feat[row * P + c] * a[c];
        }
        s
    });
    let fd: [V; 3] = vs(|j| (r[j] * oa[0] + r[3 + j] * oa[1] + r[6 + j] * oa[2]) * m);
    let mut pv_dot = cross(pv, &w);
    for i in 0..3 {
        pv_dot[i] = pv_dot[i] - r[6 + i] * (m * GRAVITY_M_S2) + gu[i] + fd[i];
    }
    // ∂H/∂q: a VJP of the J⁻¹ head with ∂H/∂l = s 𝔭ᵢ (Lᵀ𝔭)ⱼ at l's positions.
    let l = &pt.l;
    let z: [V; 3] = vs(|j| l[j] * pw[0] + l[3 + j] * pw[1] + l[6 + j] * pw[2]);
    let dy: [V; 6] = vs(|kk| {
        let pos = L_POS[kk];
        pw[pos / 3] * z[pos % 3] * INERTIA_INV_SCALE_PER_KG_M2
    });
    let hi = &n.i;
    let mut a1 = [V::ZERO; H];
    let mut g1 = [V::ZERO; H];
    for j in 0..H {
        let mut s = V::ZERO;
        for kk in 0..OI {
            s += dy[kk] * hi.w2[j][kk];
        }
        a1[j] = s;
        g1[j] = pt.ti.h1[j].one_minus_sq() * s;
    }
    let mut a0 = [V::ZERO; H];
    let mut g0 = [V::ZERO; H];
    for i in 0..H {
        let mut s = V::ZERO;
        for j in 0..H {
            s += g1[j] * hi.w1[i][j];
        }
        a0[i] = s;
        g0[i] = pt.ti.h0[i].one_minus_sq() * s;
    }
    let mut d = [V::ZERO; 9];
    for mm in 0..9 {
        let mut s = V::ZERO;
        for i in 0..H {
            s += g0[i] * hi.w0[mm][i];
        }
        d[mm] = s;
    }
    let mut pw_dot = cross(pw, &w);
    for i in 0..3 {
        let ri = [r[i * 3], r[i * 3 + 1], r[i * 3 + 2]];
        let di = [d[i * 3], d[i * 3 + 1], d[i * 3 + 2]];
        add3(&mut pw_dot, &cross(&ri, &di));
    }
    for i in 0..3 {
        pw_dot[i] = pw_dot[i] + gu[3 + i] + oa[3 + i] * TORQUE_SCALE_NM;
    }
    let p_dot: [V; 3] = vs(|i| r[i * 3] * v[0] + r[i * 3 + 1] * v[1] + r[i * 3 + 2] * v[2]);
    // Ṙ = R ω̂, ω̂ = [[0, −w₂, w₁], [w₂, 0, −w₀], [−w₁, w₀, 0]].
    let mut r_dot = [V::ZERO; 9];
    for i in 0..3 {
        let (x, y, z) = (r[i * 3], r[i * 3 + 1], r[i * 3 + 2]);
        r_dot[i * 3] = y * w[2] - z * w[1];
        r_dot[i * 3 + 1] = z * w[0] - x * w[2];
        r_dot[i * 3 + 2] = x * w[1] - y * w[0];
    }
    *rec = Rhs {
        pv: *pv,
        pw: *pw,
        w,
        v,
        oa,
        z,
        dy,
        a1,
        g1,
        a0,
        g0,
        d,
    };
    St {
        p: p_dot,
        r: r_dot,
        pv: pv_dot,
        pw: pw_dot,
    }
}

/// The reverse of [`rhs`]: the derivative's adjoint `kb` → the state's adjoint (q's explicit
/// uses, 𝔭_v, 𝔭_ω; the heads' share gathered in `pa`), the command's adjoint into `unb`, a's
/// into `ab`, and the VJP's weight gradients into `gi`.
#[inline(always)]
fn rhs_back(
    k: &K,
    n: &Nets,
    pt: &Point,
    rec: &Rhs,
    un: &[V; 4],
    a: &[V; P],
    kb: &St,
    pa: &mut PointAdj,
    unb: &mut [V; 4],
    ab: &mut [V; P],
    gi: &mut HeadGrad<OI>,
) -> St {
    let m = k.mass_kg;
    let r = &pt.x;
    let w = &rec.w;
    let mut rb = [V::ZERO; 9];
    let mut pvb = [V::ZERO; 3];
    let mut pwb = [V::ZERO; 3];
    let mut wb = [V::ZERO; 3];
    let mut vb = [V::ZERO; 3];
    // ṗ = R v.
    for i in 0..3 {
        for j in 0..3 {
            rb[i * 3 + j] += kb.p[i] * rec.v[j];
            vb[j] += r[i * 3 + j] * kb.p[i];
        }
    }
    // Ṙ = R ω̂: R̄ += Ṙ̄ ω̂ᵀ, ω̂̄ = Rᵀ Ṙ̄.
    let rdb = &kb.r;
    for i in 0..3 {
        let (b0, b1, b2) = (rdb[i * 3], rdb[i * 3 + 1], rdb[i * 3 + 2]);
        // Rows of ω̂: [0, −w₂, w₁], [w₂, 0, −w₀], [−w₁, w₀, 0].
        rb[i * 3] += b2 * w[1] - b1 * w[2];
        rb[i * 3 + 1] += b0 * w[2] - b2 * w[0];
        rb[i * 3 + 2] += b1 * w[0] - b0 * w[1];
    }
    let mut whb = [V::ZERO; 9];
    for kk in 0..3 {
        for j in 0..3 {
            whb[kk * 3 + j] = r[kk] * rdb[j] + r[3 + kk] * rdb[3 + j] + r[6 + kk] * rdb[6 + j];
        }
    }
    wb[0] += whb[7] - whb[5];
    wb[1] += whb[2] - whb[6];
    wb[2] += whb[3] - whb[1];
    // 𝔭̇_v = 𝔭_v × ω − m g r₃ + f_u + f_d.
    let vbar = &kb.pv;
    add3(&mut pvb, &cross(w, vbar));
    add3(&mut wb, &cross(vbar, &rec.pv));
    for i in 0..3 {
        rb[6 + i] -= vbar[i] * (m * GRAVITY_M_S2);
    }
    // 𝔭̇_ω = 𝔭_ω × ω + Σᵢ rᵢ × dᵢ + τ_u + τ_d.
    let obar = &kb.pw;
    add3(&mut pwb, &cross(w, obar));
    add3(&mut wb, &cross(obar, &rec.pw));
    let mut db = [V::ZERO; 9];
    for i in 0..3 {
        let ri = [r[i * 3], r[i * 3 + 1], r[i * 3 + 2]];
        let di = [rec.d[i * 3], rec.d[i * 3 + 1], rec.d[i * 3 + 2]];
        add3(&mut rb[i * 3..i * 3 + 3], &cross(&di, obar));
        let c = cross(obar, &ri);
        db[i * 3..i * 3 + 3].copy_from_slice(&c);
    }
    // g u.
    let gub: [V; 6] = [vbar[0], vbar[1], vbar[2], obar[0], obar[1], obar[2]];
    let gy = &pt.tg.y;
    for row in 0..6 {
        let s = gub[row] * WRENCH_SCALE[row];
        for c in 0..4 {
            pa.yg[row * 4 + c] += s * un[c];
            unb[c] += gy[row * 4 + c] * s;
        }
    }
    // f_d = m Rᵀ n, τ_d = TORQUE_SCALE t, [n; t] = O a.
    let mut oab = [V::ZERO; 6];
    for i in 0..3 {
        let mut s = V::ZERO;
        for j in 0..3 {
            rb[i * 3 + j] += rec.oa[i] * vbar[j] * m;
            s += r[i * 3 + j] * vbar[j];
        }
        oab[i] = s * m;
        oab[3 + i] = obar[i] * TORQUE_SCALE_NM;
    }
    let o = &pt.td.y;
    for row in 0..6 {
        for c in 0..P {
            pa.yd[row * P + c] += oab[row] * a[c];
            ab[c] += o[row * P + c] * oab[row];
        }
    }
    // The VJP d = W₀ᵀ (s₀ ⊙ W₁ᵀ (s₁ ⊙ W₂ᵀ dy)), second order through s = 1 − h².
    let hi = &n.i;
    let g0b = dense_t_back(&hi.w0, &rec.g0, &db, &mut gi.w0);
    let mut a0b = [V::ZERO; H];
    for i in 0..H {
        let h = pt.ti.h0[i];
        a0b[i] = g0b[i] * h.one_minus_sq();
        pa.h0x[i] -= g0b[i] * rec.a0[i] * h * 2.0;
    }
    let g1b = dense_t_back(&hi.w1, &rec.g1, &a0b, &mut gi.w1);
    let mut a1b = [V::ZERO; H];
    for j in 0..H {
        let h = pt.ti.h1[j];
        a1b[j] = g1b[j] * h.one_minus_sq();
        pa.h1x[j] -= g1b[j] * rec.a1[j] * h * 2.0;
    }
    let dyb = dense_t_back(&hi.w2, &rec.dy, &a1b, &mut gi.w2);
    // dy = s 𝔭ᵢ zⱼ, z = Lᵀ 𝔭_ω.
    let pw = &rec.pw;
    let mut zb = [V::ZERO; 3];
    for (kk, &pos) in L_POS.iter().enumerate() {
        let (i, j) = (pos / 3, pos % 3);
        let s = dyb[kk] * INERTIA_INV_SCALE_PER_KG_M2;
        pwb[i] += s * rec.z[j];
        zb[j] += s * pw[i];
    }
    for i in 0..3 {
        for j in 0..3 {
            pa.l[i * 3 + j] += pw[i] * zb[j];
            pwb[i] += pt.l[i * 3 + j] * zb[j];
        }
    }
    // v = 𝔭_v / m, ω = J⁻¹ 𝔭_ω.
    for i in 0..3 {
        pvb[i] += vb[i] / m;
    }
    for i in 0..3 {
        for j in 0..3 {
            pa.j[i * 3 + j] += wb[i] * pw[j];
            pwb[j] += pt.j[i * 3 + j] * wb[i];
        }
    }
    St {
        p: [V::ZERO; 3],
        r: rb,
        pv: pvb,
        pw: pwb,
    }
}

/// One lane group's data: states x₀..x_N, commands, flight rows, lane weights.
struct Group {
    p: Vec<[V; 3]>,
    r: Vec<[V; 9]>,
    v: Vec<[V; 3]>,
    w: Vec<[V; 3]>,
    u: Vec<[V; 4]>,
    flight: [usize; LANES],
    /// 1/B for a window of the batch, 0 for a padding lane.
    weight: V,
}

impl Group {
    fn load(data: &Windows, ids: &[usize], batch: usize) -> Self {
        let len = data.window_len;
        let id = |l: usize| ids[l.min(ids.len() - 1)];
        let lane3 = |f: &dyn Fn(usize) -> [f32; 3]| -> [V; 3] {
            let mut o = [V::ZERO; 3];
            for l in 0..LANES {
                let x = f(id(l));
                for c in 0..3 {
                    o[c].0[l] = x[c];
                }
            }
            o
        };
        let mut g = Group {
            p: Vec::with_capacity(len),
            r: Vec::with_capacity(len),
            v: Vec::with_capacity(len),
            w: Vec::with_capacity(len),
            u: Vec::with_capacity(len),
            flight: std::array::from_fn(|l| data.windows[id(l)].realization),
            weight: V(std::array::from_fn(|l| {
                if l < ids.len() {
                    1.0 / batch as f32
                } else {
                    0.0
                }
            })),
        };
        for s in 0..len {
            let st = |i: usize| &data.windows[i].states[s];
            g.p.push(lane3(&|i| st(i).p_m.into()));
            g.v.push(lane3(&|i| st(i).v_body_m_s.into()));
            g.w.push(lane3(&|i| st(i).w_body_rad_s.into()));
            let mut r = [V::ZERO; 9];
            for l in 0..LANES {
                let x = rot_input(&st(id(l)).rot);
                for c in 0..9 {
                    r[c].0[l] = x[c];
                }
            }
            g.r.push(r);
        }
        for s in 0..len.saturating_sub(1) {
            let mut u = [V::ZERO; 4];
            for l in 0..LANES {
                let x = data.windows[id(l)].u[s];
                for c in 0..4 {
                    u[c].0[l] = x[c];
                }
            }
            g.u.push(u);
        }
        g
    }
}

/// Scratch space of one lane group's pass, reused.
struct Scratch {
    pts: Vec<Point>,
    recs: Vec<Rhs>,
    adj: Vec<PointAdj>,
    /// x₀..x_N.
    states: Vec<St>,
    un: Vec<[V; 4]>,
    rotors: Vec<[V; 4]>,
}

/// The loss of one lane group (lane-weighted, summed over its lanes) and its gradient, added
/// to `g`.
#[inline(always)]
fn group(k: &K, n: &Nets, pf: &[f32], width: usize, gr: &Group, sc: &mut Scratch, g: &mut Grads) {
    let steps = gr.u.len();
    let npts = 4 * steps + 1;
    sc.pts.resize(npts, Point::ZERO);
    sc.recs.resize(4 * steps, Rhs::ZERO);
    sc.adj.clear();
    sc.adj.resize(steps + 1, PointAdj::ZERO);
    sc.states.resize(steps + 1, St::ZERO);
    sc.un.resize(steps, [V::ZERO; 4]);
    sc.rotors.resize(steps, [V::ZERO; 4]);
    let m = k.mass_kg;
    let dt = k.dt_s;
    let rotor_gains = width > P;
    let a: [V; P] = vs(|c| V(std::array::from_fn(|l| pf[gr.flight[l] * width + c])));
    let eta: [V; NR] = vs(|c| {
        V(std::array::from_fn(|l| {
            if rotor_gains {
                pf[gr.flight[l] * width + P + c]
            } else {
                0.0
            }
        }))
    });
    // ζ → 𝔭 at x₀: 𝔭_ω = (J⁻¹)⁻¹ ω by cofactors.
    eval_point(n, &gr.r[0], &mut sc.pts[0]);
    let jm = sc.pts[0].j;
    let row = |i: usize| [jm[i * 3], jm[i * 3 + 1], jm[i * 3 + 2]];
    let (ra, rb, rc) = (row(0), row(1), row(2));
    let bxc = cross(&rb, &rc);
    let cxa = cross(&rc, &ra);
    let axb = cross(&ra, &rb);
    let det = ra[0] * bxc[0] + ra[1] * bxc[1] + ra[2] * bxc[2];
    // inv[i][j] = [b × c, c × a, a × b][j][i] / det.
    let cols = [bxc, cxa, axb];
    let inv: [V; 9] = vs(|e| cols[e % 3][e / 3] / det);
    let w0 = &gr.w[0];
    let pw0: [V; 3] = vs(|i| inv[i * 3] * w0[0] + inv[i * 3 + 1] * w0[1] + inv[i * 3 + 2] * w0[2]);
    sc.states[0] = St {
        p: gr.p[0],
        r: gr.r[0],
        pv: vs(|i| gr.v[0][i] * m),
        pw: pw0,
    };
    let mut loss = V::ZERO;
    // Forward.
    for s in 0..steps {
        let u0: [V; 4] = vs(|c| gr.u[s][c] * k.cinv[c]);
        let mut un = u0;
        if rotor_gains {
            let rot: [V; 4] = vs(|j| {
                let mut t = V::ZERO;
                for i in 0..4 {
                    t += u0[i] * k.rfu[i][j];
                }
                t
            });
            sc.rotors[s] = rot;
            for c in 0..4 {
                let mut t = V::ZERO;
                for j in 0..4 {
                    t += rot[j] * eta[j] * k.ufr[j][c];
                }
                un[c] = u0[c] + t;
            }
        }
        sc.un[s] = un;
        let x = sc.states[s];
        let b = 4 * s;
        let k1 = rhs(k, n, &sc.pts[b], &x.pv, &x.pw, &un, &a, &mut sc.recs[b]);
        let x2 = x.axpy(0.5 * dt, &k1);
        eval_point(n, &x2.r, &mut sc.pts[b + 1]);
        let k2 = rhs(
            k,
            n,
            &sc.pts[b + 1],
            &x2.pv,
            &x2.pw,
            &un,
            &a,
            &mut sc.recs[b + 1],
        );
        let x3 = x.axpy(0.5 * dt, &k2);
        eval_point(n, &x3.r, &mut sc.pts[b + 2]);
        let k3 = rhs(
            k,
            n,
            &sc.pts[b + 2],
            &x3.pv,
            &x3.pw,
            &un,
            &a,
            &mut sc.recs[b + 2],
        );
        let x4 = x.axpy(dt, &k3);
        eval_point(n, &x4.r, &mut sc.pts[b + 3]);
        let k4 = rhs(
            k,
            n,
            &sc.pts[b + 3],
            &x4.pv,
            &x4.pw,
            &un,
            &a,
            &mut sc.recs[b + 3],
        );
        let h6 = dt / 6.0;
        let comb = |x: V, a: V, b: V, c: V, d: V| x + (a + (b + c) * 2.0 + d) * h6;
        let mut xn = St::ZERO;
        for i in 0..3 {
            xn.p[i] = comb(x.p[i], k1.p[i], k2.p[i], k3.p[i], k4.p[i]);
            xn.pv[i] = comb(x.pv[i], k1.pv[i], k2.pv[i], k3.pv[i], k4.pv[i]);
            xn.pw[i] = comb(x.pw[i], k1.pw[i], k2.pw[i], k3.pw[i], k4.pw[i]);
        }
        for i in 0..9 {
            xn.r[i] = comb(x.r[i], k1.r[i], k2.r[i], k3.r[i], k4.r[i]);
        }
        sc.states[s + 1] = xn;
        eval_point(n, &xn.r, &mut sc.pts[b + 4]);
    }
    // Reverse.
    let mut xb = St::ZERO;
    let mut ab = [V::ZERO; P];
    let mut etab = [V::ZERO; NR];
    let lw = gr.weight;
    for s in (0..steps).rev() {
        let b = 4 * s;
        let xn = sc.states[s + 1];
        let pt = &sc.pts[b + 4];
        // The loss at x_{s+1}.
        let (tp, tr, tv, tw) = (&gr.p[s + 1], &gr.r[s + 1], &gr.v[s + 1], &gr.w[s + 1]);
        let v: [V; 3] = vs(|i| xn.pv[i] / m);
        let jm = &pt.j;
        let w: [V; 3] =
            vs(|i| jm[i * 3] * xn.pw[0] + jm[i * 3 + 1] * xn.pw[1] + jm[i * 3 + 2] * xn.pw[2]);
        let mut lp = V::ZERO;
        let mut lv = V::ZERO;
        let mut lwv = V::ZERO;
        for i in 0..3 {
            let dp = xn.p[i] - tp[i];
            let dv = v[i] - tv[i];
            let dw = w[i] - tw[i];
            lp += dp * dp;
            lv += dv * dv;
            lwv += dw * dw;
            xb.p[i] += dp * lw * 2.0;
            xb.pv[i] += dv * lw * (2.0 * k.vel_weight) / m;
        }
        let wb: [V; 3] = vs(|i| (w[i] - tw[i]) * lw * 2.0);
        let pa = &mut sc.adj[s + 1];
        for i in 0..3 {
            for j in 0..3 {
                pa.j[i * 3 + j] += wb[i] * xn.pw[j];
                xb.pw[j] += jm[i * 3 + j] * wb[i];
            }
        }
        // ℓ_R: E = R R̄ᵀ, skew = (E − Eᵀ)/2, s = ½ Σ skew², θ² ≈ s + s²/3 + 8 s³/45.
        let r = &xn.r;
        let e: [V; 9] = vs(|ij| {
            let (i, j) = (ij / 3, ij % 3);
            r[i * 3] * tr[j * 3] + r[i * 3 + 1] * tr[j * 3 + 1] + r[i * 3 + 2] * tr[j * 3 + 2]
        });
        let skew: [V; 9] = vs(|ij| {
            let (i, j) = (ij / 3, ij % 3);
            (e[i * 3 + j] - e[j * 3 + i]) * 0.5
        });
        let mut ss = V::ZERO;
        for x in &skew {
            ss += *x * *x;
        }
        let ss = ss * 0.5;
        let lr = ss + ss * ss / 3.0 + ss * ss * ss * (8.0 / 45.0);
        loss += (lp + lr + lv * k.vel_weight + lwv) * lw;
        let ls = (V::splat(1.0) + ss * (2.0 / 3.0) + ss * ss * (8.0 / 15.0)) * lw;
        for i in 0..3 {
            for kk in 0..3 {
                let mut t = V::ZERO;
                for j in 0..3 {
                    t += skew[i * 3 + j] * tr[j * 3 + kk];
                }
                xb.r[i * 3 + kk] += t * ls;
            }
        }
        // The heads at x_{s+1} (the loss's ω, and the next step's first stage).
        let qb = point_back(n, &sc.pts[b + 4], &sc.adj[s + 1], g);
        for i in 0..9 {
            xb.r[i] += qb[i];
        }
        // RK4 reverse.
        let h6 = dt / 6.0;
        let mut k1b = St::ZERO;
        k1b.add_scaled(h6, &xb);
        let mut k2b = St::ZERO;
        k2b.add_scaled(2.0 * h6, &xb);
        let mut k3b = k2b;
        let k4b = k1b;
        let un = sc.un[s];
        let mut unb = [V::ZERO; 4];
        let stages: [(usize, f32); 3] = [(3, dt), (2, 0.5 * dt), (1, 0.5 * dt)];
        for (stage, h) in stages {
            let kb = match stage {
                3 => k4b,
                2 => k3b,
                _ => k2b,
            };
            let mut pa = PointAdj::ZERO;
            let ptx = &sc.pts[b + stage];
            let mut sb = rhs_back(
                k,
                n,
                ptx,
                &sc.recs[b + stage],
                &un,
                &a,
                &kb,
                &mut pa,
                &mut unb,
                &mut ab,
                &mut g.i,
            );
            let qb = point_back(n, ptx, &pa, g);
            for i in 0..9 {
                sb.r[i] += qb[i];
            }
            // x_stage = x + h k_{stage−1}.
            xb.add_scaled(1.0, &sb);
            match stage {
                3 => k3b.add_scaled(h, &sb),
                2 => k2b.add_scaled(h, &sb),
                _ => k1b.add_scaled(h, &sb),
            }
        }
        let mut pa = sc.adj[s];
        let sb = rhs_back(
            k,
            n,
            &sc.pts[b],
            &sc.recs[b],
            &un,
            &a,
            &k1b,
            &mut pa,
            &mut unb,
            &mut ab,
            &mut g.i,
        );
        sc.adj[s] = pa;
        xb.add_scaled(1.0, &sb);
        // The realized command through the rotor gains.
        if rotor_gains {
            let rot = sc.rotors[s];
            for j in 0..4 {
                let mut t = V::ZERO;
                for c in 0..4 {
                    t += unb[c] * k.ufr[j][c];
                }
                etab[j] += t * rot[j];
            }
        }
    }
    // 𝔭_ω(x₀) = (J⁻¹)⁻¹ ω: d(A⁻¹) = −A⁻¹ dA A⁻¹, so Ā = −A⁻ᵀ 𝔭̄ 𝔭ᵀ.
    let pwb0 = xb.pw;
    let zb: [V; 3] = vs(|i| inv[i] * pwb0[0] + inv[3 + i] * pwb0[1] + inv[6 + i] * pwb0[2]);
    {
        let pa = &mut sc.adj[0];
        for i in 0..3 {
            for j in 0..3 {
                pa.j[i * 3 + j] -= zb[i] * pw0[j];
            }
        }
    }
    let _ = point_back(n, &sc.pts[0], &sc.adj[0], g);
    // Per-flight rows.
    for l in 0..LANES {
        let row = gr.flight[l] * width;
        for c in 0..P {
            g.per_flight[row + c] += ab[c].0[l];
        }
        if rotor_gains {
            for c in 0..NR {
                g.per_flight[row + P + c] += etab[c].0[l];
            }
        }
    }
    g.loss += loss.0.iter().map(|&x| f64::from(x)).sum::<f64>();
}

/// The mean loss over the windows `ids` of `data` and its gradient for every parameter tensor
/// (`params`: the 18 MLP tensors then the per-flight one, flattened; see the module doc), with
/// the windows split over `threads` threads. `None` when the tensors' sizes are not the core's
/// compile-time ones (hidden 16, p = 6) or the per-flight tensor's width is neither p nor
/// p + 4.
pub fn loss_and_grads(
    data: &Windows,
    ids: &[usize],
    params: &[Vec<f32>],
    dt_s: f32,
    vel_weight: f32,
    threads: usize,
) -> Option<(f64, Vec<Vec<f32>>)> {
    loss_and_grads_on(data, ids, params, dt_s, vel_weight, threads, Isa::Best)
}

/// The instruction set the kernel runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// The best the CPU has (AVX-512VL, AVX2 or the baseline; [`loss_and_grads`]).
    Best,
    /// The build's baseline target (on x86_64 SSE2), whatever the CPU has: for the test of the
    /// path other CPUs take.
    Baseline,
}

/// [`loss_and_grads`] with the instruction set `isa`.
pub fn loss_and_grads_on(
    data: &Windows,
    ids: &[usize],
    params: &[Vec<f32>],
    dt_s: f32,
    vel_weight: f32,
    threads: usize,
    isa: Isa,
) -> Option<(f64, Vec<Vec<f32>>)> {
    if params.len() != 19 || ids.is_empty() || data.window_len < 2 {
        return None;
    }
    let nets = Nets {
        i: Head::from_flat(&params[0..6])?,
        g: Head::from_flat(&params[6..12])?,
        d: Head::from_flat(&params[12..18])?,
    };
    let pf = &params[18];
    let n_flights = data.realizations.len().max(1);
    if !pf.len().is_multiple_of(n_flights) {
        return None;
    }
    let width = pf.len() / n_flights;
    if width != P && width != P + NR {
        return None;
    }
    if ids.iter().any(|&i| {
        data.windows
            .get(i)
            .is_none_or(|w| w.realization >= n_flights)
    }) {
        return None;
    }
    let k = K::new(data.mass_kg, dt_s, vel_weight);
    let batch = ids.len();
    let groups: Vec<&[usize]> = ids.chunks(LANES).collect();
    let threads = threads.clamp(1, groups.len());
    let per = groups.len().div_ceil(threads);
    let run = |part: &[&[usize]]| -> Grads {
        let mut g = Grads {
            i: HeadGrad::zero(),
            g: HeadGrad::zero(),
            d: HeadGrad::zero(),
            per_flight: vec![0.0; pf.len()],
            loss: 0.0,
        };
        let mut sc = Scratch {
            pts: Vec::new(),
            recs: Vec::new(),
            adj: Vec::new(),
            states: Vec::new(),
            un: Vec::new(),
            rotors: Vec::new(),
        };
        for ids in part {
            let gr = Group::load(data, ids, batch);
            if isa == Isa::Baseline {
                group(&k, &nets, pf, width, &gr, &mut sc, &mut g);
            } else {
                group_dispatch(&k, &nets, pf, width, &gr, &mut sc, &mut g);
            }
        }
        g
    };
    let parts: Vec<Grads> = if threads == 1 {
        vec![run(&groups)]
    } else {
        // The first part on this thread, the others on threads of their own.
        let mut chunks = groups.chunks(per);
        let first = chunks.next().unwrap_or(&[]);
        std::thread::scope(|s| {
            let hs: Vec<_> = chunks.map(|p| s.spawn(move || run(p))).collect();
            let mut out = vec![run(first)];
            out.extend(hs.into_iter().filter_map(|h| h.join().ok()));
            out
        })
    };
    let mut loss = 0.0;
    let mut out: Vec<Vec<f32>> = Vec::new();
    for g in parts {
        loss += g.loss;
        let mut flat: Vec<Vec<f32>> = Vec::with_capacity(19);
        flat.extend(g.i.flat());
        flat.extend(g.g.flat());
        flat.extend(g.d.flat());
        flat.push(g.per_flight);
        if out.is_empty() {
            out = flat;
        } else {
            for (o, f) in out.iter_mut().zip(flat) {
                for (a, b) in o.iter_mut().zip(f) {
                    *a += b;
                }
            }
        }
    }
    Some((loss, out))
}

/// [`group`] compiled for the best vector extension the CPU has: AVX-512VL (32 vector
/// registers) or AVX2 (a lane group then fills one 256-bit register), or the baseline target
/// (SSE2: two registers). Measured with `host-train bench-train --batch 0` on this machine:
/// 0.199 s per epoch baseline, 0.179 AVX2, 0.137 AVX2 with AVX-512VL; explicit FMA (`f32::mul_add`) was
/// slower (0.098 against 0.082 back to back), so the lanes multiply and add apart.
fn group_dispatch(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx2") && has!("avx512f") && has!("avx512vl") {
            // SAFETY: the CPU has every feature `group_avx512` enables (checked just above).
            unsafe { group_avx512(k, n, pf, width, gr, sc, g) };
            return;
        }
        if has!("avx2") {
            // SAFETY: the CPU has every feature `group_avx2` enables (checked just above).
            unsafe { group_avx2(k, n, pf, width, gr, sc, g) };
            return;
        }
    }
    group(k, n, pf, width, gr, sc, g);
}

/// [`group`] with AVX2 and AVX-512VL enabled (the same 8-lane code with 32 vector registers
/// instead of 16: fewer spills).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
fn group_avx512(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
    group(k, n, pf, width, gr, sc, g);
}

/// [`group`] with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn group_avx2(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
    group(k, n, pf, width, gr, sc, g);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rational tanh stays within a few ulp of the library's over the range that matters.
    #[test]
    fn fast_tanh_matches_the_library() {
        let mut worst = 0f32;
        for i in -200_000..=200_000 {
            let x = i as f32 * 1e-4;
            let e = (tanh_f32(x) - (x as f64).tanh() as f32).abs();
            worst = worst.max(e / (x as f64).tanh().abs().max(1e-30) as f32);
        }
        assert!(worst < 2e-6, "worst relative error {worst}");
        assert_eq!(tanh_f32(30.0), 1.0);
        assert_eq!(tanh_f32(-30.0), -1.0);
    }
}
