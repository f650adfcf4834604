//! A structural check of an MCAP file before the `mcap` crate reads it: every length field is
//! bounded by what contains it, so a corrupt or hostile file is an error naming the record, not
//! an allocation of what its lengths claim (the crate trusts them: a schema name length of
//! `0xFFFFFFFF` allocated 4 GB, a chunk's uncompressed size 2.4 EB).
//!
//! Checked: the leading and trailing magic; each record's length within the file (or its
//! chunk); inside every record of the specification (header, footer, schema, channel, message,
//! chunk, message index, chunk index, attachment, attachment index, statistics, metadata,
//! metadata index, summary offset, data end) every string, byte array, map and array length
//! within the record; the footer last; every offset in the footer and the indexes on the start
//! of a record of the kind (and length) it names; every chunk's
//! compression (none or zstd), its uncompressed size (at most [`MAX_CHUNK_BYTES`]) and its
//! records, once decompressed (with the size checked against the declared one); the data
//! section's CRC (data end record) and the summary's (footer), when recorded. Records of
//! unknown opcodes are skipped by their length, as the specification says. Encoding-agnostic:
//! message payloads are not looked into.

/// The largest uncompressed chunk accepted (bytes).
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Why a file is not a well-formed MCAP file: what was wrong and at which byte offset.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("not a complete MCAP file: {what} (at byte {offset})")]
pub struct McapFormatError {
    pub what: String,
    pub offset: u64,
}

/// A bounded little-endian reader over one record's body.
struct Body<'a> {
    buf: &'a [u8],
    pos: usize,
    /// Offset of `buf[0]` in the file (for messages).
    base: u64,
    record: &'static str,
}

impl<'a> Body<'a> {
    fn err(&self, what: impl std::fmt::Display) -> McapFormatError {
        McapFormatError { what: format!("{} record: {what}", self.record), offset: self.base + self.pos as u64 }
    }
    fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], McapFormatError> {
        let left = (self.buf.len() - self.pos) as u64;
        if n > left {
            return Err(self.err(format_args!("{what} needs {n} bytes, {left} left")));
        }
        let s = &self.buf[self.pos..self.pos + n as usize];
        self.pos += n as usize;
        Ok(s)
    }
    fn u8(&mut self, what: &str) -> Result<u8, McapFormatError> {
        Ok(self.take(1, what)?[0])
    }
    fn u16(&mut self, what: &str) -> Result<u16, McapFormatError> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into().expect("2 bytes")))
    }
    fn u32(&mut self, what: &str) -> Result<u32, McapFormatError> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self, what: &str) -> Result<u64, McapFormatError> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
    /// A `u32`-prefixed UTF-8 string.
    fn string(&mut self, what: &str) -> Result<&'a str, McapFormatError> {
        let n = self.u32(what)?;
        let b = self.take(n as u64, what)?;
        std::str::from_utf8(b).map_err(|_| self.err(format_args!("{what} is not UTF-8")))
    }
    /// A `u32`-prefixed byte array.
    fn bytes32(&mut self, what: &str) -> Result<&'a [u8], McapFormatError> {
        let n = self.u32(what)?;
        self.take(n as u64, what)
    }
    /// A `u64`-prefixed byte array.
    fn bytes64(&mut self, what: &str) -> Result<&'a [u8], McapFormatError> {
        let n = self.u64(what)?;
        self.take(n, what)
    }
    /// A `u32` byte length, then entries read by `entry` until exactly that many bytes are used.
    fn group(
        &mut self,
        what: &str,
        mut entry: impl FnMut(&mut Body<'a>) -> Result<(), McapFormatError>,
    ) -> Result<(), McapFormatError> {
        let n = self.u32(what)?;
        let start = self.pos;
        let inner = self.take(n as u64, what)?;
        let mut b = Body { buf: inner, pos: 0, base: self.base + start as u64, record: self.record };
        while b.pos < inner.len() {
            entry(&mut b)?;
        }
        Ok(())
    }
    fn string_map(&mut self, what: &str) -> Result<(), McapFormatError> {
        self.group(what, |b| {
            b.string("map key")?;
            b.string("map value").map(|_| ())
        })
    }
}

/// Where records may appear.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Level {
    File,
    Chunk,
}

/// A reference from one record to another: the opcode expected there (any when `None`), its
/// offset and the total length claimed (opcode and length prefix included; 0 when unknown).
struct Ref {
    op: Option<u8>,
    offset: u64,
    len: u64,
    what: &'static str,
    from: u64,
}

/// Checks `buf` (a whole MCAP file).
pub fn check(buf: &[u8]) -> Result<(), McapFormatError> {
    let len = buf.len() as u64;
    let at = |offset: u64, what: &str| McapFormatError { what: what.into(), offset };
    if buf.len() < 2 * MAGIC.len() || &buf[..8] != MAGIC {
        return Err(at(0, "no MCAP magic at the start (not an MCAP file, or truncated)"));
    }
    if &buf[buf.len() - 8..] != MAGIC {
        return Err(at(len.saturating_sub(8), "no MCAP magic at the end (truncated: the writer did not finish)"));
    }
    let mut starts = std::collections::BTreeMap::new();
    let mut refs = Vec::new();
    records(&buf[8..buf.len() - 8], 8, Level::File, &mut starts, &mut refs)?;
    // The footer ends the file (readers find it from the end).
    match starts.last_key_value() {
        Some((&o, &(0x02, n))) if o + n == len - 8 => {}
        _ => return Err(at(len - 8, "the last record is not a footer (truncated: the writer did not finish)")),
    }
    // The data section's and the summary's CRCs (when the writer recorded them: not 0).
    let u32_at = |o: u64| u32::from_le_bytes(buf[o as usize..o as usize + 4].try_into().expect("4 bytes"));
    let u64_at = |o: u64| u64::from_le_bytes(buf[o as usize..o as usize + 8].try_into().expect("8 bytes"));
    if let Some((&end, _)) = starts.iter().find(|(_, &(op, n))| op == 0x0F && n >= 13) {
        let want = u32_at(end + 9);
        if want != 0 && crc32fast::hash(&buf[..end as usize]) != want {
            return Err(at(end, "the data section's CRC does not match (the file is damaged)"));
        }
    }
    let (&footer, _) = starts.last_key_value().expect("a footer");
    let (summary_start, summary_crc) = (u64_at(footer + 9), u32_at(footer + 9 + 16));
    if summary_start != 0
        && summary_crc != 0
        && summary_start <= footer
        && crc32fast::hash(&buf[summary_start as usize..footer as usize + 9 + 16]) != summary_crc
    {
        return Err(at(summary_start, "the summary's CRC does not match (the file is damaged)"));
    }
    // Every offset that readers follow lands on the start of a record of the right kind and
    // length, so nothing is parsed that was not checked above.
    for r in refs {
        match starts.get(&r.offset) {
            Some(&(op, n)) if r.op.is_none_or(|o| o == op) && (r.len == 0 || r.len == n) => {}
            _ => {
                return Err(at(
                    r.from,
                    &format!("{} at byte {} (length {}) is not the start of such a record", r.what, r.offset, r.len),
                ))
            }
        }
    }
    Ok(())
}

/// Checks the records of `data` (which starts at file offset `base`), noting each record's start
/// (opcode, total length) and the offsets it refers to.
fn records(
    data: &[u8],
    base: u64,
    level: Level,
    starts: &mut std::collections::BTreeMap<u64, (u8, u64)>,
    refs: &mut Vec<Ref>,
) -> Result<(), McapFormatError> {
    let mut pos = 0usize;
    while pos < data.len() {
        let offset = base + pos as u64;
        let left = data.len() - pos;
        if left < 9 {
            return Err(McapFormatError { what: format!("{left} stray bytes where a record should start"), offset });
        }
        let op = data[pos];
        let n = u64::from_le_bytes(data[pos + 1..pos + 9].try_into().expect("8 bytes"));
        if n > (left - 9) as u64 {
            return Err(McapFormatError {
                what: format!("record (opcode 0x{op:02x}) claims {n} bytes, {} left", left - 9),
                offset,
            });
        }
        let body = &data[pos + 9..pos + 9 + n as usize];
        if level == Level::File {
            starts.insert(offset, (op, 9 + n));
        }
        record(op, body, offset + 9, level, refs)?;
        pos += 9 + n as usize;
    }
    Ok(())
}

fn record(op: u8, buf: &[u8], base: u64, level: Level, refs: &mut Vec<Ref>) -> Result<(), McapFormatError> {
    let name: &'static str = match op {
        0x01 => "header",
        0x02 => "footer",
        0x03 => "schema",
        0x04 => "channel",
        0x05 => "message",
        0x06 => "chunk",
        0x07 => "message index",
        0x08 => "chunk index",
        0x09 => "attachment",
        0x0A => "attachment index",
        0x0B => "statistics",
        0x0C => "metadata",
        0x0D => "metadata index",
        0x0E => "summary offset",
        0x0F => "data end",
        _ => return Ok(()),
    };
    let mut b = Body { buf, pos: 0, base, record: name };
    if level == Level::Chunk && !matches!(op, 0x03..=0x05) {
        return Err(b.err("not allowed inside a chunk"));
    }
    // An offset (with the record's total length, 0 when not given) that must be a record start.
    let from = base - 9;
    let mut point = |op: Option<u8>, offset: u64, len: u64, what: &'static str| {
        refs.push(Ref { op, offset, len, what, from });
    };
    match op {
        0x01 => {
            b.string("profile")?;
            b.string("library")?;
        }
        0x02 => {
            let summary = b.u64("summary start")?;
            let offsets = b.u64("summary offset start")?;
            b.u32("summary crc")?;
            // 0: no summary (or no summary offsets); else a record (the footer, when empty).
            if summary != 0 {
                point(None, summary, 0, "summary start");
            }
            if offsets != 0 {
                point(None, offsets, 0, "summary offset start");
            }
        }
        0x03 => {
            b.u16("id")?;
            b.string("name")?;
            b.string("encoding")?;
            b.bytes32("data")?;
        }
        0x04 => {
            b.u16("id")?;
            b.u16("schema id")?;
            b.string("topic")?;
            b.string("message encoding")?;
            b.string_map("metadata")?;
        }
        0x05 => {
            b.u16("channel id")?;
            b.u32("sequence")?;
            b.u64("log time")?;
            b.u64("publish time")?;
        }
        0x06 => chunk(&mut b, refs)?,
        0x07 => {
            b.u16("channel id")?;
            b.group("records", |e| {
                e.u64("log time")?;
                e.u64("offset").map(|_| ())
            })?;
        }
        0x08 => {
            b.u64("message start time")?;
            b.u64("message end time")?;
            let start = b.u64("chunk start offset")?;
            let length = b.u64("chunk length")?;
            point(Some(0x06), start, length, "chunk");
            let mut offsets = Vec::new();
            b.group("message index offsets", |e| {
                e.u16("channel id")?;
                offsets.push(e.u64("offset")?);
                Ok(())
            })?;
            for o in offsets {
                point(Some(0x07), o, 0, "message index");
            }
            b.u64("message index length")?;
            b.string("compression")?;
            let compressed = b.u64("compressed size")?;
            if compressed > length {
                return Err(b.err(format_args!("compressed size {compressed} exceeds the chunk's length {length}")));
            }
            let uncompressed = b.u64("uncompressed size")?;
            if uncompressed > MAX_CHUNK_BYTES {
                return Err(b.err(format_args!("uncompressed size {uncompressed} exceeds {MAX_CHUNK_BYTES}")));
            }
        }
        0x09 => {
            b.u64("log time")?;
            b.u64("create time")?;
            b.string("name")?;
            b.string("media type")?;
            b.bytes64("data")?;
            b.u32("crc")?;
        }
        0x0A => {
            let off = b.u64("offset")?;
            let length = b.u64("length")?;
            point(Some(0x09), off, length, "attachment");
            b.u64("log time")?;
            b.u64("create time")?;
            let size = b.u64("data size")?;
            if size > length {
                return Err(b.err(format_args!("data size {size} exceeds the attachment's length {length}")));
            }
            b.string("name")?;
            b.string("media type")?;
        }
        0x0B => {
            b.u64("message count")?;
            b.u16("schema count")?;
            b.u32("channel count")?;
            b.u32("attachment count")?;
            b.u32("metadata count")?;
            b.u32("chunk count")?;
            b.u64("message start time")?;
            b.u64("message end time")?;
            b.group("channel message counts", |e| {
                e.u16("channel id")?;
                e.u64("count").map(|_| ())
            })?;
        }
        0x0C => {
            b.string("name")?;
            b.string_map("metadata")?;
        }
        0x0D => {
            let off = b.u64("offset")?;
            let length = b.u64("length")?;
            point(Some(0x0C), off, length, "metadata");
            b.string("name")?;
        }
        0x0E => {
            let op = b.u8("group opcode")?;
            let start = b.u64("group start")?;
            b.u64("group length")?;
            point(Some(op), start, 0, "summary group");
        }
        0x0F => {
            b.u32("data section crc")?;
        }
        _ => unreachable!("known opcodes only"),
    }
    // Later versions of the specification may append fields: extra bytes are allowed.
    Ok(())
}

/// A chunk: its header, then its records decompressed (bounded) and checked.
fn chunk(b: &mut Body<'_>, refs: &mut Vec<Ref>) -> Result<(), McapFormatError> {
    b.u64("message start time")?;
    b.u64("message end time")?;
    let uncompressed = b.u64("uncompressed size")?;
    b.u32("uncompressed crc")?;
    let compression = b.string("compression")?;
    let data_at = b.base + b.pos as u64 + 8;
    let data = b.bytes64("records")?;
    if uncompressed > MAX_CHUNK_BYTES {
        return Err(b.err(format_args!("uncompressed size {uncompressed} exceeds {MAX_CHUNK_BYTES}")));
    }
    let plain: std::borrow::Cow<'_, [u8]> = match compression {
        "" => {
            if data.len() as u64 != uncompressed {
                return Err(b.err(format_args!("{} bytes of records, {uncompressed} declared", data.len())));
            }
            data.into()
        }
        "zstd" => {
            use std::io::Read;
            let mut out = Vec::new();
            let dec = zstd::stream::read::Decoder::new(data).map_err(|e| b.err(format_args!("zstd: {e}")))?;
            // One byte more than declared tells a size mismatch without reading further.
            dec.take(uncompressed + 1).read_to_end(&mut out).map_err(|e| b.err(format_args!("zstd: {e}")))?;
            if out.len() as u64 != uncompressed {
                return Err(b.err(format_args!(
                    "records decompress to {}{} bytes, {uncompressed} declared",
                    out.len(),
                    if out.len() as u64 > uncompressed { "+" } else { "" }
                )));
            }
            out.into()
        }
        other => return Err(b.err(format_args!("unsupported compression '{}'", other.escape_debug()))),
    };
    // Offsets inside a chunk are relative to its records; errors are reported at the chunk's data.
    records(&plain, data_at, Level::Chunk, &mut std::collections::BTreeMap::new(), refs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(op: u8, body: &[u8]) -> Vec<u8> {
        let mut v = vec![op];
        v.extend((body.len() as u64).to_le_bytes());
        v.extend(body);
        v
    }

    fn file(records: &[Vec<u8>]) -> Vec<u8> {
        let mut v = MAGIC.to_vec();
        for r in records {
            v.extend(r);
        }
        v.extend(MAGIC);
        v
    }

    fn s(x: &str) -> Vec<u8> {
        let mut v = (x.len() as u32).to_le_bytes().to_vec();
        v.extend(x.as_bytes());
        v
    }

    #[test]
    fn a_small_valid_file_passes() {
        let header = [s(""), s("t")].concat();
        let schema = [1u16.to_le_bytes().to_vec(), s("a"), s("json"), s("{}")].concat();
        let footer = [0u64.to_le_bytes().to_vec(), 0u64.to_le_bytes().to_vec(), 0u32.to_le_bytes().to_vec()].concat();
        assert_eq!(check(&file(&[rec(1, &header), rec(3, &schema), rec(2, &footer)])), Ok(()));
        let e = check(&file(&[rec(1, &header), rec(3, &schema)])).unwrap_err();
        assert!(e.what.contains("not a footer"), "{e}");
    }

    #[test]
    fn a_schema_name_longer_than_its_record_is_an_error_not_an_allocation() {
        let mut schema = 1u16.to_le_bytes().to_vec();
        schema.extend(u32::MAX.to_le_bytes());
        schema.extend(b"abc");
        let e = check(&file(&[rec(3, &schema)])).unwrap_err();
        assert!(e.what.contains("schema record: name needs 4294967295 bytes"), "{e}");
    }

    #[test]
    fn a_record_longer_than_the_file_and_a_huge_chunk_are_errors() {
        let mut f = file(&[rec(1, &[s(""), s("")].concat())]);
        f[9..17].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(check(&f).unwrap_err().what.contains("claims"));
        let mut chunk = [0u64.to_le_bytes(), 0u64.to_le_bytes(), (u64::MAX / 8).to_le_bytes()].concat();
        chunk.extend(0u32.to_le_bytes());
        chunk.extend(s("zstd"));
        chunk.extend(0u64.to_le_bytes());
        let e = check(&file(&[rec(6, &chunk)])).unwrap_err();
        assert!(e.what.contains("exceeds"), "{e}");
    }

    #[test]
    fn a_truncated_file_says_so() {
        let f = file(&[rec(1, &[s(""), s("")].concat())]);
        let e = check(&f[..f.len() - 3]).unwrap_err();
        assert!(e.to_string().contains("truncated"), "{e}");
    }
}
