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
    let file = path.display().to_string();
    let buf = std::fs::read(path).map_err(|source| InspectError::Io { file: file.clone(), source })?;
    let mc = |source| InspectError::Mcap { file: file.clone(), source };
    let summary: Summary =
        Summary::read(&buf).map_err(mc)?.ok_or_else(|| InspectError::NoSummary { file: file.clone() })?;
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
        let m = mcap::read::metadata(&buf, idx).map_err(mc)?;
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

/// The input SHA-256 recorded in a converted trial (`smocap.run` → `input_sha256`).
pub fn recorded_input_hash(path: &Path) -> Option<String> {
    inspect(path).ok()?.metadata.get("smocap.run")?.get("input_sha256").cloned()
}
