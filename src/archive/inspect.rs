//! Reading a converted trial back: channels and their message counts, the `smocap.run` metadata,
//! attachments.

use mcap::Summary;
use std::collections::BTreeMap;
use std::path::Path;

/// Errors reading an MCAP file.
#[derive(Debug, thiserror::Error)]
pub enum InspectError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {source}")]
    Mcap { file: String, source: mcap::McapError },
    #[error("{file}: no summary section (an incomplete file?)")]
    NoSummary { file: String },
    #[error("{file}: {source}")]
    Format { file: String, source: super::mcap_check::McapFormatError },
    #[error("{file}: not a regular file")]
    NotAFile { file: String },
    #[error("{file}: {what}")]
    Incomplete { file: String, what: String },
}

/// Reads a regular file whole and checks its MCAP structure ([`super::mcap_check`]) before any
/// MCAP reader looks at it.
pub fn read_checked(path: &Path) -> Result<Vec<u8>, InspectError> {
    let file = path.display().to_string();
    let io = |source| InspectError::Io { file: file.clone(), source };
    if !std::fs::metadata(path).map_err(io)?.is_file() {
        return Err(InspectError::NotAFile { file });
    }
    let buf = std::fs::read(path).map_err(io)?;
    super::mcap_check::check(&buf).map_err(|source| InspectError::Format { file: file.clone(), source })?;
    Ok(buf)
}

/// One channel: topic, schema name, message encoding, message count.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ChannelInfo {
    pub topic: String,
    pub schema: String,
    pub encoding: String,
    pub messages: u64,
}

/// What a file holds.
#[derive(Clone, Debug, serde::Serialize)]
pub struct McapInfo {
    pub channels: Vec<ChannelInfo>,
    pub messages: u64,
    /// Metadata records by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// Attachments: name and size (bytes).
    pub attachments: Vec<(String, u64)>,
}

/// Reads the summary of `path`.
pub fn inspect(path: &Path) -> Result<McapInfo, InspectError> {
    summary_of(&read_checked(path)?, &path.display().to_string())
}

/// The summary of the MCAP file `buf` (named `file` in errors); its structure is checked first.
pub fn inspect_bytes(buf: &[u8], file: &str) -> Result<McapInfo, InspectError> {
    super::mcap_check::check(buf).map_err(|source| InspectError::Format { file: file.to_string(), source })?;
    summary_of(buf, file)
}

/// The summary of `buf`, whose structure was checked.
fn summary_of(buf: &[u8], file: &str) -> Result<McapInfo, InspectError> {
    let file = file.to_string();
    let mc = |source| InspectError::Mcap { file: file.clone(), source };
    let summary: Summary =
        Summary::read(buf).map_err(mc)?.ok_or_else(|| InspectError::NoSummary { file: file.clone() })?;
    let counts = summary.stats.as_ref().map(|s| s.channel_message_counts.clone()).unwrap_or_default();
    let mut channels: Vec<(u16, ChannelInfo)> = summary
        .channels
        .iter()
        .map(|(id, c)| {
            let info = ChannelInfo {
                topic: c.topic.clone(),
                schema: c.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
                encoding: c.message_encoding.clone(),
                messages: counts.get(id).copied().unwrap_or(0),
            };
            (*id, info)
        })
        .collect();
    channels.sort_by_key(|(id, _)| *id);
    let mut metadata = BTreeMap::new();
    for idx in &summary.metadata_indexes {
        let m = mcap::read::metadata(buf, idx).map_err(mc)?;
        metadata.insert(m.name, m.metadata);
    }
    let attachments = summary.attachment_indexes.iter().map(|a| (a.name.clone(), a.data_size)).collect();
    Ok(McapInfo {
        messages: summary.stats.as_ref().map_or(0, |s| s.message_count),
        channels: channels.into_iter().map(|(_, c)| c).collect(),
        metadata,
        attachments,
    })
}

/// Checks that `buf` is a complete file as `smocap convert` writes it: its structure
/// ([`super::mcap_check`]), summary and footer readable, every message readable (chunk CRCs
/// included), as many per channel as the summary's statistics record, and one `/smocap/state`
/// message per frame of `smocap.run` → `frames`. Returns the summary.
pub fn verify_bytes(buf: &[u8], file: &str) -> Result<McapInfo, InspectError> {
    super::mcap_check::check(buf).map_err(|source| InspectError::Format { file: file.to_string(), source })?;
    checked_complete(buf, file)
}

/// [`verify_bytes`] of the file at `path`.
pub fn verify(path: &Path) -> Result<McapInfo, InspectError> {
    checked_complete(&read_checked(path)?, &path.display().to_string())
}

fn checked_complete(buf: &[u8], file: &str) -> Result<McapInfo, InspectError> {
    let info = summary_of(buf, file)?;
    let bad = |what: String| InspectError::Incomplete { file: file.to_string(), what };
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let stream = mcap::MessageStream::new(buf).map_err(|source| InspectError::Mcap { file: file.into(), source })?;
    for m in stream {
        let m = m.map_err(|source| InspectError::Mcap { file: file.into(), source })?;
        *counts.entry(m.channel.topic.clone()).or_default() += 1;
    }
    let total: u64 = counts.values().sum();
    if total != info.messages {
        return Err(bad(format!("{total} messages read, the summary records {}", info.messages)));
    }
    for c in &info.channels {
        let n = counts.get(&c.topic).copied().unwrap_or(0);
        if n != c.messages {
            return Err(bad(format!("{}: {n} messages read, the summary records {}", c.topic, c.messages)));
        }
    }
    let run = info.metadata.get("smocap.run").ok_or_else(|| bad("no smocap.run metadata".into()))?;
    let frames: u64 =
        run.get("frames").and_then(|f| f.parse().ok()).ok_or_else(|| bad("smocap.run has no frame count".into()))?;
    let states = counts.get("/smocap/state").copied().unwrap_or(0);
    if states != frames {
        return Err(bad(format!("{states} /smocap/state messages for the {frames} frames recorded")));
    }
    Ok(info)
}

/// The input SHA-256 recorded in a converted trial (`smocap.run` → `input_sha256`), when the
/// file is complete ([`verify`]); `None` for a file that is not (it is converted again).
pub fn recorded_input_hash(path: &Path) -> Option<String> {
    recorded_run(path)?.get("input_sha256").cloned()
}

/// The `smocap.run` metadata of a complete converted trial ([`verify`]).
pub fn recorded_run(path: &Path) -> Option<BTreeMap<String, String>> {
    verify(path).ok()?.metadata.remove("smocap.run")
}
