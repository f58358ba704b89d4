//! The equations' constants and the three heads at one point of a window's integration, forward and reverse.

use super::*;

/// Constants of the equations.
#[derive(Clone, Debug)]
pub(super) struct K {
    pub(super) mass_kg: f32,
    pub(super) dt_s: f32,
    pub(super) vel_weight: f32,
    /// Row form of A⁻¹ S: rotors[j] = Σᵢ u_norm[i] rfu[i][j].
    pub(super) rfu: [[f32; NR]; NR],
    /// Row form of S⁻¹ A: u_norm[c] = Σⱼ rotors[j] ufr[j][c].
    pub(super) ufr: [[f32; NR]; NR],
    pub(super) cinv: [f32; 4],
}

impl K {
    pub(super) fn new(mass_kg: f32, dt_s: f32, vel_weight: f32) -> Self {
        let (rfu, ufr) = crate::train::export::normalized_rotor_maps();
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
pub(super) struct Nets {
    pub(super) i: Head<OI>,
    pub(super) g: Head<OG>,
    pub(super) d: Head<OD>,
}

/// The three heads' gradients.
pub(super) struct Grads {
    pub(super) i: HeadGrad<OI>,
    pub(super) g: HeadGrad<OG>,
    pub(super) d: HeadGrad<OD>,
    /// Per-flight gradient, flattened `[M, width]`.
    pub(super) per_flight: Vec<f32>,
    pub(super) loss: f64,
}

/// The heads at one rotation (one point of the window's integration).
#[derive(Clone, Copy, Debug)]
pub(super) struct Point {
    /// q's rows (R row-major).
    pub(super) x: [V; 9],
    pub(super) ti: Tr<OI>,
    pub(super) tg: Tr<OG>,
    pub(super) td: Tr<OD>,
    /// L, row-major.
    pub(super) l: [V; 9],
    /// J⁻¹, row-major.
    pub(super) j: [V; 9],
}

impl Point {
    pub(super) const ZERO: Self = Self {
        x: [V::ZERO; 9],
        ti: Tr::ZERO,
        tg: Tr::ZERO,
        td: Tr::ZERO,
        l: [V::ZERO; 9],
        j: [V::ZERO; 9],
    };
}

#[inline(always)]
pub(super) fn eval_point(n: &Nets, x: &[V; 9], pt: &mut Point) {
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
pub(super) struct PointAdj {
    /// ∂ℓ/∂J⁻¹ and ∂ℓ/∂L (direct uses), row-major.
    pub(super) j: [V; 9],
    pub(super) l: [V; 9],
    pub(super) yg: [V; OG],
    pub(super) yd: [V; OD],
    /// The J⁻¹ head's hidden activations' adjoints from the VJP.
    pub(super) h0x: [V; H],
    pub(super) h1x: [V; H],
}

impl PointAdj {
    pub(super) const ZERO: Self = Self {
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
pub(super) fn point_back(n: &Nets, pt: &Point, a: &PointAdj, g: &mut Grads) -> [V; 9] {
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
