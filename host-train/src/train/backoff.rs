//! What a dataset's flights identify of the disturbance features W, and the blobs the flight
//! check tries when the learned W does not fly.
//!
//! The loss sees W only through W(q) a_j (paper eq. 1 with d = W a_j): along a direction of a
//! that no flight's a_j leans on, the data say nothing about W, and Adam walks those columns
//! where noise takes them. Simulated datasets blow winds and fail rotors in every direction, so
//! every column is taught; real flights without a deliberate disturbance teach one or two (the
//! nano-drone benchmark's a_j are almost all thrust: −0.4 to −1.6 m/s² along z), and the rest of
//! W then varies tens of times more with attitude than the nominal features do. The adaptation
//! law chases that variation and crashes.
//!
//! So when the learned W fails the flight check, [`candidates`] gives, in order: W as learned;
//! W kept only along the excited directions ([`excited_subspace`]) and nominal elsewhere; that
//! pulled toward the nominal features by [`BACKOFF_KEEP`]; and the nominal features. The
//! trainer writes the first that passes and records which ([`super::export::FeatureBackoff`]).

use hamflight::model::{ModelWeights, FEATURES};
use nalgebra::{DMatrix, SMatrix};

/// A direction of a counts as excited when the flights' a_j reach at least this share of the
/// strongest direction's singular value (the a_j stacked as rows).
pub const EXCITED_REL: f64 = 0.3;

/// The shares of the excited features' deviation from the nominal ones tried after the
/// excited features themselves (1 is W as learned there, 0 the nominal features).
pub const BACKOFF_KEEP: [f32; 3] = [0.5, 0.25, 0.1];

/// The projector onto the directions of a the flights excited, in the features' basis, and its
/// rank: the right singular vectors of the stacked a_j whose singular value is at least
/// [`EXCITED_REL`] of the largest. Rank 0 (and a zero projector) when every a_j is zero.
pub fn excited_subspace(a: &[[f32; FEATURES]]) -> (SMatrix<f32, FEATURES, FEATURES>, usize) {
    let mut p = SMatrix::<f32, FEATURES, FEATURES>::zeros();
    if a.is_empty() {
        return (p, 0);
    }
    let m = DMatrix::<f64>::from_fn(a.len(), FEATURES, |j, k| {
        a.get(j).and_then(|r| r.get(k)).copied().unwrap_or(0.0) as f64
    });
    let svd = m.svd(false, true);
    let Some(vt) = svd.v_t else {
        return (p, 0);
    };
    let smax = svd.singular_values.max();
    if !(smax > 0.0 && smax.is_finite()) {
        return (p, 0);
    }
    let mut rank = 0;
    for (i, s) in svd.singular_values.iter().enumerate() {
        if *s >= EXCITED_REL * smax {
            let v = vt.row(i).transpose();
            p += (&v * v.transpose())
                .map(|x| x as f32)
                .fixed_view::<FEATURES, FEATURES>(0, 0);
            rank += 1;
        }
    }
    (p, rank)
}

/// One blob the flight check may try.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// How many directions of a keep the learned features ([`FEATURES`]: all, as learned).
    pub excited_dims: usize,
    /// The share of those features' deviation from the nominal ones kept.
    pub kept: f32,
    /// The weights.
    pub weights: ModelWeights,
}

/// The blobs to try in order: `learned` as it is, then (with `backoff`) kept along the
/// directions the flights' `a` excited, pulled toward the nominal features by
/// [`BACKOFF_KEEP`], and the nominal features last.
pub fn candidates(learned: &ModelWeights, a: &[[f32; FEATURES]], backoff: bool) -> Vec<Candidate> {
    let mut out = vec![Candidate {
        excited_dims: FEATURES,
        kept: 1.0,
        weights: *learned,
    }];
    if !backoff {
        return out;
    }
    let (p, rank) = excited_subspace(a);
    // With nothing excited, only the nominal features remain to try.
    if rank > 0 {
        let excited = learned.with_features_in_subspace(&p);
        if rank < FEATURES {
            out.push(Candidate {
                excited_dims: rank,
                kept: 1.0,
                weights: excited,
            });
        }
        out.extend(BACKOFF_KEEP.map(|keep| Candidate {
            excited_dims: rank,
            kept: keep,
            weights: excited.with_features_toward_nominal(keep),
        }));
    }
    out.push(Candidate {
        excited_dims: 0,
        kept: 0.0,
        weights: learned.with_features_toward_nominal(0.0),
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use hamflight::model::{HamiltonianModel, LearnedModel, NominalModel, State};

    #[test]
    fn one_strong_direction_is_the_excited_subspace() {
        // Thrust offsets of −0.4 to −1.6 along z, and small noise elsewhere.
        let a: Vec<[f32; FEATURES]> = (0..12)
            .map(|j| {
                let n = 0.03 * ((j * 7 % 5) as f32 - 2.0);
                [n, -n, -0.4 - 0.1 * j as f32, 0.5 * n, 0.0, n]
            })
            .collect();
        let (p, rank) = excited_subspace(&a);
        assert_eq!(rank, 1);
        // A projector: P² = P, trace = rank, and mostly the z direction.
        assert!((p * p - p).norm() < 1e-5);
        assert!((p.trace() - 1.0).abs() < 1e-5);
        assert!(p[(2, 2)] > 0.98, "P_zz = {}", p[(2, 2)]);
        // Every direction taught: the whole space.
        let all: Vec<[f32; FEATURES]> = (0..FEATURES)
            .map(|k| std::array::from_fn(|i| if i == k { 1.0 } else { 0.0 }))
            .collect();
        let (p, rank) = excited_subspace(&all);
        assert_eq!(rank, FEATURES);
        assert!((p - SMatrix::<f32, FEATURES, FEATURES>::identity()).norm() < 1e-5);
        assert_eq!(excited_subspace(&[[0.0; FEATURES]]).1, 0);
        assert_eq!(excited_subspace(&[]).1, 0);
    }

    #[test]
    fn candidates_end_at_the_nominal_features_and_keep_the_excited_columns() {
        let mut w = ModelWeights::prior();
        // A learned W: the output layer's weights away from zero, so W varies with attitude.
        for (k, row) in w.disturbance.l2.weight.iter_mut().enumerate() {
            row.iter_mut()
                .enumerate()
                .for_each(|(i, v)| *v = 0.05 * ((k + 3 * i) % 7) as f32 - 0.15);
        }
        for (i, row) in w.disturbance.l0.weight.iter_mut().enumerate() {
            row.iter_mut()
                .enumerate()
                .for_each(|(k, v)| *v = 0.1 * ((i + k) % 5) as f32 - 0.2);
        }
        let a: Vec<[f32; FEATURES]> = (0..5)
            .map(|j| [0.0, 0.0, -1.0 - j as f32, 0.0, 0.0, 0.0])
            .collect();
        let c = candidates(&w, &a, true);
        assert_eq!(c.len(), 2 + BACKOFF_KEEP.len() + 1);
        assert_eq!((c[0].excited_dims, c[0].kept), (FEATURES, 1.0));
        assert_eq!((c[1].excited_dims, c[1].kept), (1, 1.0));
        let tilted = State {
            rot: *nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.1).matrix(),
            ..State::default()
        };
        let learned = LearnedModel::new(w).features(&tilted);
        let nominal = NominalModel::default().terms(&tilted).features;
        let excited = LearnedModel::new(c[1].weights).features(&tilted);
        // The excited column (z) is the learned one, the others nominal.
        for k in 0..FEATURES {
            let (got, want) = if k == 2 {
                (excited.column(k), learned.column(k))
            } else {
                (excited.column(k), nominal.column(k))
            };
            assert!(
                (got - want).norm() < 1e-5 * want.norm().max(1e-3),
                "column {k}"
            );
        }
        let last = c
            .last()
            .map(|c| LearnedModel::new(c.weights).features(&tilted));
        assert!(last.is_some_and(|f| (f - nominal).norm() < 1e-6));
        assert_eq!(candidates(&w, &a, false).len(), 1);
        // No flight excited anything (all calm): W as learned, then the nominal features.
        let c = candidates(&w, &[], true);
        assert_eq!(c.len(), 2);
        assert_eq!((c[1].excited_dims, c[1].kept), (0, 0.0));
    }
}
