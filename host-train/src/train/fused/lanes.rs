//! Eight windows in lockstep: the lane type [`V`] and its element-wise maths.

use super::*;

/// One value per window of a lane group.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(32))]
pub(super) struct V(pub(super) [f32; LANES]);

impl V {
    pub(super) const ZERO: V = V([0.0; LANES]);

    #[inline(always)]
    pub(super) fn splat(x: f32) -> V {
        V([x; LANES])
    }

    #[inline(always)]
    pub(super) fn map(self, f: impl Fn(f32) -> f32) -> V {
        let mut o = [0.0; LANES];
        for (o, x) in o.iter_mut().zip(self.0) {
            *o = f(x);
        }
        V(o)
    }

    #[inline(always)]
    pub(super) fn tanh(self) -> V {
        self.map(tanh_f32)
    }

    /// 1 − x².
    #[inline(always)]
    pub(super) fn one_minus_sq(self) -> V {
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
pub(super) fn tanh_f32(a: f32) -> f32 {
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
/// and a called function is compiled without the kernel's target features (such a call can take
/// a visible share of an epoch: docs/performance.md, "Training speed").
#[inline(always)]
pub(super) fn vs<const N: usize>(f: impl Fn(usize) -> V) -> [V; N] {
    let mut o = [V::ZERO; N];
    for (i, o) in o.iter_mut().enumerate() {
        *o = f(i);
    }
    o
}

/// c = a × b.
#[inline(always)]
pub(super) fn cross(a: &[V; 3], b: &[V; 3]) -> [V; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
pub(super) fn add3(acc: &mut [V], d: &[V; 3]) {
    for (a, d) in acc.iter_mut().zip(d) {
        *a += *d;
    }
}
