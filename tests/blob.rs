//! Tests for `hamflight::blob` (issue 2): exact round trips, and rejection with the right error of
//! every single-byte corruption, every truncation and any appended bytes of a valid blob.
//!
//! The blobs here are written by an independent encoder that follows the documented layout
//! byte by byte (header, parameters as little-endian f32 layer by layer, CRC-32 computed
//! bit-serially), so a layout change in the codec shows up as a failure rather than a silent
//! agreement with itself.

mod common;

use common::SplitMix64;
use hamflight::blob::{decode, BlobError, CRC_LEN, FORMAT_VERSION, HEADER_LEN, MAGIC};
use hamflight::model::{GainNet, InertiaNet, ModelWeights};
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

/// Weights with every parameter a random finite f32 bit pattern (including ±0, subnormals and
/// extreme magnitudes), so a round trip that is merely "close" fails.
fn random_weights(seed: u64) -> ModelWeights {
    let mut rng = SplitMix64(seed);
    let mut w = ModelWeights::default();
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

/// A blob from a raw body, following the documented layout.
fn blob_from_body(body: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(b"HMFW");
    out.extend_from_slice(&1u16.to_le_bytes());
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

/// The documented encoding of `w`.
fn encode_reference(w: &ModelWeights) -> Vec<u8> {
    let body: Vec<u8> = params(w).iter().flat_map(|v| v.to_le_bytes()).collect();
    blob_from_body(&body)
}

fn assert_bitwise_eq(a: &ModelWeights, b: &ModelWeights) {
    let (pa, pb) = (params(a), params(b));
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
            BlobError::UnsupportedVersion(u16::from_le_bytes(v))
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
    assert_eq!(FORMAT_VERSION, 1);
    assert_eq!(HEADER_LEN, 28);
    assert_eq!(CRC_LEN, 4);
    let blob = encode_reference(&ModelWeights::default());
    assert_eq!(
        blob.len(),
        HEADER_LEN + 4 * params(&ModelWeights::default()).len() + CRC_LEN
    );
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
        decode(b"HMFW\x02\x00").err(),
        Some(BlobError::UnsupportedVersion(2))
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
