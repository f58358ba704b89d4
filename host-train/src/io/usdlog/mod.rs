//! Bitcraze uSD-card deck binary logs: a reader (for `host-train import`) and a version-2 writer
//! (for the SITL's `host-train eval --log-usd`). Our own implementation of the format that the
//! deck's firmware writes and Bitcraze's `tools/usdlog/cfusdlog.py` decodes.
//!
//! # The format (all integers little-endian)
//!
//! | bytes | content |
//! | --- | --- |
//! | 1 | magic `0xBC` |
//! | 2 | `u16` version: 1 (timestamps `u32` ms) or 2 (timestamps `u64` µs) |
//! | 2 | `u16` number of event types T |
//! | T × | `u16` id, NUL-terminated event name, `u16` variable count V, then V NUL-terminated `name(t)` with the type character t (a Python struct code: `B b H h I i f e` = u8 i8 u16 i16 u32 i32 f32 f16) |
//! | … | events: `u16` id, timestamp, then the event type's values packed in order |
//! | 4 | CRC-32 (zlib's) of every byte before it |
//!
//! The deck's fixed-rate logging is the event type `fixedFrequency` (id `0xFFFF`); its variables
//! are named `group.name`. Other event types (event triggers) are decoded too; an importer skips
//! and counts those it does not use.
//!
//! # Errors
//! [`parse`] never panics. Every problem is an [`UsdError`] with the byte offset: a wrong magic,
//! an unsupported version, a header that ends inside an event type or has a bad name or type
//! character, a CRC mismatch (stored and computed value), an event id the header does not
//! declare (its size is unknown, so decoding cannot go on), and an event cut short.

use std::fmt;

mod parse;
mod writer;

pub use parse::parse;
pub use writer::UsdWriter;

/// Standard gravity used to convert Bitcraze's accelerometer (g) to m/s².
pub const G0_M_S2: f64 = 9.81;

/// The default commanded-wrench variables of a uSD log (Bitcraze's Lee controller).
pub const LEE_COMMAND_VARS: [&str; 4] = [
    "ctrlLee.thrustSi",
    "ctrlLee.torquex",
    "ctrlLee.torquey",
    "ctrlLee.torquez",
];

/// The state variables a uSD log must have, in the importer's order.
pub const USD_STATE_VARS: [&str; 13] = [
    "stateEstimate.x",
    "stateEstimate.y",
    "stateEstimate.z",
    "stateEstimate.vx",
    "stateEstimate.vy",
    "stateEstimate.vz",
    "stateEstimate.qx",
    "stateEstimate.qy",
    "stateEstimate.qz",
    "stateEstimate.qw",
    "gyro.x",
    "gyro.y",
    "gyro.z",
];

/// The optional accelerometer variables of a uSD log (g).
pub const USD_ACC_VARS: [&str; 3] = ["acc.x", "acc.y", "acc.z"];

/// The id of the deck's fixed-frequency event type.
pub const FIXED_FREQUENCY_ID: u16 = 0xFFFF;
/// The name of the deck's fixed-frequency event type.
pub const FIXED_FREQUENCY_NAME: &str = "fixedFrequency";
/// The file's first byte.
pub const MAGIC: u8 = 0xBC;

/// A logged variable's type (its struct code in the header).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarType {
    /// `B`
    U8,
    /// `b`
    I8,
    /// `H`
    U16,
    /// `h`
    I16,
    /// `I`
    U32,
    /// `i`
    I32,
    /// `f`
    F32,
    /// `e` (IEEE half precision; event-trigger payloads only)
    F16,
}

impl VarType {
    /// From the header's type character.
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            b'B' => Self::U8,
            b'b' => Self::I8,
            b'H' => Self::U16,
            b'h' => Self::I16,
            b'I' => Self::U32,
            b'i' => Self::I32,
            b'f' => Self::F32,
            b'e' => Self::F16,
            _ => return None,
        })
    }

    /// The header's type character.
    pub fn code(self) -> char {
        match self {
            Self::U8 => 'B',
            Self::I8 => 'b',
            Self::U16 => 'H',
            Self::I16 => 'h',
            Self::U32 => 'I',
            Self::I32 => 'i',
            Self::F32 => 'f',
            Self::F16 => 'e',
        }
    }

    /// Size in bytes.
    pub fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 | Self::F16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
        }
    }

    fn decode(self, b: &[u8]) -> f64 {
        let get = |i: usize| b.get(i).copied().unwrap_or(0);
        let u16v = u16::from_le_bytes([get(0), get(1)]);
        let u32v = u32::from_le_bytes([get(0), get(1), get(2), get(3)]);
        match self {
            Self::U8 => f64::from(get(0)),
            Self::I8 => f64::from(get(0) as i8),
            Self::U16 => f64::from(u16v),
            Self::I16 => f64::from(u16v as i16),
            Self::U32 => f64::from(u32v),
            Self::I32 => f64::from(u32v as i32),
            Self::F32 => f64::from(f32::from_bits(u32v)),
            Self::F16 => f16_to_f64(u16v),
        }
    }

    fn encode(self, v: f64, out: &mut Vec<u8>) {
        // Saturating float → integer casts, as documented for `as`.
        match self {
            Self::U8 => out.push(v as u8),
            Self::I8 => out.push((v as i8) as u8),
            Self::U16 => out.extend_from_slice(&(v as u16).to_le_bytes()),
            Self::I16 => out.extend_from_slice(&(v as i16).to_le_bytes()),
            Self::U32 => out.extend_from_slice(&(v as u32).to_le_bytes()),
            Self::I32 => out.extend_from_slice(&(v as i32).to_le_bytes()),
            Self::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
            Self::F16 => out.extend_from_slice(&f64_to_f16(v).to_le_bytes()),
        }
    }
}

fn f16_to_f64(h: u16) -> f64 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f64::from(h & 0x3ff);
    sign * match exp {
        0 => frac * 2f64.powi(-24),
        31 if frac == 0.0 => f64::INFINITY,
        31 => f64::NAN,
        e => (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

fn f64_to_f16(v: f64) -> u16 {
    // Round toward zero; enough for a writer of test logs (the deck never writes f16 variables).
    let sign: u16 = if v.is_sign_negative() { 0x8000 } else { 0 };
    let a = v.abs();
    if a.is_nan() {
        return 0x7e00;
    }
    if a >= 65520.0 {
        return sign | 0x7c00;
    }
    if a < 2f64.powi(-14) {
        return sign | (a / 2f64.powi(-24)) as u16;
    }
    let e = a.log2().floor() as i32;
    let frac = ((a / 2f64.powi(e) - 1.0) * 1024.0) as u16;
    sign | (((e + 15) as u16) << 10) | (frac & 0x3ff)
}

/// One variable of an event type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Var {
    /// Its name (for `fixedFrequency`: `group.name`).
    pub name: String,
    /// Its type.
    pub ty: VarType,
}

/// One event type of the header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EventType {
    /// Event id.
    pub id: u16,
    /// Event name.
    pub name: String,
    /// Its variables, in payload order.
    pub vars: Vec<Var>,
}

impl EventType {
    /// Payload bytes of one event.
    pub fn payload_size(&self) -> usize {
        self.vars.iter().map(|v| v.ty.size()).sum()
    }

    /// Index of the variable `name`.
    pub fn var_index(&self, name: &str) -> Option<usize> {
        self.vars.iter().position(|v| v.name == name)
    }
}

/// One decoded event.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Index of its type in [`UsdLog::event_types`].
    pub type_index: usize,
    /// Timestamp (µs; version-1 ms are scaled).
    pub timestamp_us: u64,
    /// Byte offset of the event in the file.
    pub offset: usize,
    /// The values, in the type's variable order (exact: every stored type fits an f64).
    pub values: Vec<f64>,
}

/// A decoded log.
#[derive(Clone, Debug, PartialEq)]
pub struct UsdLog {
    /// Format version (1 or 2).
    pub version: u16,
    /// The header's event types.
    pub event_types: Vec<EventType>,
    /// Every event, in file order.
    pub events: Vec<Event>,
}

impl UsdLog {
    /// Index of the fixed-frequency event type (by id `0xFFFF`, else by name).
    pub fn fixed_frequency(&self) -> Option<usize> {
        self.event_types
            .iter()
            .position(|e| e.id == FIXED_FREQUENCY_ID)
            .or_else(|| {
                self.event_types
                    .iter()
                    .position(|e| e.name == FIXED_FREQUENCY_NAME)
            })
    }
}

/// Why a log could not be decoded, with the byte offset where it went wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum UsdError {
    /// Shorter than magic + version + count + CRC.
    TooShort {
        /// File length.
        len: usize,
    },
    /// The first byte is not `0xBC`.
    BadMagic {
        /// The byte found.
        found: u8,
    },
    /// Version other than 1 or 2.
    UnsupportedVersion {
        /// The version found.
        version: u16,
    },
    /// The header ends (or the CRC starts) inside an event-type description.
    TruncatedHeader {
        /// Offset where more bytes were needed.
        offset: usize,
        /// Which event type (0-based) was being read.
        event_type: usize,
    },
    /// A name that is not UTF-8 or a `name(t)` that is malformed.
    BadName {
        /// Offset of the name.
        offset: usize,
        /// What is wrong.
        problem: String,
    },
    /// The stored CRC-32 does not match the file.
    CrcMismatch {
        /// Offset of the stored CRC (file length − 4).
        offset: usize,
        /// The stored value.
        stored: u32,
        /// The value computed over the bytes before it.
        computed: u32,
    },
    /// An event id the header does not declare (its size is unknown).
    UndeclaredEvent {
        /// Offset of the event.
        offset: usize,
        /// The id found.
        id: u16,
    },
    /// An event cut short by the end of the data (the CRC's start).
    TruncatedEvent {
        /// Offset of the event.
        offset: usize,
        /// Bytes the event needs.
        needed: usize,
        /// Bytes left before the CRC.
        left: usize,
    },
}

impl fmt::Display for UsdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooShort { len } => write!(
                f,
                "byte 0: {len} bytes is too short for a uSD log (at least 9: magic, version, \
                 event-type count, CRC)"
            ),
            Self::BadMagic { found } => write!(
                f,
                "byte 0: magic is 0x{found:02X}, expected 0xBC (not a uSD-card deck log)"
            ),
            Self::UnsupportedVersion { version } => {
                write!(
                    f,
                    "byte 1: unsupported version {version} (1 and 2 are read)"
                )
            }
            Self::TruncatedHeader { offset, event_type } => write!(
                f,
                "byte {offset}: the header ends inside event type {event_type}"
            ),
            Self::BadName { offset, problem } => write!(f, "byte {offset}: {problem}"),
            Self::CrcMismatch {
                offset,
                stored,
                computed,
            } => write!(
                f,
                "byte {offset}: CRC mismatch: stored 0x{stored:08X}, computed 0x{computed:08X} \
                 (the file is corrupt or was cut short; --allow-bad-crc decodes it anyway)"
            ),
            Self::UndeclaredEvent { offset, id } => write!(
                f,
                "byte {offset}: event id 0x{id:04X} is not declared in the header (its size is \
                 unknown, decoding cannot go on)"
            ),
            Self::TruncatedEvent {
                offset,
                needed,
                left,
            } => write!(
                f,
                "byte {offset}: event cut short: needs {needed} bytes, {left} left before the CRC"
            ),
        }
    }
}

impl std::error::Error for UsdError {}

/// How strictly to decode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParseOptions {
    /// Decode despite a CRC mismatch (a log cut short by a power loss has no valid CRC); an
    /// event cut short at the end is then dropped instead of an error.
    pub allow_bad_crc: bool,
}

/// What [`parse`] reports besides the log.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParseReport {
    /// The CRC matched.
    pub crc_ok: bool,
    /// Bytes of a final event cut short and dropped (only with `allow_bad_crc`).
    pub dropped_tail_bytes: usize,
}

/// The CRC-32 (zlib's polynomial, reflected, init and final xor 0xFFFFFFFF) of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(bytes);
    h.finalize()
}
