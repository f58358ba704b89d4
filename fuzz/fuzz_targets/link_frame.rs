//! The link's frame decoder on arbitrary byte streams, both directions: it never panics, every
//! message it yields re-encodes to a frame that decodes to the same message, and after any
//! garbage and a delimiter a valid frame decodes.
//!
//! When the first byte is odd, the rest is taken as a postcard *payload* and framed correctly
//! (CRC-32, COBS, delimiter) first, so that the fuzzer reaches the message decoding behind the
//! checksum, which mutation alone almost never passes.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../../firmware/src/link.rs"]
mod link;

use link::{Downlink, FrameDecoder, Uplink, MAX_FRAME};

fn check<T>(data: &[u8])
where
    T: for<'de> serde::Deserialize<'de> + serde::Serialize + core::fmt::Debug,
{
    let mut dec = FrameDecoder::new();
    for &b in data {
        if let Some(Ok(msg)) = dec.push::<T>(b) {
            let mut buf = [0u8; MAX_FRAME];
            let n = link::encode(&msg, &mut buf).expect("a decoded message fits a frame");
            let mut again = FrameDecoder::new();
            let back: Vec<_> = buf[..n]
                .iter()
                .filter_map(|&b| again.push::<T>(b))
                .collect();
            assert_eq!(back.len(), 1);
            let back = back
                .into_iter()
                .next()
                .and_then(Result::ok)
                .expect("re-decodes");
            let (mut x, mut y) = ([0u8; MAX_FRAME], [0u8; MAX_FRAME]);
            assert_eq!(
                postcard::to_slice(&msg, &mut x).map(|s| s.to_vec()),
                postcard::to_slice(&back, &mut y).map(|s| s.to_vec())
            );
        }
    }
    // Resynchronisation: a delimiter, then a valid frame.
    let mut buf = [0u8; MAX_FRAME];
    let n = link::encode(&Uplink::Hello, &mut buf).expect("fits");
    let _ = dec.push::<Uplink>(0);
    let out: Vec<_> = buf[..n]
        .iter()
        .filter_map(|&b| dec.push::<Uplink>(b))
        .collect();
    assert!(matches!(out.as_slice(), [Ok(Uplink::Hello)]), "{out:?}");
}

/// `payload ‖ crc32` COBS-encoded and delimited, as link::encode frames a message.
fn frame(payload: &[u8]) -> Vec<u8> {
    let mut raw = payload.to_vec();
    raw.extend_from_slice(&hamflight::blob::crc32(payload).to_le_bytes());
    let mut out = vec![0u8; raw.len() + raw.len() / 254 + 2];
    let n = cobs::try_encode(&raw, &mut out).expect("sized for the worst case");
    out.truncate(n);
    out.push(0);
    out
}

fuzz_target!(|input: &[u8]| {
    let framed;
    let data = match input.split_first() {
        Some((mode, payload)) if mode & 1 == 1 => {
            framed = frame(payload);
            &framed[..]
        }
        _ => input,
    };
    check::<Uplink>(data);
    check::<Downlink>(data);
});
