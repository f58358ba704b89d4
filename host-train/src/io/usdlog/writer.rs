//! The version-2 writer of the SITL's `eval --log-usd`.

use super::*;

/// Writes a version-2 uSD log, as the deck does: header, events, CRC-32.
#[derive(Clone, Debug)]
pub struct UsdWriter {
    types: Vec<EventType>,
    buf: Vec<u8>,
}

impl UsdWriter {
    /// A log with these event types (written into the header now).
    pub fn new(types: Vec<EventType>) -> Self {
        let mut buf = vec![MAGIC];
        buf.extend_from_slice(&2u16.to_le_bytes());
        buf.extend_from_slice(&(types.len() as u16).to_le_bytes());
        for t in &types {
            buf.extend_from_slice(&t.id.to_le_bytes());
            buf.extend_from_slice(t.name.as_bytes());
            buf.push(0);
            buf.extend_from_slice(&(t.vars.len() as u16).to_le_bytes());
            for v in &t.vars {
                buf.extend_from_slice(format!("{}({})", v.name, v.ty.code()).as_bytes());
                buf.push(0);
            }
        }
        Self { types, buf }
    }

    /// A log whose only event type is `fixedFrequency` with `f32` variables `names`.
    pub fn fixed_frequency(names: &[&str]) -> Self {
        Self::new(vec![EventType {
            id: FIXED_FREQUENCY_ID,
            name: FIXED_FREQUENCY_NAME.into(),
            vars: names
                .iter()
                .map(|n| Var {
                    name: (*n).into(),
                    ty: VarType::F32,
                })
                .collect(),
        }])
    }

    /// Appends one event of type `type_index` (values in variable order, each stored in the
    /// variable's type; missing values are written as 0, extra ones ignored).
    pub fn event(&mut self, type_index: usize, timestamp_us: u64, values: &[f64]) {
        let Some(t) = self.types.get(type_index) else {
            return;
        };
        self.buf.extend_from_slice(&t.id.to_le_bytes());
        self.buf.extend_from_slice(&timestamp_us.to_le_bytes());
        for (k, v) in t.vars.iter().enumerate() {
            v.ty.encode(values.get(k).copied().unwrap_or(0.0), &mut self.buf);
        }
    }

    /// The finished file: everything so far and its CRC-32.
    pub fn finish(mut self) -> Vec<u8> {
        let crc = crc32(&self.buf);
        self.buf.extend_from_slice(&crc.to_le_bytes());
        self.buf
    }
}
