//! Batched products of 3-vectors and 3×3 matrices as burn tensor ops, `[B, 3]` and `[B, 3, 3]`.

use burn::tensor::Tensor;

use super::Consts;

/// Batch size from which the products of small matrices below are broadcast multiplies and
/// sums instead of batched matmuls: the flex backend runs a batched matmul as one gemm call
/// per matrix, a fixed cost per window, while the broadcast form takes two more ops: it pays off
/// on large shards and costs on small ones (`host-train bench-train`; docs/performance.md,
/// "Training speed").
const BROADCAST_MIN_BATCH: usize = 1024;

/// M`[B,r,k]` x`[B,k]` → `[B,r]`.
pub fn mat_vec_n(m: Tensor<3>, x: Tensor<2>) -> Tensor<2> {
    let [b, r, k] = m.dims();
    if b < BROADCAST_MIN_BATCH {
        return m.matmul(x.reshape([b, k, 1])).reshape([b, r]);
    }
    (m * x.reshape([b, 1, k])).sum_dim(2).reshape([b, r])
}

/// M`[B,3,3]` v`[B,3]` → `[B,3]`.
pub fn matvec(m: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    mat_vec_n(m, v)
}

/// A Bᵀ for A`[B,3,3]`, B`[B,3,3]`: (A Bᵀ)ᵢⱼ = Σₖ Aᵢₖ Bⱼₖ.
pub fn mat_mat_t(a: Tensor<3>, b: Tensor<3>) -> Tensor<3> {
    let n = a.dims()[0];
    if n < BROADCAST_MIN_BATCH {
        return a.matmul(b.swap_dims(1, 2));
    }
    (a.reshape([n, 3, 1, 3]) * b.reshape([n, 1, 3, 3]))
        .sum_dim(3)
        .reshape([n, 3, 3])
}

/// A B for A`[B,3,3]`, B`[B,3,3]`.
pub fn mat_mat(a: Tensor<3>, b: Tensor<3>) -> Tensor<3> {
    let n = a.dims()[0];
    if n < BROADCAST_MIN_BATCH {
        return a.matmul(b);
    }
    (a.reshape([n, 3, 3, 1]) * b.reshape([n, 1, 3, 3]))
        .sum_dim(2)
        .reshape([n, 3, 3])
}

/// Mᵀ v for M`[B,3,3]`, v`[B,3]`.
pub fn mat_t_vec(m: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    let b = v.dims()[0];
    if b < BROADCAST_MIN_BATCH {
        return v.reshape([b, 1, 3]).matmul(m).reshape([b, 3]);
    }
    (m * v.reshape([b, 3, 1])).sum_dim(1).reshape([b, 3])
}

/// Row-major hat map of ω `[B,3]` → `[B,3,3]`.
pub fn hat(c: &Consts, w: Tensor<2>) -> Tensor<3> {
    let b = w.dims()[0];
    w.matmul(c.hat_map.clone()).reshape([b, 3, 3])
}

/// Inverse of a batch of 3×3 matrices `[B,3,3]` by cofactors (rows a, b, c:
/// A⁻¹ = [b×c | c×a | a×b] / a·(b×c)).
pub fn invert_sym3(m: Tensor<3>) -> Tensor<3> {
    let bsz = m.dims()[0];
    let row = |k: usize| m.clone().narrow(1, k, 1).reshape([bsz, 3]);
    let (a, b, c) = (row(0), row(1), row(2));
    let bc = b.clone().cross(c.clone(), 1);
    let ca = c.cross(a.clone(), 1);
    let ab = a.clone().cross(b, 1);
    let det = (a * bc.clone()).sum_dim(1); // [B,1]
                                           // Columns bc, ca, ab: stack as rows then transpose.
    let rows = Tensor::stack::<3>(vec![bc, ca, ab], 1); // [B,3(row=col index),3]
    rows.swap_dims(1, 2) / det.reshape([bsz, 1, 1])
}
