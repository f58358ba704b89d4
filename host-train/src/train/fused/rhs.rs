//! The integrated state and paper eq. 1's right-hand side, forward and reverse.

use super::*;

/// The integrated state (q, 𝔭), or its derivative, or an adjoint of either.
#[derive(Clone, Copy, Debug)]
pub(super) struct St {
    pub(super) p: [V; 3],
    pub(super) r: [V; 9],
    pub(super) pv: [V; 3],
    pub(super) pw: [V; 3],
}

impl St {
    pub(super) const ZERO: Self = Self {
        p: [V::ZERO; 3],
        r: [V::ZERO; 9],
        pv: [V::ZERO; 3],
        pw: [V::ZERO; 3],
    };

    /// self + h d.
    #[inline(always)]
    pub(super) fn axpy(&self, h: f32, d: &St) -> St {
        let mut o = *self;
        o.add_scaled(h, d);
        o
    }

    #[inline(always)]
    pub(super) fn add_scaled(&mut self, h: f32, d: &St) {
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
pub(super) struct Rhs {
    pub(super) pv: [V; 3],
    pub(super) pw: [V; 3],
    pub(super) w: [V; 3],
    pub(super) v: [V; 3],
    pub(super) oa: [V; 6],
    pub(super) z: [V; 3],
    pub(super) dy: [V; 6],
    pub(super) a1: [V; H],
    pub(super) g1: [V; H],
    pub(super) a0: [V; H],
    pub(super) g0: [V; H],
    pub(super) d: [V; 9],
}

impl Rhs {
    pub(super) const ZERO: Self = Self {
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
/// [`crate::train::tensor_model::phase_rhs_with`].
#[inline(always)]
pub(super) fn rhs(
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
pub(super) fn rhs_back(
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
