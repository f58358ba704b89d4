//! The link's framing (postcard ‖ CRC-32 ‖ COBS ‖ 0) against an independent reference: frame
//! bytes, and what the decoder makes of valid, corrupted, truncated and random streams.

use super::{decode_all, hover_input, random_uplink, SplitMix64};
use crate::link::{self, Downlink, FrameError, Telemetry, Uplink};

#[test]
fn frame_round_trip() {
    let msg = Uplink::Input(hover_input(42));
    let mut buf = [0u8; link::MAX_FRAME];
    let n = link::encode(&msg, &mut buf).unwrap();
    assert_eq!(buf[n - 1], 0);
    assert!(buf[..n - 1].iter().all(|&b| b != 0));
    let got = decode_all::<Uplink>(&buf[..n]);
    assert_eq!(got, vec![Ok(msg)]);
}

// ---- Reference framing, written from the COBS paper and the frame layout, independent of the
// `cobs` crate that link.rs uses: the oracle of the tests below. ----

/// COBS (Cheshire & Baker): each group is a code byte (1 + the non-zero bytes that follow, 0xFF
/// for a full group of 254 without an implied zero) and the bytes.
fn cobs_encode_reference(src: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    let mut code_at = 0;
    for &b in src {
        if b == 0 {
            out[code_at] = (out.len() - code_at) as u8;
            code_at = out.len();
            out.push(0);
        } else {
            out.push(b);
            if out.len() - code_at == 0xFF {
                out[code_at] = 0xFF;
                code_at = out.len();
                out.push(0);
            }
        }
    }
    out[code_at] = (out.len() - code_at) as u8;
    out
}

/// The inverse; `None` for a zero byte or a group running past the end.
fn cobs_decode_reference(enc: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let mut r = 0;
    while r < enc.len() {
        let code = enc[r] as usize;
        if code == 0 || r + code > enc.len() {
            return None;
        }
        let group = &enc[r + 1..r + code];
        if group.contains(&0) {
            return None;
        }
        out.extend_from_slice(group);
        r += code;
        if code != 0xFF && r < enc.len() {
            out.push(0);
        }
    }
    Some(out)
}

/// CRC-32/ISO-HDLC bit by bit.
fn crc32_reference(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= u32::from(b);
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

/// What the decoder must make of the bytes between two delimiters.
fn frame_reference<T: for<'de> serde::Deserialize<'de>>(
    frame: &[u8],
) -> Option<Result<T, FrameError>> {
    if frame.is_empty() {
        return None;
    }
    if frame.len() > link::MAX_FRAME {
        return Some(Err(FrameError::Overflow));
    }
    let Some(raw) = cobs_decode_reference(frame) else {
        return Some(Err(FrameError::Cobs));
    };
    if raw.len() < 4 {
        return Some(Err(FrameError::Crc));
    }
    let (body, crc) = raw.split_at(raw.len() - 4);
    if crc32_reference(body).to_le_bytes() != crc {
        return Some(Err(FrameError::Crc));
    }
    Some(postcard::from_bytes(body).map_err(|_| FrameError::Decode))
}

fn postcard_bytes<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    let mut buf = [0u8; 512];
    postcard::to_slice(msg, &mut buf).unwrap().to_vec()
}

/// The frame of `msg` by the reference: COBS(postcard ‖ CRC-32 LE) ‖ 0.
fn frame_by_reference<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    let mut raw = postcard_bytes(msg);
    let crc = crc32_reference(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut f = cobs_encode_reference(&raw);
    f.push(0);
    f
}

fn random_downlink(rng: &mut SplitMix64) -> Downlink {
    let word = |rng: &mut SplitMix64| rng.next_u64() as u32 >> rng.below(32);
    match rng.below(4) {
        0 => Downlink::Status(link::LinkStatus::WatchdogTripped),
        1 => Downlink::Report(link::Report {
            steps: word(rng),
            total_step_cost: rng.next_u64() >> rng.below(64),
            stack_peak_bytes: word(rng),
            ..link::Report::default()
        }),
        _ => Downlink::Telemetry(Telemetry {
            seq: word(rng),
            rpm: rng.f32s(),
            thrust_n: rng.f32s(),
            duty: [rng.next_u64() as u16; 4],
            a: rng.f32s(),
            faults: rng.next_u64() as u16,
            step_cost: word(rng),
            bad_frames: word(rng),
            watchdog_trips: word(rng),
        }),
    }
}

/// Bit-exact comparison of decoded messages (postcard re-encoding: f32 -0.0 vs 0.0 differ).
fn same<T: serde::Serialize>(a: &Result<T, FrameError>, b: &Result<T, FrameError>) -> bool {
    match (a, b) {
        (Ok(x), Ok(y)) => postcard_bytes(x) == postcard_bytes(y),
        (Err(x), Err(y)) => x == y,
        _ => false,
    }
}

#[test]
fn frames_are_byte_identical_to_the_reference_framing() {
    let mut rng = SplitMix64(1);
    let mut buf = [0u8; link::MAX_FRAME];
    for _ in 0..2000 {
        let up = random_uplink(&mut rng);
        let n = link::encode(&up, &mut buf).unwrap();
        assert_eq!(&buf[..n], &frame_by_reference(&up)[..], "{up:?}");
        let down = random_downlink(&mut rng);
        let n = link::encode(&down, &mut buf).unwrap();
        assert_eq!(&buf[..n], &frame_by_reference(&down)[..], "{down:?}");
    }
    // COBS edge cases: long runs without zeros (a full 254-byte group) and all zeros.
    for len in [0usize, 1, 253, 254, 255, 300] {
        for fill in [0u8, 1, 0xFF] {
            let src: Vec<u8> = (0..len)
                .map(|i| if i % 7 == 3 { 0 } else { fill })
                .collect();
            let mut enc = vec![0u8; len + len / 254 + 2];
            let n = cobs::try_encode(&src, &mut enc).unwrap();
            if len > 0 {
                assert_eq!(
                    &enc[..n],
                    &cobs_encode_reference(&src)[..],
                    "len {len} fill {fill}"
                );
            }
            assert_eq!(
                cobs_decode_reference(&cobs_encode_reference(&src)),
                Some(src)
            );
        }
    }
}

/// Feeds `stream` to a fresh decoder and to the reference; both must yield the same results in
/// the same order.
fn check_stream<T>(stream: &[u8]) -> usize
where
    T: for<'de> serde::Deserialize<'de> + serde::Serialize + core::fmt::Debug,
{
    let got = decode_all::<T>(stream);
    let want: Vec<Result<T, FrameError>> = stream
        .split(|&b| b == 0)
        .take(stream.split(|&b| b == 0).count() - 1) // bytes after the last delimiter wait
        .filter_map(frame_reference::<T>)
        .collect();
    assert_eq!(got.len(), want.len(), "{got:?}\n{want:?}");
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(same(g, w), "result {k}: {g:?} vs {w:?}");
    }
    got.len()
}

/// The stable-toolchain counterpart of `fuzz/fuzz_targets/link_frame.rs`, run by the README's
/// test command: 3,000 seeded streams of valid, corrupted, truncated, spliced and overlong
/// frames and random bytes, for both directions. The decoder never panics, yields exactly what
/// the reference framing says (message, or which error) in order, and resynchronises at every
/// delimiter.
#[test]
fn randomized_streams_decode_as_the_reference_says() {
    let mut rng = SplitMix64(0x11AC);
    let mut outcomes = [0usize; 5]; // ok, Overflow, Cobs, Crc, Decode
    for case in 0..3000 {
        let mut stream = Vec::new();
        for _ in 0..1 + rng.below(8) {
            let mut frame = if case % 2 == 0 {
                frame_by_reference(&random_uplink(&mut rng))
            } else {
                frame_by_reference(&random_downlink(&mut rng))
            };
            match rng.below(8) {
                0 | 1 => {} // intact
                2 => {
                    let k = rng.below(frame.len() - 1);
                    frame[k] ^= 1 << rng.below(8); // may create a zero: a split frame
                }
                3 => {
                    let k = rng.below(frame.len() - 1);
                    frame[k] = rng.next_u64() as u8;
                }
                4 => {
                    let keep = rng.below(frame.len());
                    frame.drain(keep..frame.len() - 1); // truncated, still delimited
                }
                5 => {
                    // Overlong: random non-zero bytes past MAX_FRAME.
                    frame = (0..link::MAX_FRAME + 1 + rng.below(300))
                        .map(|_| 1 + rng.below(255) as u8)
                        .collect();
                    frame.push(0);
                }
                6 => {
                    // Random bytes, zeros included.
                    frame = (0..rng.below(80)).map(|_| rng.next_u64() as u8).collect();
                }
                _ => {
                    let k = rng.below(frame.len());
                    frame.insert(k, rng.next_u64() as u8);
                }
            }
            stream.extend_from_slice(&frame);
        }
        stream.push(0);
        let n = if case % 2 == 0 {
            check_stream::<Uplink>(&stream)
        } else {
            check_stream::<Downlink>(&stream)
        };
        assert!(n > 0 || stream.iter().all(|&b| b == 0));
        // Tally what the decoder saw, to show that every path is reached.
        for r in decode_all::<Uplink>(&stream) {
            let k = match r {
                Ok(_) => 0,
                Err(FrameError::Overflow) => 1,
                Err(FrameError::Cobs) => 2,
                Err(FrameError::Crc) => 3,
                Err(FrameError::Decode) => 4,
            };
            outcomes[k] += 1;
        }
    }
    assert!(
        outcomes.iter().all(|&n| n > 0),
        "ok/Overflow/Cobs/Crc/Decode: {outcomes:?}"
    );
}

#[test]
fn corrupted_frame_is_dropped_and_decoder_resyncs() {
    let mut buf = [0u8; link::MAX_FRAME];
    let n = link::encode(&Uplink::Hello, &mut buf).unwrap();
    let mut bytes = buf[..n].to_vec();
    bytes[1] ^= 0x10; // flip a payload bit
    bytes.extend_from_slice(&buf[..n]);
    let got = decode_all::<Uplink>(&bytes);
    assert_eq!(got, vec![Err(FrameError::Crc), Ok(Uplink::Hello)]);
}

#[test]
fn overlong_frame_is_an_overflow() {
    let mut bytes = vec![1u8; link::MAX_FRAME + 10];
    bytes.push(0);
    assert_eq!(
        decode_all::<Uplink>(&bytes),
        vec![Err(FrameError::Overflow)]
    );
}
