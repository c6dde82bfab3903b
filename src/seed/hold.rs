//! A seed job's hold on the files it records into (its progress and
//! failed-tiles files) for as long as it runs, so that a second job that
//! would write the same files is refused when it starts rather than
//! overwriting the first one's record. The hold is an advisory exclusive
//! lock (`flock`) on `FILE.lock` beside each file, which names the holder's
//! PID; the kernel releases it when the process ends however it ends, and a
//! job that ends removes the file while it still holds it.

use super::SeedError;
use std::fs::{File, OpenOptions, TryLockError};
use std::io::Write;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// This job's hold on a file; released when dropped.
#[derive(Debug)]
pub struct Hold {
    lock: PathBuf,
    _file: File,
}

impl Drop for Hold {
    fn drop(&mut self) {
        // Still held: a job that opened this file meanwhile finds it gone
        // once it has the lock, and takes a new one.
        let _ = std::fs::remove_file(&self.lock);
    }
}

/// Holds `record` for this job; an error names the job that holds it.
pub fn hold(record: &Path) -> Result<Hold, SeedError> {
    let lock = lock_of(record);
    let io = |source| SeedError::Io { path: lock.clone(), source };
    loop {
        let mut file =
            OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&lock).map_err(io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => return Err(in_use(record, &lock)),
            Err(TryLockError::Error(e)) => return Err(io(e)),
        }
        if is_at(&file, &lock) {
            file.set_len(0).and_then(|()| write!(file, "{}", std::process::id())).map_err(io)?;
            return Ok(Hold { lock, _file: file });
        }
    }
}

/// `FILE.lock`.
fn lock_of(record: &Path) -> PathBuf {
    let mut name = record.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

/// True if `file` is still the one at `path` (not removed by a holder that
/// ended after it was opened).
fn is_at(file: &File, path: &Path) -> bool {
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => (a.dev(), a.ino()) == (b.dev(), b.ino()),
        _ => false,
    }
}

/// The error for `record` held by another job, named by the PID its lock
/// file holds.
fn in_use(record: &Path, lock: &Path) -> SeedError {
    let pid = std::fs::read_to_string(lock).unwrap_or_default();
    let holder = match pid.trim() {
        "" => "its pid not written yet".to_string(),
        pid => format!("pid {pid}"),
    };
    SeedError::InUse { file: record.to_path_buf(), lock: lock.to_path_buf(), holder }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_held_by_a_job_is_refused_to_another_until_the_first_ends() {
        // Regression: a second job in the same directory overwrote the
        // first one's progress and failed-tiles files.
        let record = std::env::temp_dir().join(format!("sylva-hold-{}.json", std::process::id()));
        let first = hold(&record).unwrap();
        let err = hold(&record).unwrap_err().to_string();
        let named = [&record.display().to_string(), &format!("pid {}", std::process::id()), "--progress-file"];
        assert!(named.iter().all(|n| err.contains(n)), "{err}");
        drop(first);
        assert!(!lock_of(&record).exists(), "the lock file is removed");
        drop(hold(&record).unwrap());
    }
}
