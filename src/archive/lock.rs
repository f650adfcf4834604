//! Which `smocap convert` runs may write into one output folder at once: advisory locks
//! (`flock`-style, [`std::fs::File::try_lock`]) held for the whole run.
//!
//! - An unsharded run holds `<out>/.smocap-convert.lock` exclusively: no other run writes there.
//! - A run of shard `I/N` holds that lock shared, and `<out>/.smocap-convert.shard-I-of-N.lock`
//!   exclusively: the other shards of the same archive (same `N`, as a job array's tasks) run
//!   side by side (their subjects, hence their output files, are disjoint), while a second run of
//!   the same shard, an unsharded run, or a run cut into another number of shards (whose subjects
//!   would overlap) stops at once with an error.
//!
//! The shard count of the running shards is written in `<out>/.smocap-convert.shards`; the
//! decisions are taken under a brief exclusive lock on `<out>/.smocap-convert.gate`. Locks go
//! with the process (also when it is killed); the lock files stay, empty.

use super::shard::Shard;
use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

/// Name of the folder's lock file inside the output folder.
pub const LOCK_FILE: &str = ".smocap-convert.lock";
/// Taken briefly (blocking) while a run decides whether it may start.
const GATE_FILE: &str = ".smocap-convert.gate";
/// The shard count of the shards running now.
const COUNT_FILE: &str = ".smocap-convert.shards";

/// The lock file of one shard inside the output folder.
pub fn shard_lock_file(s: Shard) -> String {
    format!(".smocap-convert.shard-{}-of-{}.lock", s.index, s.count)
}

/// Errors taking the locks.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error(
        "{out}: another smocap convert is writing into this folder (it holds {lock}); wait for it to end or use another --out"
    )]
    Held { out: String, lock: String },
    #[error(
        "{out}: another smocap convert is writing into this folder as shards of {running} (this run is shard {index}/{count}); shards running side by side must share their count"
    )]
    OtherCount { out: String, running: usize, index: usize, count: usize },
}

/// The held locks; dropping them releases them.
#[derive(Debug)]
pub struct OutLock {
    _files: Vec<File>,
    /// The lock that keeps other runs of this one out: the folder's, or the shard's.
    pub path: PathBuf,
}

fn open(path: &Path) -> Result<File, LockError> {
    OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(path)
        .map_err(|source| LockError::Io { path: path.display().to_string(), source })
}

/// `Ok(true)` when taken, `Ok(false)` when another holds it.
fn try_take(file: &File, path: &Path, shared: bool) -> Result<bool, LockError> {
    let r = if shared { file.try_lock_shared() } else { file.try_lock() };
    match r {
        Ok(()) => Ok(true),
        Err(TryLockError::WouldBlock) => Ok(false),
        Err(TryLockError::Error(source)) => Err(LockError::Io { path: path.display().to_string(), source }),
    }
}

/// Creates `out` when missing and takes the locks of a run of `shard` (the whole archive when
/// `None`), without waiting for other runs (only for another run's decision, a few file
/// operations).
pub fn lock_out(out: &Path, shard: Option<Shard>) -> Result<OutLock, LockError> {
    std::fs::create_dir_all(out).map_err(|source| LockError::Io { path: out.display().to_string(), source })?;
    let held = |p: &Path| LockError::Held { out: out.display().to_string(), lock: p.display().to_string() };
    let path = out.join(LOCK_FILE);
    let folder = open(&path)?;
    let Some(s) = shard else {
        return if try_take(&folder, &path, false)? {
            Ok(OutLock { _files: vec![folder], path })
        } else {
            Err(held(&path))
        };
    };
    let gate_path = out.join(GATE_FILE);
    let gate = open(&gate_path)?;
    gate.lock().map_err(|source| LockError::Io { path: gate_path.display().to_string(), source })?;
    let count_path = out.join(COUNT_FILE);
    let io = |source| LockError::Io { path: count_path.display().to_string(), source };
    if try_take(&folder, &path, false)? {
        // Nobody writes here: this run sets the shard count, then shares the folder.
        std::fs::write(&count_path, s.count.to_string()).map_err(io)?;
        folder.unlock().map_err(|source| LockError::Io { path: path.display().to_string(), source })?;
        if !try_take(&folder, &path, true)? {
            return Err(held(&path));
        }
    } else {
        // A whole run holds it exclusively; else shards do, of the count they wrote.
        if !try_take(&folder, &path, true)? {
            return Err(held(&path));
        }
        let running = std::fs::read_to_string(&count_path).ok().and_then(|t| t.trim().parse::<usize>().ok());
        if let Some(n) = running.filter(|&n| n != s.count) {
            return Err(LockError::OtherCount {
                out: out.display().to_string(),
                running: n,
                index: s.index,
                count: s.count,
            });
        }
    }
    let shard_path = out.join(shard_lock_file(s));
    let file = open(&shard_path)?;
    if !try_take(&file, &shard_path, false)? {
        return Err(held(&shard_path));
    }
    drop(gate);
    Ok(OutLock { _files: vec![folder, file], path: shard_path })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("smocap-lock-{}-{name}", std::process::id()))
    }

    #[test]
    fn a_second_lock_on_one_folder_is_refused_until_the_first_is_dropped() {
        let dir = dir("whole");
        let first = lock_out(&dir, None).unwrap();
        let second = lock_out(&dir, None);
        assert!(matches!(second, Err(LockError::Held { .. })), "{second:?}");
        drop(first);
        assert!(lock_out(&dir, None).is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn different_shards_share_a_folder_and_the_same_shard_another_count_or_a_whole_run_are_refused() {
        let dir = dir("shards");
        let sh = |s: &str| Some(s.parse::<Shard>().unwrap());
        let a = lock_out(&dir, sh("0/3")).unwrap();
        let b = lock_out(&dir, sh("2/3")).unwrap();
        assert!(matches!(lock_out(&dir, sh("0/3")), Err(LockError::Held { .. })));
        assert!(matches!(lock_out(&dir, sh("1/2")), Err(LockError::OtherCount { running: 3, .. })));
        assert!(matches!(lock_out(&dir, None), Err(LockError::Held { .. })));
        drop((a, b));
        // Free again: a whole run, then shards of another count.
        let whole = lock_out(&dir, None).unwrap();
        assert!(matches!(lock_out(&dir, sh("1/2")), Err(LockError::Held { .. })));
        drop(whole);
        assert!(lock_out(&dir, sh("1/2")).is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
