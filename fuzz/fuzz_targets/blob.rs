//! The weight-blob decoder on arbitrary bytes: `decode_into` and `decode` never panic, agree
//! with each other, leave the output untouched on error, and on success give exactly postcard's
//! reading of the body.
//!
//! A mutated CRC-32 almost never matches, so a fuzzer alone rarely gets past the checksum: when
//! the first byte is odd, the rest is taken as a *body* and wrapped in a valid header (length,
//! CRC), which reaches the body checks (`Malformed`, `NonFinite`, success).
#![no_main]

use hamflight::blob::{decode, decode_into, CRC_LEN, HEADER_LEN};
use hamflight::model::ModelWeights;
use libfuzzer_sys::fuzz_target;

fn bits(w: &mut ModelWeights) -> Vec<u32> {
    w.params_mut().map(|v| v.to_bits()).collect()
}

/// `body` behind this build's header and its CRC.
fn wrap(body: &[u8]) -> Vec<u8> {
    let mut prefix = hamflight::blob::encode(&ModelWeights::ZERO);
    prefix.truncate(24);
    prefix.extend_from_slice(&(body.len() as u32).to_le_bytes());
    prefix.extend_from_slice(body);
    prefix.extend_from_slice(&hamflight::blob::crc32(body).to_le_bytes());
    prefix
}

fuzz_target!(|input: &[u8]| {
    let wrapped;
    let data = match input.split_first() {
        Some((mode, body)) if mode & 1 == 1 => {
            wrapped = wrap(body);
            &wrapped[..]
        }
        _ => input,
    };
    let mut sentinel = ModelWeights::ZERO;
    for (k, v) in sentinel.params_mut().enumerate() {
        *v = k as f32;
    }
    let mut out = sentinel;
    let got = decode_into(data, &mut out);
    let by_value = decode(data);
    match (&got, &by_value) {
        (Ok(()), Ok(w)) => {
            let mut w = *w;
            assert_eq!(bits(&mut out), bits(&mut w));
            let body = &data[HEADER_LEN..data.len() - CRC_LEN];
            let mut pc: ModelWeights = postcard::from_bytes(body).expect("postcard reads it too");
            assert_eq!(bits(&mut out), bits(&mut pc));
            assert!(out.is_finite());
        }
        (Err(a), Err(b)) => {
            assert_eq!(a, b);
            assert_eq!(
                bits(&mut out),
                bits(&mut sentinel),
                "output touched on error"
            );
        }
        _ => panic!("decode_into {got:?} but decode {:?}", by_value.map(|_| ())),
    }
});
