//! The C3D parameter section: groups and parameters of any type and dimensions.

use super::C3dError;

/// Processor type of the file: byte order and float format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Proc {
    /// 84: little-endian, IEEE floats.
    Intel,
    /// 85: little-endian integers, VAX F-floats.
    Dec,
    /// 86: big-endian, IEEE floats.
    Mips,
}

impl Proc {
    /// A 4-byte float in this processor's format.
    pub(super) fn f32(self, b: &[u8]) -> f32 {
        let b = [b[0], b[1], b[2], b[3]];
        match self {
            Proc::Intel => f32::from_le_bytes(b),
            Proc::Mips => f32::from_be_bytes(b),
            Proc::Dec => {
                // VAX F: 16-bit halves swapped against IEEE, exponent bias 128 with a
                // 0.1m mantissa (a factor 4); exponent 0 is zero (or a reserved operand).
                let bits = u32::from_le_bytes([b[2], b[3], b[0], b[1]]);
                let exp = (bits >> 23) & 0xff;
                if exp == 0 {
                    return 0.0;
                }
                let mant = 1.0 + f64::from(bits & 0x7f_ffff) / f64::from(1u32 << 23);
                let v = mant * 2f64.powi(exp as i32 - 129);
                (if bits >> 31 == 1 { -v } else { v }) as f32
            }
        }
    }

    /// A 16-bit integer in this processor's byte order.
    pub(super) fn i16(self, b: &[u8]) -> i16 {
        match self {
            Proc::Mips => i16::from_be_bytes([b[0], b[1]]),
            Proc::Intel | Proc::Dec => i16::from_le_bytes([b[0], b[1]]),
        }
    }
}

/// One parameter: its type (-1 char, 1 byte, 2 int16, 4 float), dimensions and raw data.
struct Param<'a> {
    group: String,
    name: String,
    kind: i8,
    dims: Vec<usize>,
    data: &'a [u8],
}

/// All parameters of a file, looked up by group and name (case-insensitive).
pub(super) struct Params<'a> {
    pub(super) proc: Proc,
    list: Vec<Param<'a>>,
    /// Oddities met while parsing.
    pub(super) warnings: Vec<String>,
}

impl<'a> Params<'a> {
    /// Parses the parameter section that header byte 0 points at.
    pub(super) fn parse(bytes: &'a [u8], file: &str) -> Result<Params<'a>, C3dError> {
        let pointer = bytes[0];
        let bad_ptr = |why: String| C3dError::BadParameterPointer { file: file.into(), pointer, why };
        if pointer < 2 {
            return Err(bad_ptr("the parameter section must start at block 2 or later".into()));
        }
        let start = (usize::from(pointer) - 1) * 512;
        if start + 4 > bytes.len() {
            return Err(bad_ptr(format!("block {pointer} is past the end of the {}-byte file", bytes.len())));
        }
        let proc = match bytes[start + 3] {
            84 => Proc::Intel,
            85 => Proc::Dec,
            86 => Proc::Mips,
            code => return Err(C3dError::UnknownProcessor { file: file.into(), code }),
        };
        let mut params = Params { proc, list: Vec::new(), warnings: Vec::new() };
        let mut groups: Vec<(i8, String)> = Vec::new();
        let mut pending: Vec<(i8, Param<'a>)> = Vec::new();
        let mut at = start + 4;
        let malformed =
            |offset: usize, what: &str| C3dError::BadParameter { file: file.into(), offset, what: what.into() };
        let take = |at: usize, n: usize, what: &str| -> Result<&'a [u8], C3dError> {
            bytes.get(at..at.saturating_add(n)).ok_or_else(|| C3dError::Truncated {
                file: file.into(),
                what: format!("parameter {what} at byte {at}"),
                needed: (at as u64).saturating_add(n as u64),
                len: bytes.len(),
            })
        };
        loop {
            let head = take(at, 2, "record header")?;
            let n_chars = head[0] as i8;
            let id = head[1] as i8;
            if n_chars == 0 {
                break;
            }
            let n_chars = usize::from(n_chars.unsigned_abs());
            let name = String::from_utf8_lossy(take(at + 2, n_chars, "name")?).trim().to_ascii_uppercase();
            let off_at = at + 2 + n_chars;
            let next = proc.i16(take(off_at, 2, "next-record offset")?);
            if id < 0 {
                // Group −128 has no parameter that could name it (ids are at most 127).
                match id.checked_neg() {
                    Some(g) => groups.push((g, name)),
                    None => params.warnings.push(format!("group {name} with id {id} ignored")),
                }
            } else if id > 0 {
                let kind = take(off_at + 2, 1, "type")?[0] as i8;
                if !matches!(kind, -1 | 1 | 2 | 4) {
                    return Err(malformed(off_at + 2, &format!("parameter {name} has unknown type {kind}")));
                }
                let n_dims = usize::from(take(off_at + 3, 1, "dimension count")?[0]);
                let dims: Vec<usize> =
                    take(off_at + 4, n_dims, "dimensions")?.iter().map(|&d| usize::from(d)).collect();
                // At most 255 dimensions of at most 255: saturate, then check against the file.
                let count = dims.iter().fold(1usize, |a, &d| a.saturating_mul(d));
                let size = count.saturating_mul(usize::from(kind.unsigned_abs()));
                let data = take(off_at + 4 + n_dims, size, &format!("{name} data"))?;
                pending.push((id, Param { group: String::new(), name, kind, dims, data }));
            } else {
                params.warnings.push(format!("parameter record {name} with group id 0 ignored"));
            }
            if next <= 0 {
                break;
            }
            at = off_at + next as usize;
        }
        for (id, mut p) in pending {
            match groups.iter().find(|(g, _)| *g == id) {
                Some((_, g)) => p.group = g.clone(),
                None => params.warnings.push(format!("parameter {} is in undeclared group {id}", p.name)),
            }
            params.list.push(p);
        }
        Ok(params)
    }

    fn get(&self, group: &str, name: &str) -> Option<&Param<'a>> {
        self.list.iter().find(|p| p.group == group && p.name == name)
    }

    /// Numeric values (int16, byte or float) as f64.
    fn numbers(&self, group: &str, name: &str) -> Option<Vec<f64>> {
        let p = self.get(group, name)?;
        let values = match p.kind {
            1 => p.data.iter().map(|&b| f64::from(b)).collect(),
            2 => p.data.chunks_exact(2).map(|w| f64::from(self.proc.i16(w))).collect(),
            4 => p.data.chunks_exact(4).map(|w| f64::from(self.proc.f32(w))).collect(),
            _ => return None,
        };
        Some(values)
    }

    /// First value as a float.
    pub(super) fn float(&self, group: &str, name: &str) -> Option<f64> {
        self.numbers(group, name)?.first().copied()
    }

    /// First value as an unsigned count: int16 read as unsigned 16-bit, floats rounded.
    pub(super) fn uint(&self, group: &str, name: &str) -> Option<u64> {
        let p = self.get(group, name)?;
        match p.kind {
            2 => p.data.get(..2).map(|w| u64::from(self.proc.i16(w) as u16)),
            1 | 4 => {
                let v = self.float(group, name)?;
                (v.is_finite() && v >= 0.0).then(|| v.round().min(u32::MAX as f64) as u64)
            }
            _ => None,
        }
    }

    /// Two int16 words combined as an unsigned 32-bit value (low word first).
    pub(super) fn u32_pair(&self, group: &str, name: &str) -> Option<u64> {
        let p = self.get(group, name)?;
        let v = self.numbers(group, name)?;
        match (p.kind, v.as_slice()) {
            (2, [lo, hi, ..]) => Some(u64::from(*lo as i16 as u16) | u64::from(*hi as i16 as u16) << 16),
            (4 | 1, [x, ..]) if x.is_finite() && *x >= 0.0 => Some(x.round().min(u32::MAX as f64) as u64),
            _ => None,
        }
    }

    /// A char parameter as strings: the first dimension is the string length, trailing
    /// spaces and NULs trimmed.
    pub(super) fn strings(&self, group: &str, name: &str) -> Option<Vec<String>> {
        let p = self.get(group, name)?;
        if p.kind != -1 {
            return None;
        }
        let width = match p.dims.first() {
            Some(&w) if p.dims.len() > 1 => w,
            _ => p.data.len(),
        };
        if width == 0 {
            return Some(Vec::new());
        }
        let text = |c: &[u8]| String::from_utf8_lossy(c).trim_end_matches([' ', '\0']).to_string();
        Some(p.data.chunks(width).map(text).collect())
    }

    /// A char parameter as one string (the first, for multi-string parameters).
    pub(super) fn string(&self, group: &str, name: &str) -> Option<String> {
        self.strings(group, name)?.into_iter().next()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parameter section (block 2) of group records `(id, name)` after a header block.
    fn section(records: &[(i8, &str)]) -> Vec<u8> {
        let mut b = vec![0u8; 512];
        b[0] = 2;
        b[1] = 0x50;
        b.extend([1, 0x50, 1, 84]);
        for (i, (id, name)) in records.iter().enumerate() {
            b.push(name.len() as u8);
            b.push(*id as u8);
            b.extend(name.as_bytes());
            let next: i16 = if i + 1 == records.len() { 0 } else { 3 };
            b.extend(next.to_le_bytes());
            b.push(0);
        }
        b.resize(1024, 0);
        b
    }

    #[test]
    fn a_group_id_of_minus_128_is_ignored_with_a_warning_not_a_panic() {
        let bytes = section(&[(-1, "POINT"), (-128, "ODD")]);
        let p = Params::parse(&bytes, "odd.c3d").expect("parses");
        assert!(p.warnings.iter().any(|w| w.contains("ODD") && w.contains("-128")), "{:?}", p.warnings);
    }
}
