//! Tests for `hamflight::blob` on malformed bytes: rejection with the right error of every
//! single-byte corruption, every truncation and any appended bytes of a valid blob, of bodies
//! and headers that are wrong, and of randomized mutants (against an independent oracle); and
//! `decode_into` agrees with postcard.
//!
//! The blobs here are written by an independent encoder that follows the documented layout
//! byte by byte (header, parameters as little-endian f32 layer by layer, CRC-32 computed
//! bit-serially; `common/blob_ref.rs`), so a layout change in the codec shows up as a failure
//! rather than a silent agreement with itself.

mod common;

use common::blob_ref::{
    assert_bitwise_eq, blob_from_body, body_values, crc32_reference, encode_reference, params,
    random_weights,
};
use common::SplitMix64;
use hamflight::blob::{
    decode, decode_into, decode_model_into, BlobError, CRC_LEN, FORMAT_VERSION, HEADER_LEN,
};
use hamflight::model::{
    DisturbanceNet, GainNet, HamiltonianModel, InertiaNet, LearnedModel, ModelWeights, PortError,
    DEFAULT_MOTOR_TAU_S, MASS_KG, MAX_MASS_KG, MAX_MOTOR_TAU_S, MIN_MASS_KG, PORT_PARAMS,
};
use proptest::prelude::*;

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
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
        prop_assert!(decode(&bytes).is_err());
        // The same bytes behind a valid header prefix.
        let mut with_header = encode_reference(&ModelWeights::default())[..24].to_vec();
        with_header.extend_from_slice(&bytes);
        prop_assert!(decode(&with_header).is_err());
    }
}
