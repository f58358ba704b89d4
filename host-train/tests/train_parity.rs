//! Parity: the core's f32 inference (`LearnedModel`) and the host's burn training model give
//! the same J⁻¹, g, W and state derivative (paper eq. 1–2) on random states for the same weights.

mod train_common;

use burn::tensor::{Device, Int, Tensor, TensorData};
use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, State, FEATURES};
use host_train::train::{init_weights, tensor_to_vec, Consts, Forcing, TModel};
use nalgebra::Vector4;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rel_err(a: &[f32], b: &[f32]) -> f32 {
    let num: f32 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f32>()
        .sqrt();
    let den: f32 = b.iter().map(|y| y * y).sum::<f32>().sqrt().max(1e-12);
    num / den
}

/// Weights far from the prior, so every network term matters.
fn weights() -> ModelWeights {
    let mut w = init_weights(11, 1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for v in w
        .inertia
        .l2
        .bias
        .iter_mut()
        .chain(w.gain.l2.bias.iter_mut())
    {
        *v += rng.gen_range(-0.3..0.3);
    }
    for v in w
        .inertia
        .l0
        .bias
        .iter_mut()
        .chain(w.disturbance.l1.bias.iter_mut())
    {
        *v = rng.gen_range(-0.5..0.5);
    }
    w
}

fn tensor2(v: Vec<f32>, shape: [usize; 2], d: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(v, shape), d)
}

/// For a small batch (batched matmuls) and a large one (the small products as broadcast
/// multiplies and sums, see `BROADCAST_MIN_BATCH` in the host model).
#[test]
fn core_and_host_models_agree() {
    for n in [16, 1100] {
        core_and_host_models_agree_at(n);
    }
}

fn core_and_host_models_agree_at(n: usize) {
    let device = Device::flex();
    // A vehicle heavier than the stock one: the mass must reach both sides the same way.
    let w = ModelWeights {
        mass_kg: 0.034,
        ..weights()
    };
    let core = LearnedModel::new(w);
    let host = TModel::from_core(&w, &device);
    let c = Consts::new(&device, w.mass_kg);
    assert_eq!(
        host.to_core(&c),
        w,
        "host ↔ core weights round trip, mass included"
    );
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let states: Vec<State> = (0..n)
        .map(|_| train_common::random_state(&mut rng, 1.0))
        .collect();
    let us: Vec<Vector4<f32>> = (0..n)
        .map(|_| train_common::random_control(&mut rng))
        .collect();
    let a: Vec<[f32; FEATURES]> = (0..n)
        .map(|_| std::array::from_fn(|_| rng.gen_range(-1.0..1.0)))
        .collect();

    let flat = |f: &dyn Fn(&State) -> Vec<f32>| states.iter().flat_map(f).collect::<Vec<f32>>();
    let p = tensor2(flat(&|s| s.p_m.as_slice().to_vec()), [n, 3], &device);
    let rot: Tensor<3> = Tensor::from_data(
        TensorData::new(
            flat(&|s| hamflight::model::learned::rot_input(&s.rot).to_vec()),
            [n, 3, 3],
        ),
        &device,
    );
    let v = tensor2(flat(&|s| s.v_body_m_s.as_slice().to_vec()), [n, 3], &device);
    let om = tensor2(
        flat(&|s| s.w_body_rad_s.as_slice().to_vec()),
        [n, 3],
        &device,
    );
    let u = tensor2(
        us.iter().flat_map(|u| u.as_slice().to_vec()).collect(),
        [n, 4],
        &device,
    );
    let a_all = tensor2(
        a.iter().flatten().copied().collect(),
        [n, FEATURES],
        &device,
    );
    let idx: Tensor<1, Int> = Tensor::from_data(
        TensorData::new((0..n as i64).collect::<Vec<_>>(), [n]),
        &device,
    );
    let forcing = Forcing::new(&c, u.clone(), a_all, idx);

    // J⁻¹, g, W.
    let jinv_h = tensor_to_vec(&host.inertia_inv(&c, &rot).jinv);
    let w_h = tensor_to_vec(&host.features(&c, &rot));
    let mut jinv_c = Vec::new();
    let mut w_c = Vec::new();
    for s in &states {
        let t = core.terms(s);
        jinv_c.extend(t.inertia_inv.transpose().iter().copied()); // row-major
        w_c.extend(t.features.transpose().iter().copied());
    }
    assert!(
        rel_err(&jinv_h, &jinv_c) < 1e-4,
        "J⁻¹ {}",
        rel_err(&jinv_h, &jinv_c)
    );
    assert!(rel_err(&w_h, &w_c) < 1e-4, "W {}", rel_err(&w_h, &w_c));

    // g u (both columns scales at once: the control wrench of random controls).
    let (fu, tu) = host.control_wrench(&c, &rot, forcing.u_norm.clone());
    let (fu, tu) = (tensor_to_vec(&fu), tensor_to_vec(&tu));
    for (i, (s, uu)) in states.iter().zip(&us).enumerate() {
        let gu = core.terms(s).gain * uu;
        let fh = &fu[3 * i..3 * i + 3];
        let th = &tu[3 * i..3 * i + 3];
        assert!(rel_err(fh, &gu.as_slice()[..3]) < 1e-4);
        assert!(
            rel_err(th, &gu.as_slice()[3..]) < 1e-4,
            "{th:?} vs {:?}",
            &gu.as_slice()[3..]
        );
    }
    // g itself, column by column, with unit controls.
    for k in 0..4 {
        let mut e = vec![0f32; 4 * n];
        for i in 0..n {
            e[4 * i + k] = hamflight::model::learned::CONTROL_SCALE[k];
        }
        let un = tensor2(e, [n, 4], &device)
            * tensor2(
                hamflight::model::learned::CONTROL_SCALE
                    .iter()
                    .map(|c| 1.0 / c)
                    .collect(),
                [1, 4],
                &device,
            );
        let (f, t) = host.control_wrench(&c, &rot, un);
        let (f, t) = (tensor_to_vec(&f), tensor_to_vec(&t));
        for (i, s) in states.iter().enumerate() {
            let col = core.terms(s).gain.column(k) * hamflight::model::learned::CONTROL_SCALE[k];
            let h: Vec<f32> = f[3 * i..3 * i + 3]
                .iter()
                .chain(&t[3 * i..3 * i + 3])
                .copied()
                .collect();
            assert!(rel_err(&h, col.as_slice()) < 1e-4, "g column {k}");
        }
    }

    // The state derivative, including ∂H/∂rᵢ (VJP) and d/dt J⁻¹ (JVP).
    let (pd, rd, vd, wd) = host.state_derivative(&c, p, rot, v, om, &forcing);
    let (pd, rd, vd, wd) = (
        tensor_to_vec(&pd),
        tensor_to_vec(&rd),
        tensor_to_vec(&vd),
        tensor_to_vec(&wd),
    );
    let (mut pc, mut rc, mut vc, mut wc) = (vec![], vec![], vec![], vec![]);
    for ((s, uu), aj) in states.iter().zip(&us).zip(&a) {
        let d = core.dynamics(s, uu, aj);
        pc.extend_from_slice(d.p_dot_m_s.as_slice());
        rc.extend(d.rot_dot.transpose().iter().copied());
        vc.extend_from_slice(d.v_dot_m_s2.as_slice());
        wc.extend_from_slice(d.w_dot_rad_s2.as_slice());
    }
    assert!(rel_err(&pd, &pc) < 1e-4, "ṗ {}", rel_err(&pd, &pc));
    assert!(rel_err(&rd, &rc) < 1e-4, "Ṙ {}", rel_err(&rd, &rc));
    assert!(rel_err(&vd, &vc) < 1e-4, "v̇ {}", rel_err(&vd, &vc));
    assert!(rel_err(&wd, &wc) < 1e-4, "ω̇ {}", rel_err(&wd, &wc));
}

#[test]
fn host_network_jacobians_match_finite_differences() {
    let device = Device::flex();
    let w = weights();
    let host = TModel::from_core(&w, &device);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let x: Vec<f32> = (0..9).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let dx: Vec<f32> = (0..9).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let dy: Vec<f32> = (0..6).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let xt = tensor2(x.clone(), [1, 9], &device);
    let tr = host.inertia.forward(xt);
    let jvp = tensor_to_vec(&host.inertia.jvp(&tr, tensor2(dx.clone(), [1, 9], &device)));
    let vjp = tensor_to_vec(&host.inertia.vjp(&tr, tensor2(dy.clone(), [1, 6], &device)));
    let h = 1e-2f32;
    let f =
        |x: &[f32]| tensor_to_vec(&host.inertia.forward(tensor2(x.to_vec(), [1, 9], &device)).y);
    let shift = |s: f32| {
        x.iter()
            .zip(&dx)
            .map(|(a, b)| a + s * b)
            .collect::<Vec<_>>()
    };
    let (yp, ym) = (f(&shift(h)), f(&shift(-h)));
    let fd: Vec<f32> = yp
        .iter()
        .zip(&ym)
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect();
    assert!(rel_err(&jvp, &fd) < 1e-3, "JVP {jvp:?} vs {fd:?}");
    for i in 0..9 {
        let mut xp = x.clone();
        xp[i] += h;
        let mut xm = x.clone();
        xm[i] -= h;
        let (yp, ym) = (f(&xp), f(&xm));
        let g: f32 = yp
            .iter()
            .zip(&ym)
            .zip(&dy)
            .map(|((a, b), d)| d * (a - b) / (2.0 * h))
            .sum();
        assert!(
            (g - vjp[i]).abs() < 1e-3 * (1.0 + g.abs()),
            "VJP[{i}] {} vs {g}",
            vjp[i]
        );
    }
}

/// The trainer's fast loss (heads fused for small batches, J⁻¹(q) and the heads evaluated once
/// per state and shared by the velocities and the next RK4 stage) equals the plain reference
/// built from the model's methods — the value and every tensor's gradient — for a small batch
/// (fused heads) and a large one (heads apart).
#[test]
fn fast_training_loss_matches_the_reference_ops() {
    use host_train::train::{
        batch_loss, batch_loss_reference, batch_windows, RealizationInfo, Window, Windows,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let n_real = 3;
    let windows: Vec<Window> = (0..1100)
        .map(|i| Window {
            states: (0..5)
                .map(|_| train_common::random_state(&mut rng, 0.5))
                .collect(),
            u: (0..4)
                .map(|_| train_common::random_control(&mut rng).into())
                .collect(),
            realization: i % n_real,
        })
        .collect();
    let data = Windows {
        windows,
        sample_hz: 240.0,
        window_len: 5,
        mass_kg: 0.034,
        manifest_mass_kg: 0.034,
        vehicle: Default::default(),
        realizations: (0..n_real)
            .map(|j| RealizationInfo {
                file: format!("r{j}"),
                wind_m_s2: None,
                rotor_efficiency: None,
                disturbance_free: false,
                windows: 0,
                source_file: None,
            })
            .collect(),
    };
    let ad = Device::flex().autodiff();
    let c = Consts::new(&ad, data.mass_kg);
    let w = weights();
    let mut a: Vec<f32> = Vec::new();
    for _ in 0..n_real * FEATURES {
        a.push(rng.gen_range(-0.5..0.5));
    }
    for n in [64usize, 1100] {
        let ids: Vec<usize> = (0..n).collect();
        let b = batch_windows(&data, &ids, &ad);
        let run = |reference: bool| {
            let mut leaves = TModel::from_core(&w, &ad).tensors();
            leaves.push(tensor2(a.clone(), [n_real, FEATURES], &ad));
            let leaves: Vec<Tensor<2>> = leaves.into_iter().map(|l| l.require_grad()).collect();
            let model = TModel::from_tensors(&leaves[..18]);
            let f = if reference {
                batch_loss_reference
            } else {
                batch_loss
            };
            let loss = f(&model, &c, leaves[18].clone(), &b, 1.0 / 240.0, 50.0);
            let grads = loss.backward();
            let g: Vec<Vec<f32>> = leaves
                .iter()
                .map(|l| {
                    l.grad(&grads)
                        .map(|g| tensor_to_vec(&g))
                        .unwrap_or_default()
                })
                .collect();
            (tensor_to_vec(&loss.inner())[0], g)
        };
        let (l_fast, g_fast) = run(false);
        let (l_ref, g_ref) = run(true);
        assert!(l_ref.is_finite() && l_ref > 0.0, "batch {n}: loss {l_ref}");
        assert!(
            (l_fast - l_ref).abs() <= 1e-4 * l_ref,
            "batch {n}: loss {l_fast} vs {l_ref}"
        );
        for (k, (gf, gr)) in g_fast.iter().zip(&g_ref).enumerate() {
            assert!(!gr.is_empty(), "batch {n}: tensor {k} has no gradient");
            let e = rel_err(gf, gr);
            assert!(e < 1e-3, "batch {n}: gradient of tensor {k} off by {e}");
        }
    }
}

/// A minibatch split over the cores (one autodiff graph per shard, gradients averaged by shard
/// size) gives the whole minibatch's loss and gradients, on collected data.
#[test]
fn split_minibatch_gradients_equal_the_whole_batch() {
    use host_train::data::{collect_dataset, CollectConfig};
    use host_train::train::{initial_gradients, load_windows, TrainConfig};
    let dir = train_common::scratch("split-grads");
    let cc = CollectConfig {
        realizations: 2,
        windows: 150,
        poses: 2,
        ..CollectConfig::default()
    };
    collect_dataset(&dir, &cc).expect("collect");
    let cfg = TrainConfig::default();
    let windows = load_windows(&dir, cfg.window).expect("load");
    let ids: Vec<usize> = (0..windows.windows.len()).collect();
    assert!(ids.len() >= 256, "{} windows", ids.len());
    let (l_split, g_split) = initial_gradients(&cfg, &windows, &ids, true);
    let (l_whole, g_whole) = initial_gradients(&cfg, &windows, &ids, false);
    assert!(
        (l_split - l_whole).abs() <= 1e-5 * l_whole,
        "loss {l_split} vs {l_whole}"
    );
    for (k, (a, b)) in g_split.iter().zip(&g_whole).enumerate() {
        assert!(!b.is_empty(), "tensor {k} has no gradient");
        let e = rel_err(a, b);
        assert!(e < 1e-4, "gradient of tensor {k} off by {e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The hand-fused kernel (`train::fused`) gives the burn path's loss and gradients on
/// collected data: with and without the per-flight rotor gains, for two window lengths, at the
/// initial weights and at weights and per-flight parameters moved off them (nonzero a_j and δηⱼ,
/// so that the W head and every term of the rotor gains' path carry a gradient).
#[test]
fn fused_kernel_gradients_equal_burns() {
    use host_train::data::{collect_dataset, CollectConfig};
    use host_train::train::{gradients_at, initial_params, load_windows, Isa, TrainConfig};
    let dir = train_common::scratch("fused-grads");
    let cc = CollectConfig {
        realizations: 2,
        windows: 60,
        poses: 2,
        ..CollectConfig::default()
    };
    collect_dataset(&dir, &cc).expect("collect");
    // The paper's windows of 5 states with and without rotor gains, and windows of 3 states.
    for (rotor_gains, len) in [(false, 5), (true, 5), (true, 3)] {
        let cfg = TrainConfig {
            flight_rotor_gains: rotor_gains,
            window: host_train::io::WindowSpec {
                len,
                ..Default::default()
            },
            ..TrainConfig::default()
        };
        let windows = load_windows(&dir, cfg.window).expect("load");
        // Not a multiple of the kernel's 8 lanes: the padding lanes must not count.
        let ids: Vec<usize> = (0..windows.windows.len().min(101)).collect();
        assert_eq!(ids.len(), 101);
        let init = initial_params(&cfg, &windows);
        let mut moved = init.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for t in moved.iter_mut() {
            for v in t.iter_mut() {
                *v += rng.gen_range(-0.1..0.1);
            }
        }
        for (what, params) in [("initial", &init), ("moved", &moved)] {
            let (l_burn, g_burn) = gradients_at(&cfg, &windows, &ids, params, None);
            let (l_fused, g_fused) = gradients_at(&cfg, &windows, &ids, params, Some(Isa::Best));
            // The baseline build of the kernel (what a CPU without AVX2 runs): the same
            // arithmetic in the same order, so the same values.
            let (l_base, g_base) = gradients_at(&cfg, &windows, &ids, params, Some(Isa::Baseline));
            assert_eq!(l_base, l_fused, "{what} weights: baseline vs vector loss");
            assert_eq!(
                g_base, g_fused,
                "{what} weights: baseline vs vector gradients"
            );
            let tag = format!("rotor gains {rotor_gains}, {len} states, {what} weights");
            eprintln!(
                "{tag}: loss relative difference {:.2e}",
                (l_fused - l_burn).abs() / l_burn
            );
            assert!(l_burn.is_finite() && l_burn > 0.0, "{tag}: loss {l_burn}");
            // The two differ by rounding only: the loss within 1e-6 relative of burn's, each
            // gradient within the bar below. A term missing from the hand-written adjoint (the
            // VJP's second-order one, say) puts a head's gradient percents off and fails here
            // (docs/performance.md, "Training speed").
            assert!(
                (l_fused - l_burn).abs() <= 1e-6 * l_burn,
                "{tag}: loss {l_fused} vs {l_burn}"
            );
            assert_eq!(g_fused.len(), g_burn.len());
            for (k, (gf, gb)) in g_fused.iter().zip(&g_burn).enumerate() {
                assert_eq!(gf.len(), gb.len(), "{tag}: tensor {k}'s size");
                let norm = gb.iter().map(|x| x * x).sum::<f32>().sqrt();
                let e = rel_err(gf, gb);
                eprintln!("{tag}: tensor {k}: |g| {norm:.2e}, relative error {e:.2e}");
                if what == "moved" {
                    assert!(norm > 0.0, "{tag}: tensor {k} has a zero gradient");
                }
                assert!(e < 3e-6, "{tag}: gradient of tensor {k} off by {e}");
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
