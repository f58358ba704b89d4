//! The reader: a uSD log's bytes to a [`UsdLog`], every problem an [`UsdError`] with its offset.

use super::*;

struct Cursor<'a> {
    b: &'a [u8],
    pos: usize,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        let end = self.pos.checked_add(n)?;
        let s = self.b.get(self.pos..end)?;
        self.pos = end;
        Some(s)
    }
    fn u16(&mut self) -> Option<u16> {
        self.take(2).map(|s| u16::from_le_bytes([s[0], s[1]]))
    }
    fn cstr(&mut self) -> Option<&[u8]> {
        let rest = self.b.get(self.pos..)?;
        let n = rest.iter().position(|&c| c == 0)?;
        let s = rest.get(..n)?;
        self.pos += n + 1;
        Some(s)
    }
}

/// Decodes a uSD log. Never panics; see [`UsdError`] for what is rejected.
///
/// # Errors
/// See [`UsdError`].
pub fn parse(bytes: &[u8], opts: ParseOptions) -> Result<(UsdLog, ParseReport), UsdError> {
    if bytes.len() < 9 {
        return Err(UsdError::TooShort { len: bytes.len() });
    }
    if bytes[0] != MAGIC {
        return Err(UsdError::BadMagic { found: bytes[0] });
    }
    let body_end = bytes.len() - 4;
    let body = &bytes[..body_end];
    let mut c = Cursor { b: body, pos: 1 };
    let trunc = |offset: usize, event_type: usize| UsdError::TruncatedHeader { offset, event_type };
    let version = c.u16().ok_or(trunc(1, 0))?;
    if version != 1 && version != 2 {
        return Err(UsdError::UnsupportedVersion { version });
    }
    let n_types = c.u16().ok_or(trunc(3, 0))?;
    let mut event_types = Vec::with_capacity(usize::from(n_types).min(64));
    for t in 0..usize::from(n_types) {
        let id = c.u16().ok_or(trunc(c.pos, t))?;
        let name_at = c.pos;
        let name = c.cstr().ok_or(trunc(name_at, t))?;
        let name = std::str::from_utf8(name)
            .map_err(|_| UsdError::BadName {
                offset: name_at,
                problem: "event name is not UTF-8".into(),
            })?
            .to_string();
        let n_vars = c.u16().ok_or(trunc(c.pos, t))?;
        let mut vars = Vec::with_capacity(usize::from(n_vars).min(64));
        for _ in 0..n_vars {
            let at = c.pos;
            let raw = c.cstr().ok_or(trunc(at, t))?;
            let bad = |problem: String| UsdError::BadName {
                offset: at,
                problem,
            };
            let s =
                std::str::from_utf8(raw).map_err(|_| bad("variable name is not UTF-8".into()))?;
            let (Some(stem), true) = (s.strip_suffix(')'), s.len() >= 4) else {
                return Err(bad(format!("variable `{s}` is not of the form `name(t)`")));
            };
            let Some((vname, code)) = stem.rsplit_once('(') else {
                return Err(bad(format!("variable `{s}` is not of the form `name(t)`")));
            };
            let ty = match code.as_bytes() {
                [b] => VarType::from_code(*b),
                _ => None,
            }
            .ok_or_else(|| bad(format!("variable `{s}`: unknown type character `{code}`")))?;
            vars.push(Var {
                name: vname.to_string(),
                ty,
            });
        }
        event_types.push(EventType { id, name, vars });
    }
    let stored = u32::from_le_bytes([
        bytes[body_end],
        bytes[body_end + 1],
        bytes[body_end + 2],
        bytes[body_end + 3],
    ]);
    let computed = crc32(body);
    let crc_ok = stored == computed;
    if !crc_ok && !opts.allow_bad_crc {
        return Err(UsdError::CrcMismatch {
            offset: body_end,
            stored,
            computed,
        });
    }
    let sizes: Vec<usize> = event_types.iter().map(EventType::payload_size).collect();
    let ts_len = if version == 1 { 4 } else { 8 };
    let mut events = Vec::new();
    let mut report = ParseReport {
        crc_ok,
        dropped_tail_bytes: 0,
    };
    while c.pos < body_end {
        let offset = c.pos;
        let left = body_end - offset;
        let cut = |needed: usize| UsdError::TruncatedEvent {
            offset,
            needed,
            left,
        };
        let Some(id) = c.u16() else {
            if opts.allow_bad_crc {
                report.dropped_tail_bytes = left;
                break;
            }
            return Err(cut(2));
        };
        let Some(type_index) = event_types.iter().position(|e| e.id == id) else {
            return Err(UsdError::UndeclaredEvent { offset, id });
        };
        let needed = 2 + ts_len + sizes[type_index];
        if needed > left {
            if opts.allow_bad_crc {
                report.dropped_tail_bytes = left;
                break;
            }
            return Err(cut(needed));
        }
        let ts = c.take(ts_len).ok_or(cut(needed))?;
        let timestamp_us = match (<[u8; 4]>::try_from(ts), <[u8; 8]>::try_from(ts)) {
            (Ok(ms), _) => u64::from(u32::from_le_bytes(ms)) * 1000,
            (_, Ok(us)) => u64::from_le_bytes(us),
            _ => return Err(cut(needed)),
        };
        let payload = c.take(sizes[type_index]).ok_or(cut(needed))?;
        let mut values = Vec::with_capacity(event_types[type_index].vars.len());
        let mut at = 0;
        for v in &event_types[type_index].vars {
            let n = v.ty.size();
            values.push(v.ty.decode(payload.get(at..at + n).unwrap_or(&[])));
            at += n;
        }
        events.push(Event {
            type_index,
            timestamp_us,
            offset,
            values,
        });
    }
    Ok((
        UsdLog {
            version,
            event_types,
            events,
        },
        report,
    ))
}
