//! Tests for `hamflight::blob`: exact round trips, and rejection with the right error of
//! every single-byte corruption, every truncation and any appended bytes of a valid blob.
//!
//! The blobs here are written by an independent encoder that follows the documented layout
//! byte by byte (header, parameters as little-endian f32 layer by layer, CRC-32 computed
//! bit-serially), so a layout change in the codec shows up as a failure rather than a silent
//! agreement with itself.

mod common;

use common::SplitMix64;
use hamflight::blob::{
    check, decode, decode_into, decode_model_into, BlobError, CRC_LEN, FORMAT_VERSION, HEADER_LEN,
    MAGIC,
};
use hamflight::model::{
    DisturbanceNet, GainNet, HamiltonianModel, InertiaNet, LearnedModel, ModelWeights, PortError,
    PortTerms, DEFAULT_MOTOR_TAU_S, MASS_KG, MAX_MASS_KG, MAX_MOTOR_TAU_S, MIN_MASS_KG,
    PORT_PARAMS,
};
use hamflight::nn::{Dense, Mlp};
use proptest::prelude::*;

/// Calls `f` on every parameter of `w`, in blob order: J⁻¹, g, W networks; within a network the
/// layers in order; within a layer the weights row by row (`weight[o][i]`), then the biases.
fn for_each_param(w: &mut ModelWeights, mut f: impl FnMut(&mut f32)) {
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

fn params(w: &ModelWeights) -> Vec<f32> {
    let mut w = *w;
    let mut out = Vec::new();
    for_each_param(&mut w, |v| out.push(*v));
    out
}

/// What [`decode`] gives, in blob order: the mass, then every parameter.
fn body_values(w: &ModelWeights) -> Vec<f32> {
    [w.mass_kg].into_iter().chain(params(w)).collect()
}

/// The body's values in blob order (format version 4): the mass, the motor time constant
/// `tau`, the port terms (the identity), then every parameter.
fn body_values_tau(w: &ModelWeights, tau: f32) -> Vec<f32> {
    body_values_port(w, tau, &PortTerms::IDENTITY)
}

/// The format-4 body with the port terms `port`.
fn body_values_port(w: &ModelWeights, tau: f32, port: &PortTerms) -> Vec<f32> {
    [w.mass_kg, tau]
        .into_iter()
        .chain(port.to_array())
        .chain(params(w))
        .collect()
}

/// The format-3 body: the mass, the motor lag, every parameter (no port terms).
fn body_values_v3(w: &ModelWeights, tau: f32) -> Vec<f32> {
    [w.mass_kg, tau].into_iter().chain(params(w)).collect()
}

/// A random valid motor lag (s).
#[cfg_attr(not(feature = "std"), allow(dead_code))]
fn random_tau(seed: u64) -> f32 {
    let unit = (SplitMix64(seed ^ 0x7A0).next_u64() >> 40) as f32 / (1u64 << 24) as f32;
    unit * MAX_MOTOR_TAU_S
}

/// Weights with every parameter a random finite f32 bit pattern (including ±0, subnormals and
/// extreme magnitudes), so a round trip that is merely "close" fails, and a random valid mass.
fn random_weights(seed: u64) -> ModelWeights {
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
fn crc32_reference(data: &[u8]) -> u32 {
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
fn blob_from_body(body: &[u8]) -> Vec<u8> {
    blob_from_body_version(4, body)
}

/// A blob of format `version` from a raw body, following the documented layout.
fn blob_from_body_version(version: u16, body: &[u8]) -> Vec<u8> {
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
fn encode_reference(w: &ModelWeights) -> Vec<u8> {
    encode_reference_tau(w, DEFAULT_MOTOR_TAU_S)
}

/// The documented encoding of `w` with the motor lag `tau` (s).
fn encode_reference_tau(w: &ModelWeights, tau: f32) -> Vec<u8> {
    let body: Vec<u8> = body_values_tau(w, tau)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    blob_from_body(&body)
}

fn assert_bitwise_eq(a: &ModelWeights, b: &ModelWeights) {
    let (pa, pb) = (body_values(a), body_values(b));
    assert_eq!(pa.len(), pb.len());
    for (n, (x, y)) in pa.iter().zip(pb.iter()).enumerate() {
        assert_eq!(x.to_bits(), y.to_bits(), "parameter {n}: {x:e} vs {y:e}");
    }
}

/// The error a single-byte corruption at `pos` (XOR `mask`) of the valid `blob` must produce.
fn expected_error(blob: &[u8], pos: usize, mask: u8) -> BlobError {
    let body_len = blob.len() - HEADER_LEN - CRC_LEN;
    match pos {
        0..4 => BlobError::BadMagic,
        4..6 => {
            let mut v = FORMAT_VERSION.to_le_bytes();
            v[pos - 4] ^= mask;
            match u16::from_le_bytes(v) {
                // Versions 1 to 3 would read the mass, the motor lag or the port terms as
                // parameters: values too many.
                1..=3 => BlobError::Malformed,
                v => BlobError::UnsupportedVersion(v),
            }
        }
        6..24 => BlobError::ShapeMismatch,
        24..28 => {
            let new_len = body_len ^ ((mask as usize) << (8 * (pos - 24)));
            if new_len > body_len {
                BlobError::Truncated
            } else {
                BlobError::TrailingBytes
            }
        }
        // The body and the stored CRC: CRC-32 detects every error burst of up to 32 bits.
        _ => BlobError::Checksum,
    }
}

#[test]
fn layout_constants_match_the_documentation() {
    assert_eq!(MAGIC, *b"HMFW");
    assert_eq!(FORMAT_VERSION, 4);
    assert_eq!(PORT_PARAMS, 27);
    assert_eq!(HEADER_LEN, 28);
    assert_eq!(CRC_LEN, 4);
    let blob = encode_reference(&ModelWeights::default());
    assert_eq!(
        blob.len(),
        HEADER_LEN + 4 + 4 + 4 * PORT_PARAMS + 4 * params(&ModelWeights::default()).len() + CRC_LEN
    );
    assert_eq!(ModelWeights::default().mass_kg, MASS_KG);
    // The decode target stays all-zero bits, the model around it too (a `static` of it lives in
    // .bss, not in flash), and reads as the default motor lag.
    let zero = LearnedModel::new(ModelWeights::ZERO);
    // SAFETY: LearnedModel is plain f32 and u32 fields (no padding, no pointers); its bytes are
    // read, not written.
    let bytes = unsafe {
        std::slice::from_raw_parts(
            (&zero as *const LearnedModel).cast::<u8>(),
            std::mem::size_of::<LearnedModel>(),
        )
    };
    assert!(bytes.iter().all(|b| *b == 0));
    assert_eq!(zero.motor_tau_s(), DEFAULT_MOTOR_TAU_S);
    // The motor lag is the body's second value.
    let blob = encode_reference_tau(&ModelWeights::default(), 0.02);
    assert_eq!(blob[HEADER_LEN + 4..HEADER_LEN + 8], 0.02f32.to_le_bytes());
    let m = LearnedModel::from_blob(&blob).expect("valid blob");
    assert_eq!(m.motor_tau_s().to_bits(), 0.02f32.to_bits());
    assert_eq!(crc32_reference(b"123456789"), 0xCBF4_3926);
    assert_eq!(
        hamflight::blob::crc32(b"123456789"),
        crc32_reference(b"123456789")
    );
}

#[test]
fn default_weights_round_trip() {
    let w = ModelWeights::default();
    assert_bitwise_eq(&decode(&encode_reference(&w)).expect("valid blob"), &w);
}

/// `blob::encode` exists with the `std` feature (the workspace build enables it via host-train).
#[cfg(feature = "std")]
#[test]
fn encoder_writes_the_documented_layout() {
    for seed in 0..4 {
        let w = random_weights(seed);
        let blob = hamflight::blob::encode(&w);
        assert_eq!(blob, encode_reference(&w), "seed {seed}");
        assert_bitwise_eq(&decode(&blob).expect("valid blob"), &w);
        let tau = random_tau(seed);
        let model = LearnedModel::new(w).with_motor_tau_s(tau);
        let blob = hamflight::blob::encode_model(&model);
        assert_eq!(blob, encode_reference_tau(&w, tau), "seed {seed}");
        assert_eq!(LearnedModel::from_blob(&blob), Ok(model), "seed {seed}");
    }
}

#[test]
fn every_single_byte_corruption_is_rejected_by_position() {
    let mut blob = encode_reference(&random_weights(7));
    let original = blob.clone();
    assert!(decode(&blob).is_ok());
    for pos in 0..blob.len() {
        for mask in [0x01u8, 0x80, 0xFF, 0x5A] {
            blob[pos] ^= mask;
            let got = decode(&blob);
            let want = expected_error(&original, pos, mask);
            assert_eq!(
                got.err(),
                Some(want),
                "byte {pos} ^ {mask:#04x} of {}",
                blob.len()
            );
            blob[pos] ^= mask;
        }
    }
    assert_eq!(blob, original);
}

#[test]
fn every_truncation_is_rejected() {
    let blob = encode_reference(&random_weights(11));
    for n in 0..blob.len() {
        assert_eq!(
            decode(&blob[..n]).err(),
            Some(BlobError::Truncated),
            "first {n} of {} bytes",
            blob.len()
        );
    }
}

#[test]
fn appended_bytes_are_rejected() {
    let blob = encode_reference(&random_weights(13));
    for extra in [&[0u8][..], &[0xFF], &[1, 2, 3, 4], &[0; 64]] {
        let mut longer = blob.clone();
        longer.extend_from_slice(extra);
        assert_eq!(
            decode(&longer).err(),
            Some(BlobError::TrailingBytes),
            "{} extra bytes",
            extra.len()
        );
    }
    // Two valid blobs back to back are not one valid blob.
    let twice = [blob.clone(), blob].concat();
    assert_eq!(decode(&twice).err(), Some(BlobError::TrailingBytes));
}

#[test]
fn non_finite_parameter_with_valid_checksum_is_rejected() {
    let n = params(&ModelWeights::default()).len();
    for bad in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        // The first and last parameter, and the first of each later network.
        let starts = [
            0,
            InertiaNet::PARAMS,
            InertiaNet::PARAMS + GainNet::PARAMS,
            n - 1,
        ];
        for target in starts {
            let mut w = random_weights(17);
            let mut k = 0;
            for_each_param(&mut w, |v| {
                if k == target {
                    *v = bad;
                }
                k += 1;
            });
            let blob = encode_reference(&w);
            assert_eq!(
                decode(&blob).err(),
                Some(BlobError::NonFinite),
                "{bad} at parameter {target}"
            );
        }
    }
}

#[test]
fn mass_outside_the_documented_range_is_rejected() {
    for bad in [0.0, -0.027, MIN_MASS_KG * 0.99, MAX_MASS_KG * 1.01, 1e30] {
        let w = ModelWeights {
            mass_kg: bad,
            ..random_weights(23)
        };
        assert_eq!(
            decode(&encode_reference(&w)).err(),
            Some(BlobError::BadMass),
            "{bad} kg"
        );
    }
    for bad in [f32::NAN, f32::INFINITY] {
        let w = ModelWeights {
            mass_kg: bad,
            ..random_weights(23)
        };
        assert_eq!(
            decode(&encode_reference(&w)).err(),
            Some(BlobError::NonFinite)
        );
    }
    for ok in [MIN_MASS_KG, 0.034, MAX_MASS_KG] {
        let w = ModelWeights {
            mass_kg: ok,
            ..random_weights(23)
        };
        assert_eq!(decode(&encode_reference(&w)).map(|d| d.mass_kg), Ok(ok));
    }
}

#[test]
fn motor_lag_outside_the_documented_range_is_rejected() {
    let w = random_weights(31);
    for bad in [-1e-6, -0.02, MAX_MOTOR_TAU_S * 1.01, 1e30] {
        assert_eq!(
            decode(&encode_reference_tau(&w, bad)).err(),
            Some(BlobError::BadMotorTau),
            "{bad} s"
        );
    }
    for bad in [f32::NAN, f32::NEG_INFINITY] {
        assert_eq!(
            decode(&encode_reference_tau(&w, bad)).err(),
            Some(BlobError::NonFinite)
        );
    }
    for ok in [0.0, 0.02, 0.072, MAX_MOTOR_TAU_S] {
        let m = LearnedModel::from_blob(&encode_reference_tau(&w, ok));
        assert_eq!(m.map(|m| m.motor_tau_s()), Ok(ok));
    }
}

/// A version-1 blob (no mass in its body) still loads, as the stock vehicle it was trained for,
/// with the motor lag every model assumed then.
#[test]
fn version_1_blob_is_migrated_to_the_stock_mass() {
    let w = ModelWeights {
        mass_kg: 0.034,
        ..random_weights(29)
    };
    let body: Vec<u8> = params(&w).iter().flat_map(|v| v.to_le_bytes()).collect();
    let v1 = blob_from_body_version(1, &body);
    let got = LearnedModel::from_blob(&v1).expect("version 1 decodes");
    assert_eq!(got.weights.mass_kg, MASS_KG);
    assert_eq!(got.motor_tau_s(), DEFAULT_MOTOR_TAU_S);
    assert_eq!(params(&got.weights), params(&w));
    // A version-1 header over a version-3 body has two values too many.
    let v3_body = &encode_reference_tau(&w, 0.02)[HEADER_LEN..][..body.len() + 8];
    assert_eq!(
        decode(&blob_from_body_version(1, v3_body)).err(),
        Some(BlobError::Malformed)
    );
}

/// A version-2 blob (the mass, no motor lag) loads with its mass and the default lag, the one
/// the composite law assumed for every model before the lag was data.
#[test]
fn version_2_blob_is_migrated_to_the_default_motor_lag() {
    let w = ModelWeights {
        mass_kg: 0.034,
        ..random_weights(37)
    };
    let body: Vec<u8> = body_values(&w)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let got = LearnedModel::from_blob(&blob_from_body_version(2, &body)).expect("version 2");
    assert_eq!(got.weights.mass_kg, 0.034);
    assert_eq!(got.motor_tau_s(), DEFAULT_MOTOR_TAU_S);
    assert_eq!(params(&got.weights), params(&w));
    // A version-2 header over a version-3 body has one value too many, and a version-3 header
    // over a version-2 body one too few.
    let v3_body = &encode_reference_tau(&w, 0.02)[HEADER_LEN..][..body.len() + 4];
    assert_eq!(
        decode(&blob_from_body_version(2, v3_body)).err(),
        Some(BlobError::Malformed)
    );
    assert_eq!(
        decode(&blob_from_body_version(3, &body)).err(),
        Some(BlobError::Malformed)
    );
}

#[test]
fn body_that_is_not_the_networks_is_malformed() {
    let blob = encode_reference(&random_weights(19));
    let body = &blob[HEADER_LEN..blob.len() - CRC_LEN];
    // Consistent length and checksum, but too few or too many parameters.
    for cut in [1, 3, 4, body.len()] {
        let short = blob_from_body(&body[..body.len() - cut]);
        assert_eq!(
            decode(&short).err(),
            Some(BlobError::Malformed),
            "{cut} bytes short"
        );
    }
    for extra in [1, 4] {
        let long = blob_from_body(&[body, &vec![0u8; extra]].concat());
        assert_eq!(
            decode(&long).err(),
            Some(BlobError::Malformed),
            "{extra} bytes long"
        );
    }
}

#[test]
fn header_checks_come_in_file_order() {
    assert_eq!(decode(&[]).err(), Some(BlobError::Truncated));
    assert_eq!(decode(b"HMF").err(), Some(BlobError::Truncated));
    assert_eq!(decode(b"XXXX").err(), Some(BlobError::BadMagic));
    assert_eq!(decode(b"HMFW").err(), Some(BlobError::Truncated));
    assert_eq!(
        decode(b"HMFW\x05\x00").err(),
        Some(BlobError::UnsupportedVersion(5))
    );
    assert_eq!(
        decode(b"HMFW\x00\x00").err(),
        Some(BlobError::UnsupportedVersion(0))
    );
    let blob = encode_reference(&ModelWeights::default());
    // Wrong version and wrong shapes: the version is reported.
    let mut both = blob.clone();
    both[4] = 9;
    both[6] ^= 1;
    assert_eq!(decode(&both).err(), Some(BlobError::UnsupportedVersion(9)));
    // A huge declared body length neither overflows nor panics.
    let mut huge = blob.clone();
    huge[24..28].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(decode(&huge).err(), Some(BlobError::Truncated));
    let mut zero = blob;
    zero[24..28].copy_from_slice(&0u32.to_le_bytes());
    assert_eq!(decode(&zero).err(), Some(BlobError::TrailingBytes));
}

#[test]
fn every_error_has_display_text() {
    let all = [
        BlobError::Truncated,
        BlobError::BadMagic,
        BlobError::UnsupportedVersion(7),
        BlobError::ShapeMismatch,
        BlobError::Checksum,
        BlobError::TrailingBytes,
        BlobError::Malformed,
        BlobError::NonFinite,
        BlobError::BadMass,
        BlobError::BadMotorTau,
    ];
    let texts: Vec<String> = all.iter().map(|e| e.to_string()).collect();
    for (e, t) in all.iter().zip(&texts) {
        assert!(!t.trim().is_empty(), "{e:?} has no text");
        let as_error: &dyn core::error::Error = e;
        assert_eq!(as_error.to_string(), *t);
    }
    assert!(texts[2].contains('7'), "the version is named: {}", texts[2]);
    let mut unique = texts.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), texts.len(), "each variant has its own text");
}

/// The documented checks, written again from the layout table (not from the codec): the
/// oracle of the randomized tests below. Returns the parameters on success.
fn decode_reference(b: &[u8]) -> Result<Vec<f32>, BlobError> {
    if b.len() < 4 {
        return Err(BlobError::Truncated);
    }
    if b[..4] != *b"HMFW" {
        return Err(BlobError::BadMagic);
    }
    if b.len() < 6 {
        return Err(BlobError::Truncated);
    }
    let version = u16::from_le_bytes([b[4], b[5]]);
    if !(1..=4).contains(&version) {
        return Err(BlobError::UnsupportedVersion(version));
    }
    if b.len() < 24 {
        return Err(BlobError::Truncated);
    }
    let shapes: Vec<u8> = ModelWeights::DIMS
        .iter()
        .flatten()
        .flat_map(|d| d.to_le_bytes())
        .collect();
    if b[6..24] != shapes[..] {
        return Err(BlobError::ShapeMismatch);
    }
    if b.len() < 28 {
        return Err(BlobError::Truncated);
    }
    let body_len = u32::from_le_bytes([b[24], b[25], b[26], b[27]]) as u64;
    let total = 28 + body_len + 4;
    if (b.len() as u64) < total {
        return Err(BlobError::Truncated);
    }
    if (b.len() as u64) > total {
        return Err(BlobError::TrailingBytes);
    }
    let body = &b[28..b.len() - 4];
    let crc = u32::from_le_bytes([
        b[b.len() - 4],
        b[b.len() - 3],
        b[b.len() - 2],
        b[b.len() - 1],
    ]);
    if crc32_reference(body) != crc {
        return Err(BlobError::Checksum);
    }
    // Version 4: the mass, the motor lag, the 27 port terms, then the parameters; version 3:
    // the mass, the motor lag, then the parameters; version 2: the mass, then the parameters
    // (the default lag); version 1: the parameters (the stock mass, the default lag).
    let extra = match version {
        4 => 2 + 27,
        v => usize::from(v) - 1,
    };
    let n = params(&ModelWeights::default()).len() + extra;
    if body.len() != 4 * n {
        return Err(BlobError::Malformed);
    }
    let mut port: Vec<f32> = Vec::new();
    let mut stored = body
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    let values: Vec<f32> = match version {
        1 => [MASS_KG, DEFAULT_MOTOR_TAU_S]
            .into_iter()
            .chain(stored)
            .collect(),
        2 => {
            let mass = stored.next().unwrap_or(f32::NAN);
            [mass, DEFAULT_MOTOR_TAU_S]
                .into_iter()
                .chain(stored)
                .collect()
        }
        3 => stored.collect(),
        _ => {
            let all: Vec<f32> = stored.collect();
            port = all[2..29].to_vec();
            all[..2].iter().chain(&all[29..]).copied().collect()
        }
    };
    if values.iter().chain(&port).any(|v| !v.is_finite()) {
        return Err(BlobError::NonFinite);
    }
    if !(MIN_MASS_KG..=MAX_MASS_KG).contains(&values[0]) {
        return Err(BlobError::BadMass);
    }
    if !(0.0..=MAX_MOTOR_TAU_S).contains(&values[1]) {
        return Err(BlobError::BadMotorTau);
    }
    if !port.is_empty() {
        // The documented order: gain offsets (4), lags (2), drag (3), rate damping (3), …
        if port[..4]
            .iter()
            .any(|k| !(0.02..=50.0).contains(&(1.0 + k)))
        {
            return Err(BlobError::BadPort(PortError::BadGain));
        }
        if port[4..6].iter().any(|t| !(0.0..=1.0).contains(t)) {
            return Err(BlobError::BadPort(PortError::BadLag));
        }
        if port[6..12].iter().any(|d| *d < 0.0) {
            return Err(BlobError::BadPort(PortError::NegativeDissipation));
        }
    }
    Ok(values)
}

/// One random edit of a blob: flip, set, insert, delete, truncate, duplicate a range, or splice
/// in a header field's worth of random bytes. Some edits are fixed up afterwards (length and
/// CRC recomputed), so that the deeper checks are reached too.
fn mutate(rng: &mut SplitMix64, blob: &mut Vec<u8>) {
    let len = blob.len().max(1);
    let pos = (rng.next_u64() as usize) % len;
    let byte = rng.next_u64() as u8;
    match rng.next_u64() % 8 {
        0 => {
            if let Some(b) = blob.get_mut(pos) {
                *b ^= 1 << (byte % 8);
            }
        }
        1 => {
            if let Some(b) = blob.get_mut(pos) {
                *b = byte;
            }
        }
        2 => blob.insert(pos.min(blob.len()), byte),
        3 => {
            if pos < blob.len() {
                blob.remove(pos);
            }
        }
        4 => blob.truncate(pos),
        5 => {
            let end = (pos + 1 + (rng.next_u64() as usize) % 16).min(blob.len());
            let chunk = blob.get(pos..end).map(<[u8]>::to_vec).unwrap_or_default();
            let at = (rng.next_u64() as usize) % (blob.len() + 1);
            blob.splice(at..at, chunk);
        }
        6 => {
            // A body edit behind a consistent length and CRC: reaches Malformed / NonFinite.
            if blob.len() >= HEADER_LEN + CRC_LEN {
                let mut body = blob[HEADER_LEN..blob.len() - CRC_LEN].to_vec();
                let k = 4 * ((rng.next_u64() as usize) % (body.len() / 4).max(1));
                match byte % 4 {
                    0 => body.truncate((rng.next_u64() as usize) % (body.len() + 1)),
                    1 => body.push(byte),
                    2 => {
                        // Another finite value: still a valid blob.
                        let v = (rng.next_u64() as u32 as f32).to_le_bytes();
                        for (d, s) in body.iter_mut().skip(k).zip(v) {
                            *d = s;
                        }
                    }
                    _ => {
                        // A NaN or infinity (exponent all ones) at a random parameter.
                        if let Some(b) = body.get_mut(k + 3) {
                            *b |= 0x7F;
                        }
                        if let Some(b) = body.get_mut(k + 2) {
                            *b |= 0x80;
                        }
                    }
                }
                let mut fixed = blob[..24].to_vec();
                fixed.extend_from_slice(&(body.len() as u32).to_le_bytes());
                fixed.extend_from_slice(&body);
                fixed.extend_from_slice(&crc32_reference(&body).to_le_bytes());
                *blob = fixed;
            }
        }
        _ => {
            // Random bytes over a header field (version, shapes or length).
            let at = 4 + (rng.next_u64() as usize) % 24;
            for k in at..(at + 1 + (byte % 4) as usize).min(blob.len()) {
                blob[k] = rng.next_u64() as u8;
            }
        }
    }
}

/// The stable-toolchain counterpart of `fuzz/fuzz_targets/blob.rs`, run by the README's test
/// command: 20,000 seeded mutants of valid blobs (1–6 edits each) and 5,000 random byte
/// strings. Neither decoder panics, both give the oracle's result (the same error, or the same
/// parameters bit for bit), and `decode_into` leaves its output untouched on error.
#[test]
fn randomized_mutants_get_the_documented_result() {
    let mut rng = SplitMix64(0x5EED_B10B);
    let valid = encode_reference(&random_weights(23));
    let sentinel = random_weights(29);
    let mut seen = std::collections::BTreeMap::<String, u32>::new();
    for case in 0..25_000u32 {
        let bytes = if case < 20_000 {
            let mut b = valid.clone();
            for _ in 0..=(rng.next_u64() % 6) {
                mutate(&mut rng, &mut b);
            }
            b
        } else {
            let n = (rng.next_u64() % 96) as usize;
            let mut b: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
            if rng.next_u64().is_multiple_of(2) && b.len() >= 4 {
                b[..4].copy_from_slice(b"HMFW");
            }
            b
        };
        let want = decode_reference(&bytes);
        // What `decode` gives: the values without the motor lag (the body's second).
        let want_weights = want.clone().map(|v| {
            v.iter()
                .enumerate()
                .filter(|(k, _)| *k != 1)
                .map(|(_, x)| x.to_bits())
                .collect::<Vec<u32>>()
        });
        let mut out = sentinel;
        let got = decode_into(&bytes, &mut out);
        let mut model = LearnedModel::new(sentinel).with_motor_tau_s(0.123);
        let got_model = decode_model_into(&bytes, &mut model);
        assert_eq!(got_model, got, "case {case}");
        match &want {
            Ok(values) => {
                assert_eq!(got, Ok(()), "case {case}");
                let bits: Vec<u32> = body_values(&out).iter().map(|v| v.to_bits()).collect();
                assert_eq!(Ok(bits), want_weights, "case {case}");
                assert_eq!(model.weights, out, "case {case}");
                assert_eq!(
                    model.motor_tau_s().to_bits(),
                    values[1].to_bits(),
                    "case {case}"
                );
            }
            Err(e) => {
                assert_eq!(got, Err(*e), "case {case}: {} bytes", bytes.len());
                assert_bitwise_eq(&out, &sentinel);
                assert_bitwise_eq(&model.weights, &sentinel);
                assert_eq!(model.motor_tau_s(), 0.123);
            }
        }
        assert_eq!(
            decode(&bytes).map(|w| body_values(&w)
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()),
            want_weights,
            "case {case}"
        );
        let key = match got {
            Ok(()) => "ok".to_string(),
            Err(e) => format!("{e:?}").split('(').next().unwrap_or("").to_string(),
        };
        *seen.entry(key).or_default() += 1;
    }
    // Every outcome was reached, so the mutants exercise every check.
    for key in [
        "ok",
        "Truncated",
        "BadMagic",
        "UnsupportedVersion",
        "ShapeMismatch",
        "Checksum",
        "TrailingBytes",
        "Malformed",
        "NonFinite",
    ] {
        assert!(
            seen.get(key).copied().unwrap_or(0) > 0,
            "{key} never reached: {seen:?}"
        );
    }
}

/// `decode_into` reads the body as postcard does (the documented layout is postcard's encoding
/// of the networks), on random weights and on the shipped blob.
#[test]
fn decode_into_agrees_with_postcard() {
    let shipped = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/weights/default.hfw"));
    let mut blobs: Vec<Vec<u8>> = (0..8)
        .map(|s| encode_reference(&random_weights(s)))
        .collect();
    blobs.extend(shipped.ok());
    for blob in &blobs {
        let body = &blob[HEADER_LEN..blob.len() - CRC_LEN];
        let (mass_kg, tau, _port, inertia, gain, disturbance): (
            f32,
            f32,
            [f32; PORT_PARAMS],
            InertiaNet,
            GainNet,
            DisturbanceNet,
        ) = postcard::from_bytes(body).expect("postcard body");
        let by_postcard = ModelWeights {
            mass_kg,
            inertia,
            gain,
            disturbance,
        };
        let mut in_place = LearnedModel::new(ModelWeights::ZERO);
        decode_model_into(blob, &mut in_place).expect("valid blob");
        assert_bitwise_eq(&in_place.weights, &by_postcard);
        assert_eq!(in_place.motor_tau_s().to_bits(), tau.to_bits());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn round_trip_is_bitwise_exact(seed in any::<u64>()) {
        let w = random_weights(seed);
        let decoded = decode(&encode_reference(&w)).expect("valid blob");
        assert_bitwise_eq(&decoded, &w);
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
        prop_assert!(decode(&bytes).is_err());
        // The same bytes behind a valid header prefix.
        let mut with_header = encode_reference(&ModelWeights::default())[..24].to_vec();
        with_header.extend_from_slice(&bytes);
        prop_assert!(decode(&with_header).is_err());
    }
}

#[test]
fn blob_error_text_names_the_range() {
    let text = BlobError::BadMass.to_string();
    assert!(
        text.contains(&format!("{MIN_MASS_KG}..={MAX_MASS_KG} kg")),
        "{text}"
    );
    let text = BlobError::BadMotorTau.to_string();
    assert!(text.contains(&format!("0..={MAX_MOTOR_TAU_S} s")), "{text}");
}

/// A version-3 blob (the mass and the motor lag, no port terms) loads as the rigid body alone.
#[test]
fn version_3_blob_is_migrated_to_the_rigid_body() {
    let w = ModelWeights {
        mass_kg: 0.045,
        ..random_weights(41)
    };
    let body: Vec<u8> = body_values_v3(&w, 0.0325)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let got = LearnedModel::from_blob(&blob_from_body_version(3, &body)).expect("version 3");
    assert_eq!(got.weights.mass_kg, 0.045);
    assert_eq!(got.motor_tau_s(), 0.0325);
    assert_eq!(*got.port(), PortTerms::IDENTITY);
    assert_eq!(params(&got.weights), params(&w));
    // A version-4 header over a version-3 body is 27 values short.
    assert_eq!(
        decode(&blob_from_body_version(4, &body)).err(),
        Some(BlobError::Malformed)
    );
}

/// A non-trivial set of port terms that passes its checks.
fn sample_port() -> PortTerms {
    let mut t = PortTerms::from_array(&core::array::from_fn(|i| 1e-4 * (i as f32 + 1.0)));
    t.thrust_gain_offset = 0.004;
    t.torque_gain_offset = [-0.88, -0.94, -0.76];
    t.thrust_lag_s = 0.048;
    t.torque_lag_s = 0.054;
    t
}

/// The port terms round-trip through the documented layout, and terms that cannot fly are
/// refused with their reason even under a valid checksum.
#[test]
fn port_terms_round_trip_and_are_checked() {
    let w = random_weights(43);
    let port = sample_port();
    let body: Vec<u8> = body_values_port(&w, 0.03, &port)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let got = LearnedModel::from_blob(&blob_from_body(&body)).expect("valid port terms");
    assert_eq!(*got.port(), port);
    assert_eq!(check(&blob_from_body(&body)).map(|i| i.port), Ok(port));
    #[cfg(feature = "std")]
    assert_eq!(hamflight::blob::encode_model(&got), blob_from_body(&body));
    let bad = |f: &dyn Fn(&mut PortTerms)| {
        let mut p = port;
        f(&mut p);
        let body: Vec<u8> = body_values_port(&w, 0.03, &p)
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        decode(&blob_from_body(&body)).err()
    };
    assert_eq!(
        bad(&|p| p.rate_damping_nm_s[2] = -1e-6),
        Some(BlobError::BadPort(PortError::NegativeDissipation))
    );
    assert_eq!(
        bad(&|p| p.torque_gain_offset[0] = -1.0),
        Some(BlobError::BadPort(PortError::BadGain))
    );
    assert_eq!(
        bad(&|p| p.thrust_lag_s = 1.5),
        Some(BlobError::BadPort(PortError::BadLag))
    );
    // A NaN anywhere in the body is a non-finite parameter first.
    assert_eq!(
        bad(&|p| p.gyrator_nm_s_m[1][2] = f32::NAN),
        Some(BlobError::NonFinite)
    );
}
