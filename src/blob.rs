//! The weight blob: one self-checking file that carries the learned networks to the firmware.
//!
//! Layout (all integers little-endian):
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 4 | magic `b"HMFW"` |
//! | 4 | 2 | format version ([`FORMAT_VERSION`]) |
//! | 6 | 18 | network shapes: J⁻¹, g, W, each `[inputs, hidden, outputs]` as u16 |
//! | 24 | 4 | body length in bytes |
//! | 28 | n | body: the vehicle's mass (kg), its motor time constant (s), the port terms ([`PortTerms`], 27 numbers), then every network parameter ([`ModelWeights`] in blob order), each an f32, as postcard writes them |
//! | 28 + n | 4 | CRC-32 (IEEE 802.3) of the body |
//!
//! Older versions migrate on decode, so old blobs keep flying unchanged:
//! - version 1 (before the mass was data) has neither mass nor motor lag in its body: it is read
//!   as a model of the stock CF2X ([`MASS_KG`], the only mass version 1 was ever trained with);
//! - versions 1 and 2 (before the motor lag was data) read with [`DEFAULT_MOTOR_TAU_S`], the lag
//!   the composite law's prediction assumed for every model then;
//! - versions 1 to 3 (before the dissipation, the learned potential and the input's gains and
//!   lags were data) read with [`PortTerms::IDENTITY`], the rigid body alone.
//!
//! [`encode`] and [`encode_model`] always write the current version. [`decode`] and
//! [`decode_into`] give the networks and the mass ([`ModelWeights`]); [`decode_model_into`] (and
//! [`LearnedModel::from_blob`]) also the motor lag and the port terms.
//!
//! [`decode`] (by value) and [`decode_into`] (in place, for small stacks) check each field in that
//! order and return the first failure as a [`BlobError`]; they never panic and never leave a
//! partly loaded model.

use crate::model::{
    LearnedModel, ModelWeights, PortError, PortTerms, DEFAULT_MOTOR_TAU_S, MASS_KG, MAX_MASS_KG,
    MAX_MOTOR_TAU_S, MIN_MASS_KG, PORT_PARAMS,
};

/// The blob's first four bytes.
pub const MAGIC: [u8; 4] = *b"HMFW";
/// The format version this build reads and writes.
pub const FORMAT_VERSION: u16 = 4;
/// The oldest format version this build reads (migrated on decode; see the module docs).
pub const OLDEST_VERSION: u16 = 1;
/// Size of the fixed header before the body.
pub const HEADER_LEN: usize = 28;
/// Size of the trailing checksum.
pub const CRC_LEN: usize = 4;
/// The largest blob this build reads: a current-version one (the mass, the motor lag, the port
/// terms and every network parameter, 4 bytes each). Older versions are shorter.
pub const MAX_LEN: usize = HEADER_LEN + 4 * (2 + PORT_PARAMS + ModelWeights::PARAMS) + CRC_LEN;

/// Why a blob was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BlobError {
    /// Shorter than its header says (or than a header).
    Truncated,
    /// The first four bytes are not `HMFW`: not a hamflight weight blob.
    BadMagic,
    /// Written by a format version this build cannot read.
    UnsupportedVersion(u16),
    /// The network shapes in the header differ from the ones this build was compiled for.
    ShapeMismatch,
    /// The body's CRC-32 does not match: the file is corrupt.
    Checksum,
    /// Bytes follow the checksum.
    TrailingBytes,
    /// The body passed its checksum but is not a valid encoding of the networks.
    Malformed,
    /// A parameter is NaN or infinite.
    NonFinite,
    /// The vehicle mass is not in [[`MIN_MASS_KG`], [`MAX_MASS_KG`]] kg.
    BadMass,
    /// The motor time constant is not in [0, [`MAX_MOTOR_TAU_S`]] s.
    BadMotorTau,
    /// The port terms cannot be flown ([`PortTerms::validate`]).
    BadPort(PortError),
}

impl core::fmt::Display for BlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Truncated => f.write_str("weight blob is truncated"),
            Self::BadMagic => f.write_str("not a hamflight weight blob (bad magic)"),
            Self::UnsupportedVersion(v) => write!(
                f,
                "weight blob format version {v} is not supported (this build reads \
                 {OLDEST_VERSION} to {FORMAT_VERSION})"
            ),
            Self::ShapeMismatch => {
                f.write_str("weight blob network shapes differ from this build's networks")
            }
            Self::Checksum => f.write_str("weight blob checksum mismatch (corrupt file)"),
            Self::TrailingBytes => f.write_str("weight blob has bytes after its checksum"),
            Self::Malformed => f.write_str("weight blob body is malformed"),
            Self::NonFinite => f.write_str("weight blob holds a NaN or infinite parameter"),
            // A literal, not the constants: formatting an f32 would pull ~10 KB of float
            // printing into every firmware that shows this error (blob_error_text_names_the_range
            // checks the text against MIN_MASS_KG and MAX_MASS_KG).
            Self::BadMass => f.write_str("weight blob vehicle mass is outside 0.005..=5 kg"),
            Self::BadMotorTau => f.write_str("weight blob motor time constant is outside 0..=1 s"),
            Self::BadPort(e) => f.write_str(match e {
                PortError::NonFinite => "weight blob port terms hold a NaN or infinite number",
                PortError::BadGain => "weight blob input gain is outside 0.02..=50",
                PortError::BadLag => "weight blob input lag is outside 0..=1 s",
                PortError::NegativeDissipation => "weight blob dissipation is negative",
            }),
        }
    }
}

impl core::error::Error for BlobError {}

/// The header bytes this build writes (magic, version, shapes), without the length.
fn expected_prefix() -> [u8; 24] {
    let mut out = [0u8; 24];
    let mut fields = MAGIC.into_iter().chain(FORMAT_VERSION.to_le_bytes()).chain(
        ModelWeights::DIMS
            .into_iter()
            .flatten()
            .flat_map(u16::to_le_bytes),
    );
    for b in out.iter_mut() {
        *b = fields.next().unwrap_or(0);
    }
    out
}

fn le_u16(b: &[u8]) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(..2)?.try_into().ok()?))
}

fn le_u32(b: &[u8]) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(..4)?.try_into().ok()?))
}

/// Decodes and checks a weight blob, returning the weights by value (about 10 KB: on a small
/// stack use [`decode_into`]).
///
/// # Errors
/// As [`decode_into`].
///
/// # Examples
///
/// ```
/// use hamflight::blob::{self, BlobError};
///
/// let bytes = include_bytes!("../weights/default.hfw");
/// let weights = blob::decode(bytes)?;
/// assert!((weights.mass_kg - 0.027).abs() < 1e-6);
///
/// // Every check fails loudly: one flipped byte in the body breaks the checksum.
/// let mut bad = bytes.to_vec();
/// let last = bad.len() - 1;
/// bad[last] ^= 0x40;
/// assert!(blob::decode(&bad).is_err());
/// assert_eq!(blob::decode(&bytes[..4]), Err(BlobError::Truncated));
/// # Ok::<(), BlobError>(())
/// ```
pub fn decode(bytes: &[u8]) -> Result<ModelWeights, BlobError> {
    let mut weights = ModelWeights::ZERO;
    decode_into(bytes, &mut weights)?;
    Ok(weights)
}

/// Decodes and checks a weight blob into `out`, in place: no copy of the weights passes through
/// the stack, so a firmware can boot on a few hundred bytes of it (decoding into a `static`).
/// Every check runs before the first parameter is written, so on error `out` is unchanged.
///
/// The body is postcard's encoding of the tuple (mass, motor lag, J⁻¹, g, W networks), which for
/// these all-f32 values is each as 4 little-endian bytes, the parameters in
/// [`ModelWeights::params_mut`] order; it is read as such (`tests/blob.rs` checks that postcard
/// agrees on random and shipped blobs). The motor lag is checked here but not stored: see
/// [`decode_model_into`].
///
/// # Errors
/// The first failed check, in file order: [`BlobError::Truncated`] (shorter than the header),
/// [`BlobError::BadMagic`], [`BlobError::UnsupportedVersion`], [`BlobError::ShapeMismatch`],
/// [`BlobError::Truncated`] / [`BlobError::TrailingBytes`] (length disagrees with the header),
/// [`BlobError::Checksum`], [`BlobError::Malformed`] (the body is not the mass, the motor lag
/// and [`ModelWeights::PARAMS`] f32 values), [`BlobError::NonFinite`], [`BlobError::BadMass`],
/// [`BlobError::BadMotorTau`].
pub fn decode_into(bytes: &[u8], out: &mut ModelWeights) -> Result<(), BlobError> {
    decode_checked(bytes, out).map(|_| ())
}

/// [`decode_into`] for the whole model: the networks and the mass into `out.weights`, the motor
/// lag into `out` ([`LearnedModel::with_motor_tau_s`]; [`DEFAULT_MOTOR_TAU_S`] for blobs before
/// version 3). On error `out` is unchanged.
///
/// # Errors
/// As [`decode_into`].
pub fn decode_model_into(bytes: &[u8], out: &mut LearnedModel) -> Result<(), BlobError> {
    let (tau, port) = decode_checked(bytes, &mut out.weights)?;
    // In place: a by-value copy of the model would put 10 KB on a firmware's stack.
    out.set_motor_tau_s(tau);
    out.set_port(port);
    Ok(())
}

/// What [`check`] reports of a blob that passed every check of [`decode`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobInfo {
    /// The format version it was written with.
    pub version: u16,
    /// The whole blob's length in bytes (header, body, CRC).
    pub total_len: usize,
    /// The CRC-32 of the body, as stored in the blob.
    pub crc: u32,
    /// The vehicle's mass (kg).
    pub mass_kg: f32,
    /// The motor time constant (s).
    pub motor_tau_s: f32,
    /// The port terms ([`PortTerms::IDENTITY`] before version 4).
    pub port: PortTerms,
}

/// Runs every check of [`decode`] without decoding: for a firmware that receives a blob into a
/// buffer and must reject a bad one before it touches the model it flies.
///
/// # Errors
/// As [`decode_into`].
// Inline: a firmware's caller then holds the one copy of the result (the Crazyflie app's
// memory task checks an upload on a 1,200-byte stack).
#[inline]
pub fn check(bytes: &[u8]) -> Result<BlobInfo, BlobError> {
    parse(bytes).map(|p| p.info)
}

/// A blob that passed every check: its facts and its network parameters.
struct Parsed<'a> {
    info: BlobInfo,
    params: &'a [[u8; 4]],
}

/// [`decode_into`], returning the blob's motor lag (s) and port terms.
fn decode_checked(bytes: &[u8], out: &mut ModelWeights) -> Result<(f32, PortTerms), BlobError> {
    let p = parse(bytes)?;
    out.mass_kg = p.info.mass_kg;
    for (slot, b) in out.params_mut().zip(p.params) {
        *slot = f32::from_le_bytes(*b);
    }
    Ok((p.info.motor_tau_s, p.info.port))
}

/// Every check, in file order (see [`decode_into`]); writes nothing.
fn parse(bytes: &[u8]) -> Result<Parsed<'_>, BlobError> {
    let prefix = expected_prefix();
    let magic = bytes.get(..4).ok_or(BlobError::Truncated)?;
    if magic != MAGIC {
        return Err(BlobError::BadMagic);
    }
    let version = bytes
        .get(4..)
        .and_then(le_u16)
        .ok_or(BlobError::Truncated)?;
    if !(OLDEST_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(BlobError::UnsupportedVersion(version));
    }
    let shapes = bytes.get(6..24).ok_or(BlobError::Truncated)?;
    if Some(shapes) != prefix.get(6..24) {
        return Err(BlobError::ShapeMismatch);
    }
    let body_len = bytes
        .get(24..)
        .and_then(le_u32)
        .ok_or(BlobError::Truncated)? as usize;
    let total = HEADER_LEN
        .checked_add(body_len)
        .and_then(|n| n.checked_add(CRC_LEN))
        .ok_or(BlobError::Truncated)?;
    if bytes.len() < total {
        return Err(BlobError::Truncated);
    }
    if bytes.len() > total {
        return Err(BlobError::TrailingBytes);
    }
    let body = bytes
        .get(HEADER_LEN..HEADER_LEN + body_len)
        .ok_or(BlobError::Truncated)?;
    let stored_crc = bytes
        .get(HEADER_LEN + body_len..)
        .and_then(le_u32)
        .ok_or(BlobError::Truncated)?;
    if crc32(body) != stored_crc {
        return Err(BlobError::Checksum);
    }
    let (values, rest) = body.as_chunks::<4>();
    // Version 4 puts the mass, the motor lag and the port terms before the parameters,
    // version 3 the mass and the lag, version 2 the mass alone; version 1 has none of them (the
    // stock vehicle).
    let (mass_kg, motor_tau_s, port, params) = match (version, values) {
        (1, params) => (MASS_KG, DEFAULT_MOTOR_TAU_S, &[][..], params),
        (2, [mass, params @ ..]) => (
            f32::from_le_bytes(*mass),
            DEFAULT_MOTOR_TAU_S,
            &[][..],
            params,
        ),
        (3, [mass, tau, params @ ..]) => (
            f32::from_le_bytes(*mass),
            f32::from_le_bytes(*tau),
            &[][..],
            params,
        ),
        (4.., [mass, tau, rest @ ..]) if rest.len() >= PORT_PARAMS => {
            let (port, params) = rest.split_at(PORT_PARAMS);
            (
                f32::from_le_bytes(*mass),
                f32::from_le_bytes(*tau),
                port,
                params,
            )
        }
        _ => return Err(BlobError::Malformed),
    };
    let mut port_values = [0.0f32; PORT_PARAMS];
    for (o, b) in port_values.iter_mut().zip(port) {
        *o = f32::from_le_bytes(*b);
    }
    let port = PortTerms::from_array(&port_values);
    if params.len() != ModelWeights::PARAMS || !rest.is_empty() {
        return Err(BlobError::Malformed);
    }
    if !mass_kg.is_finite()
        || !motor_tau_s.is_finite()
        || !port_values.iter().all(|v| v.is_finite())
        || !params.iter().all(|b| f32::from_le_bytes(*b).is_finite())
    {
        return Err(BlobError::NonFinite);
    }
    if !(MIN_MASS_KG..=MAX_MASS_KG).contains(&mass_kg) {
        return Err(BlobError::BadMass);
    }
    if !(0.0..=MAX_MOTOR_TAU_S).contains(&motor_tau_s) {
        return Err(BlobError::BadMotorTau);
    }
    port.validate().map_err(BlobError::BadPort)?;
    Ok(Parsed {
        info: BlobInfo {
            version,
            total_len: total,
            crc: stored_crc,
            mass_kg,
            motor_tau_s,
            port,
        },
        params,
    })
}

/// Encodes weights as a blob (host side), with the default motor lag ([`DEFAULT_MOTOR_TAU_S`]).
#[cfg(feature = "std")]
pub fn encode(weights: &ModelWeights) -> Vec<u8> {
    encode_model(&LearnedModel::new(*weights))
}

/// Encodes a model as a blob (host side): its networks, mass, motor lag and port terms.
#[cfg(feature = "std")]
pub fn encode_model(model: &LearnedModel) -> Vec<u8> {
    let w = &model.weights;
    // Serializing plain f32 tuples into a Vec cannot fail.
    let body = postcard::to_stdvec(&(
        w.mass_kg,
        crate::model::HamiltonianModel::motor_tau_s(model),
        crate::model::HamiltonianModel::port(model).to_array(),
        &w.inertia,
        &w.gain,
        &w.disturbance,
    ))
    .unwrap_or_default();
    let mut out = Vec::with_capacity(HEADER_LEN + body.len() + CRC_LEN);
    out.extend_from_slice(&expected_prefix());
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_le_bytes());
    out
}

const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, as zlib and PNG use).
pub fn crc32(data: &[u8]) -> u32 {
    !data.iter().fold(!0u32, |c, &b| {
        let idx = ((c ^ b as u32) & 0xFF) as usize;
        CRC_TABLE.get(idx).copied().unwrap_or(0) ^ (c >> 8)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_agrees_with_decode_and_writes_nothing() {
        let bytes = include_bytes!("../weights/default.hfw");
        let info = check(bytes).expect("the shipped blob passes");
        let w = decode(bytes).expect("and decodes");
        assert_eq!(info.mass_kg, w.mass_kg);
        assert_eq!(
            (info.version, info.total_len),
            (FORMAT_VERSION, bytes.len())
        );
        assert_eq!(
            bytes.len(),
            MAX_LEN,
            "a current-version blob has the largest size"
        );
        let body = &bytes[HEADER_LEN..bytes.len() - CRC_LEN];
        assert_eq!(info.crc, crc32(body));
        let mut bad = bytes.to_vec();
        bad[HEADER_LEN + 9] ^= 1;
        assert_eq!(check(&bad), Err(BlobError::Checksum));
        assert_eq!(check(&bytes[..bytes.len() - 1]), Err(BlobError::Truncated));
    }

    #[test]
    fn crc32_check_value() {
        // The standard check value of CRC-32/ISO-HDLC.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }
}
