//! A seed job's hold on the files it records into (its progress and
//! failed-tiles files) for as long as it runs, so that a second job that
//! would write the same files is refused when it starts rather than
//! overwriting the first one's record. The hold is an advisory exclusive
//! lock (`flock`) on `FILE.lock` beside each file, which names the holder's
//! PID; the kernel releases it when the process ends however it ends, and a
//! job that ends removes the file while it still holds it. The lock lies
//! beside the file a path resolves to (two links to one file are one
//! record). Where the filesystem cannot lock (an NFS mount without its lock
//! service), the job says so and runs unguarded, as it did before holds.

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

/// Holds `record` for this job (`None`: its filesystem cannot lock, said
/// once); an error names the job that holds it.
pub fn hold(record: &Path) -> Result<Option<Hold>, SeedError> {
    let lock = lock_of(&crate::outputs::resolve(record));
    let io = |source| SeedError::Io { path: lock.clone(), source };
    loop {
        let mut file =
            OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&lock).map_err(io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => return Err(in_use(record, &lock)),
            Err(TryLockError::Error(e)) if cannot_lock(&e) => {
                let _ = std::fs::remove_file(&lock);
                crate::outputs::say(format_args!(
                    "sylva seed: {}: {e}; another job on this file is not refused",
                    lock.display()
                ));
                return Ok(None);
            }
            Err(TryLockError::Error(e)) => return Err(io(e)),
        }
        if is_at(&file, &lock) {
            file.set_len(0).and_then(|()| write!(file, "{}", std::process::id())).map_err(io)?;
            return Ok(Some(Hold { lock, _file: file }));
        }
    }
}

/// Whether `e` says the filesystem cannot lock files at all (ENOLCK,
/// ENOSYS, EOPNOTSUPP).
fn cannot_lock(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::Unsupported || matches!(e.raw_os_error(), Some(37 | 38 | 95))
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
        let first = hold(&record).unwrap().expect("the temporary directory locks");
        let err = hold(&record).unwrap_err().to_string();
        let named = [&record.display().to_string(), &format!("pid {}", std::process::id()), "--progress-file"];
        assert!(named.iter().all(|n| err.contains(n)), "{err}");
        drop(first);
        assert!(!lock_of(&record).exists(), "the lock file is removed");
        drop(hold(&record).unwrap());
        // A link to the file is the same record.
        std::fs::write(&record, "{}").unwrap();
        let link = record.with_extension("link.json");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&record, &link).unwrap();
        let first = hold(&record).unwrap();
        assert!(hold(&link).is_err(), "a link to a held record is refused");
        drop(first);
        let _ = (std::fs::remove_file(&link), std::fs::remove_file(&record));
        let error = |code| std::io::Error::from_raw_os_error(code);
        assert!(cannot_lock(&error(37)) && !cannot_lock(&error(13)), "ENOLCK, not EACCES");
    }
}
