//! The independent blob encoder and helpers shared by `tests/blob.rs` and
//! `tests/blob_format.rs`: blobs written from the documented layout, byte by byte, not by the
//! codec under test.

use super::SplitMix64;
use hamflight::model::{
    ModelWeights, PortTerms, DEFAULT_MOTOR_TAU_S, MAX_MASS_KG, MAX_MOTOR_TAU_S, MIN_MASS_KG,
};
use hamflight::nn::{Dense, Mlp};

/// Calls `f` on every parameter of `w`, in blob order: J⁻¹, g, W networks; within a network the
/// layers in order; within a layer the weights row by row (`weight[o][i]`), then the biases.
pub fn for_each_param(w: &mut ModelWeights, mut f: impl FnMut(&mut f32)) {
    fn dense<const I: usize, const O: usize>(d: &mut Dense<I, O>, f: &mut impl FnMut(&mut f32)) {
        d.weight
            .iter_mut()
            .flatten()
            .chain(d.bias.iter_mut())
            .for_each(f);
    }
    fn mlp<const I: usize, const H: usize, const O: usize>(
        m: &mut Mlp<I, H, O>,
        f: &mut impl FnMut(&mut f32),
    ) {
        dense(&mut m.l0, f);
        dense(&mut m.l1, f);
        dense(&mut m.l2, f);
    }
    mlp(&mut w.inertia, &mut f);
    mlp(&mut w.gain, &mut f);
    mlp(&mut w.disturbance, &mut f);
}

pub fn params(w: &ModelWeights) -> Vec<f32> {
    let mut w = *w;
    let mut out = Vec::new();
    for_each_param(&mut w, |v| out.push(*v));
    out
}

/// What [`decode`] gives, in blob order: the mass, then every parameter.
pub fn body_values(w: &ModelWeights) -> Vec<f32> {
    [w.mass_kg].into_iter().chain(params(w)).collect()
}

/// The body's values in blob order (format version 4): the mass, the motor time constant
/// `tau`, the port terms (the identity), then every parameter.
pub fn body_values_tau(w: &ModelWeights, tau: f32) -> Vec<f32> {
    body_values_port(w, tau, &PortTerms::IDENTITY)
}

/// The format-4 body with the port terms `port`.
pub fn body_values_port(w: &ModelWeights, tau: f32, port: &PortTerms) -> Vec<f32> {
    [w.mass_kg, tau]
        .into_iter()
        .chain(port.to_array())
        .chain(params(w))
        .collect()
}

/// The format-3 body: the mass, the motor lag, every parameter (no port terms).
pub fn body_values_v3(w: &ModelWeights, tau: f32) -> Vec<f32> {
    [w.mass_kg, tau].into_iter().chain(params(w)).collect()
}

/// A random valid motor lag (s).
#[cfg_attr(not(feature = "std"), allow(dead_code))]
pub fn random_tau(seed: u64) -> f32 {
    let unit = (SplitMix64(seed ^ 0x7A0).next_u64() >> 40) as f32 / (1u64 << 24) as f32;
    unit * MAX_MOTOR_TAU_S
}

/// Weights with every parameter a random finite f32 bit pattern (including ±0, subnormals and
/// extreme magnitudes), so a round trip that is merely "close" fails, and a random valid mass.
pub fn random_weights(seed: u64) -> ModelWeights {
    let mut rng = SplitMix64(seed);
    let mut w = ModelWeights::default();
    let unit = (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
    w.mass_kg = MIN_MASS_KG + unit * (MAX_MASS_KG - MIN_MASS_KG);
    for_each_param(&mut w, |v| {
        let mut x = f32::from_bits(rng.next_u64() as u32);
        while !x.is_finite() {
            x = f32::from_bits(rng.next_u64() as u32);
        }
        *v = x;
    });
    w
}

/// CRC-32/ISO-HDLC, bit by bit (independent of the codec's table).
pub fn crc32_reference(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A current-version blob from a raw body, following the documented layout.
pub fn blob_from_body(body: &[u8]) -> Vec<u8> {
    blob_from_body_version(4, body)
}

/// A blob of format `version` from a raw body, following the documented layout.
pub fn blob_from_body_version(version: u16, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(b"HMFW");
    out.extend_from_slice(&version.to_le_bytes());
    for shape in ModelWeights::DIMS {
        for d in shape {
            out.extend_from_slice(&d.to_le_bytes());
        }
    }
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(body);
    out.extend_from_slice(&crc32_reference(body).to_le_bytes());
    out
}

/// The documented encoding of `w` with the default motor lag.
pub fn encode_reference(w: &ModelWeights) -> Vec<u8> {
    encode_reference_tau(w, DEFAULT_MOTOR_TAU_S)
}

/// The documented encoding of `w` with the motor lag `tau` (s).
pub fn encode_reference_tau(w: &ModelWeights, tau: f32) -> Vec<u8> {
    let body: Vec<u8> = body_values_tau(w, tau)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    blob_from_body(&body)
}

pub fn assert_bitwise_eq(a: &ModelWeights, b: &ModelWeights) {
    let (pa, pb) = (body_values(a), body_values(b));
    assert_eq!(pa.len(), pb.len());
    for (n, (x, y)) in pa.iter().zip(pb.iter()).enumerate() {
        assert_eq!(x.to_bits(), y.to_bits(), "parameter {n}: {x:e} vs {y:e}");
    }
}
