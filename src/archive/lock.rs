//! One `smocap convert` at a time per output folder: an exclusive advisory lock
//! (`flock`-style, [`std::fs::File::try_lock`]) on `<out>/.smocap-convert.lock`, held for the
//! whole run. A second run into the same `--out` stops at once with an error instead of writing
//! the same temporary files. The lock goes with the process (also when it is killed); the lock
//! file itself stays, empty.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

/// Name of the lock file inside the output folder.
pub const LOCK_FILE: &str = ".smocap-convert.lock";

/// Errors taking the lock.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error(
        "{out}: another smocap convert is writing into this folder (it holds {lock}); wait for it to end or use another --out"
    )]
    Held { out: String, lock: String },
}

/// The held lock; dropping it releases it.
#[derive(Debug)]
pub struct OutLock {
    _file: File,
    pub path: PathBuf,
}

/// Creates `out` when missing and takes its lock, without waiting.
pub fn lock_out(out: &Path) -> Result<OutLock, LockError> {
    let io = |p: &Path| {
        let path = p.display().to_string();
        move |source| LockError::Io { path, source }
    };
    std::fs::create_dir_all(out).map_err(io(out))?;
    let path = out.join(LOCK_FILE);
    let file = OpenOptions::new().create(true).truncate(false).write(true).open(&path).map_err(io(&path))?;
    match file.try_lock() {
        Ok(()) => Ok(OutLock { _file: file, path }),
        Err(TryLockError::WouldBlock) => {
            Err(LockError::Held { out: out.display().to_string(), lock: path.display().to_string() })
        }
        Err(TryLockError::Error(source)) => Err(LockError::Io { path: path.display().to_string(), source }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_on_one_folder_is_refused_until_the_first_is_dropped() {
        let dir = std::env::temp_dir().join(format!("smocap-lock-{}", std::process::id()));
        let first = lock_out(&dir).unwrap();
        let second = lock_out(&dir);
        assert!(matches!(second, Err(LockError::Held { .. })), "{second:?}");
        drop(first);
        assert!(lock_out(&dir).is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
