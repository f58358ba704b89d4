//! Adam, the optimizer of the training epochs ([`super::epochs`]) and the black-box comparison.

use burn::tensor::Tensor;

/// Adam (β₁ = 0.9, β₂ = 0.999, ε = 1e-8) on a list of tensors, a learning rate per tensor.
pub struct Adam {
    m: Vec<Tensor<2>>,
    v: Vec<Tensor<2>>,
    t: i32,
}

impl Adam {
    /// Zero moments for `params`.
    pub fn new(params: &[Tensor<2>]) -> Self {
        Self {
            m: params.iter().map(|p| p.zeros_like()).collect(),
            v: params.iter().map(|p| p.zeros_like()).collect(),
            t: 0,
        }
    }

    /// One Adam step (β₁ = 0.9, β₂ = 0.999, ε = 1e-8) with a learning rate per tensor; a
    /// tensor without a gradient (`None`) is left as it is.
    pub fn step(&mut self, params: &mut [Tensor<2>], grads: &[Option<Tensor<2>>], lrs: &[f64]) {
        self.t += 1;
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        let c1 = 1.0 - b1.powi(self.t);
        let c2 = 1.0 - b2.powi(self.t);
        for i in 0..params.len() {
            let Some(g) = grads[i].clone() else {
                continue;
            };
            self.m[i] = self.m[i].clone().mul_scalar(b1) + g.clone().mul_scalar(1.0 - b1);
            self.v[i] = self.v[i].clone().mul_scalar(b2) + g.square().mul_scalar(1.0 - b2);
            let mhat = self.m[i].clone().div_scalar(c1);
            let vhat = self.v[i].clone().div_scalar(c2);
            let upd = mhat / vhat.sqrt().add_scalar(eps);
            params[i] = params[i].clone() - upd.mul_scalar(lrs[i]);
        }
    }
}
