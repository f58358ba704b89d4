//! One lane group's windows: RK4 through each window, the loss and its full reverse pass.

use super::*;

/// One lane group's data: states x₀..x_N, commands, flight rows, lane weights.
pub(super) struct Group {
    pub(super) p: Vec<[V; 3]>,
    pub(super) r: Vec<[V; 9]>,
    pub(super) v: Vec<[V; 3]>,
    pub(super) w: Vec<[V; 3]>,
    pub(super) u: Vec<[V; 4]>,
    pub(super) flight: [usize; LANES],
    /// 1/B for a window of the batch, 0 for a padding lane.
    pub(super) weight: V,
}

impl Group {
    pub(super) fn load(data: &Windows, ids: &[usize], batch: usize) -> Self {
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
pub(super) struct Scratch {
    pub(super) pts: Vec<Point>,
    pub(super) recs: Vec<Rhs>,
    pub(super) adj: Vec<PointAdj>,
    /// x₀..x_N.
    pub(super) states: Vec<St>,
    pub(super) un: Vec<[V; 4]>,
    pub(super) rotors: Vec<[V; 4]>,
}

/// The loss of one lane group (lane-weighted, summed over its lanes) and its gradient, added
/// to `g`.
#[inline(always)]
pub(super) fn group(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
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
