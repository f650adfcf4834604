//! Whole archives: `datasets.toml` ([`config`]), finding trials by subject ([`discover`]),
//! splitting them between cluster jobs ([`shard`]), converting each subject (calibrated once) to
//! one MCAP file per trial ([`convert`], [`mcap_out`]), and reading those files back ([`inspect`]).

pub mod config;
pub mod convert;
pub mod discover;
pub mod export;
pub mod hook;
pub mod inspect;
pub mod lock;
pub mod mcap_check;
pub mod mcap_out;
pub mod mcap_robot;
pub mod merge;
pub mod progress;
pub mod proto;
pub mod schemas;
pub mod shard;
pub mod synthetic;
pub mod trial_job;

pub use convert::{convert, ConvertOptions, ConvertSummary, TrialOutcome};

/// SHA-256 of a file's bytes, lowercase hex, read in blocks (memory does not grow with its size).
pub fn sha256_file(path: &std::path::Path) -> std::io::Result<String> {
    use sha2::{Digest, Sha256};
    use std::io::Read;
    let mut f = std::fs::File::open(path)?;
    let (mut h, mut buf) = (Sha256::new(), vec![0u8; 1 << 16]);
    loop {
        match f.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => h.update(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        }
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// SHA-256 of a byte string, lowercase hex.
pub fn sha256_hex(data: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(data).iter().map(|b| format!("{b:02x}")).collect()
}
