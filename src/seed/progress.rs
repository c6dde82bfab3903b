//! The resume state of a seed: which subtrees are finished, written
//! atomically (temporary file, then rename) about once a second and at the
//! end, so a seeder killed at any moment resumes from its last save.
//!
//! The state is a set of finished subtree roots: when a tile is finished (it
//! and every tile below it were made, its children walked first), its
//! children leave the set and it enters. Every root in the set has an
//! unfinished parent, which some worker is walking or under which a tile
//! failed, so the set stays about as small as the walk's frontier (plus a
//! few siblings per level above each failure), however many tiles the job
//! has. A resumed walk skips the subtrees in the set and retries the rest;
//! tiles finished after the last save are found in the cache, newer than the
//! job's start, and kept.

use crate::grid::TileId;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Saves at most this often (and at the end).
const EVERY: Duration = Duration::from_secs(1);

/// The file's contents.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
struct State {
    /// Digest of everything that defines the job.
    job: String,
    /// The cache it writes to (none in files from before it was recorded).
    #[serde(default)]
    cache: String,
    /// When the job first started, Unix ms.
    started_ms: u64,
    /// Tile files made or found by the job's runs so far (a resumed dry run
    /// says it; the bar counts what is left from `done`).
    products: u64,
    /// Finished subtree roots, `level/row/col`.
    done: Vec<String>,
    /// The whole walk finished.
    complete: bool,
}

/// Why the progress file cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct ProgressError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// The resume state of a running job.
#[derive(Debug)]
pub struct Progress {
    path: PathBuf,
    job: String,
    cache: String,
    started: SystemTime,
    done: Mutex<HashSet<TileId>>,
    saved: Mutex<Instant>,
    /// Products counted by earlier runs of this job.
    pub earlier: u64,
    /// The job had finished before.
    pub complete: bool,
}

impl Progress {
    /// A new state at `path` (replacing an old one) of `job`, which
    /// writes to `cache`.
    pub fn start(path: &Path, job: &str, cache: &str) -> Progress {
        Progress {
            path: path.to_path_buf(),
            job: job.to_string(),
            cache: cache.to_string(),
            started: SystemTime::now(),
            done: Mutex::new(HashSet::new()),
            saved: Mutex::new(Instant::now()),
            earlier: 0,
            complete: false,
        }
    }

    /// The saved state of `job` at `path`; an error if the file is another
    /// job's, or the job wrote to another cache than the one named `caches`
    /// (the subtrees it finished are not there).
    pub fn resume(path: &Path, job: &str, caches: &[String]) -> Result<Progress, ProgressError> {
        let fail = |message: String| ProgressError { path: path.to_path_buf(), message };
        let text = std::fs::read_to_string(path).map_err(|e| fail(format!("cannot resume: {e}")))?;
        let state: State = serde_json::from_str(&text).map_err(|e| fail(format!("not a seed progress file: {e}")))?;
        if state.job != job {
            return Err(fail(
                "written by another job (other grid, layers, formats, levels, area, shard or configuration); run without --resume to start afresh".into(),
            ));
        }
        if !state.cache.is_empty() && !caches.contains(&state.cache) {
            let (wrote, here) = (&state.cache, caches.first().map_or("", String::as_str));
            return Err(fail(format!(
                "this job wrote to the cache {wrote}, not to {here}, which lacks the tiles it finished: resume it with that cache, or run without --resume to start afresh (if they are one cache under two names, remove the \"cache\" entry from this file)"
            )));
        }
        let done = state
            .done
            .iter()
            .map(|t| parse_tile(t).ok_or_else(|| fail(format!("bad tile {t:?}"))))
            .collect::<Result<_, _>>()?;
        Ok(Progress {
            path: path.to_path_buf(),
            job: job.to_string(),
            // A file from before the cache was recorded records it now.
            cache: Some(state.cache).filter(|c| !c.is_empty()).or_else(|| caches.first().cloned()).unwrap_or_default(),
            started: UNIX_EPOCH + Duration::from_millis(state.started_ms),
            done: Mutex::new(done),
            saved: Mutex::new(Instant::now()),
            earlier: state.products,
            complete: state.complete,
        })
    }

    /// When the job first started.
    pub fn started(&self) -> SystemTime {
        self.started
    }

    /// True if `tile`'s subtree was finished.
    pub fn is_done(&self, tile: TileId) -> bool {
        self.done.lock().is_ok_and(|d| d.contains(&tile))
    }

    /// Marks `tile`'s subtree finished (its `children` were); saves if due.
    pub fn finish(&self, tile: TileId, children: &[TileId], products: u64) -> std::io::Result<()> {
        if let Ok(mut done) = self.done.lock() {
            for c in children {
                done.remove(c);
            }
            done.insert(tile);
        }
        if super::due(&self.saved, EVERY) { self.save(products, false) } else { Ok(()) }
    }

    /// Writes the state now (atomically).
    pub fn save(&self, products: u64, complete: bool) -> std::io::Result<()> {
        let done = self.done.lock().map(|d| d.iter().map(|t| t.to_string()).collect()).unwrap_or_default();
        let started_ms = self.started.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64);
        let (job, cache) = (self.job.clone(), self.cache.clone());
        let state = State { job, cache, started_ms, products: self.earlier + products, done, complete };
        let text = serde_json::to_string(&state).map_err(std::io::Error::other)?;
        let tmp = self.path.with_extension(format!("tmp{}", std::process::id()));
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, &self.path)
    }

    /// The finished subtrees' roots.
    pub fn finished(&self) -> Vec<TileId> {
        self.done.lock().map(|d| d.iter().copied().collect()).unwrap_or_default()
    }

    /// Finished subtrees held (the set's size stays near the walk's frontier).
    pub fn held(&self) -> usize {
        self.done.lock().map_or(0, |d| d.len())
    }
}

/// `level/row/col`.
pub fn parse_tile(text: &str) -> Option<TileId> {
    let mut parts = text.trim().split('/').map(|p| p.parse::<u64>().ok());
    let (Some(Some(level)), Some(Some(row)), Some(Some(col)), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return None;
    };
    Some(TileId::new(u32::try_from(level).ok()?, row, col))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finished_subtrees_replace_their_children_and_resume() {
        let path = std::env::temp_dir().join(format!("sylva-progress-{}.json", std::process::id()));
        let p = Progress::start(&path, "job1", "directory /a");
        let parent = TileId::new(3, 1, 1);
        let kids = parent.children();
        for k in kids {
            p.finish(k, &[], 1).unwrap();
        }
        assert_eq!(p.held(), 4);
        p.finish(parent, &kids, 5).unwrap();
        assert_eq!(p.held(), 1);
        p.save(5, false).unwrap();
        let names = |n: &[&str]| n.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let r = Progress::resume(&path, "job1", &names(&["directory /a"])).unwrap();
        assert!(r.is_done(parent) && !r.is_done(kids[0]));
        assert_eq!((r.earlier, r.complete), (5, false));
        assert_eq!(
            r.started().duration_since(UNIX_EPOCH).unwrap().as_millis(),
            p.started().duration_since(UNIX_EPOCH).unwrap().as_millis()
        );
        let err = Progress::resume(&path, "job2", &names(&["directory /a"])).unwrap_err().to_string();
        assert!(err.contains("another job"), "{err}");
        // Regression: resumed into another cache, a job skipped the subtrees
        // it had finished in the first, and left the second incomplete.
        let err = Progress::resume(&path, "job1", &names(&["directory /b"])).unwrap_err().to_string();
        assert!(err.contains("wrote to the cache directory /a, not to directory /b"), "{err}");
        // The same cache by another of its names (its links resolved).
        assert!(Progress::resume(&path, "job1", &names(&["directory /b", "directory /a"])).is_ok());
        // A file from before the cache was recorded resumes anywhere.
        let text = std::fs::read_to_string(&path).unwrap().replace(r#""cache":"directory /a","#, "");
        std::fs::write(&path, text).unwrap();
        assert!(Progress::resume(&path, "job1", &names(&["directory /b"])).is_ok());
        std::fs::remove_file(&path).unwrap();
        assert_eq!(parse_tile("12/3/4"), Some(TileId::new(12, 3, 4)));
        assert_eq!(parse_tile("12/3"), None);
    }
}
