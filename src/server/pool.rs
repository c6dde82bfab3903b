//! The bounded pool that runs CPU work (tile computations) off the async
//! executor: a rayon pool of `workers` threads, with at most `queue` jobs
//! waiting. A job beyond that is refused at once (the caller answers 503)
//! rather than piling up until every request times out.
//!
//! The pipeline's own data parallelism (rayon iterators inside a stage) runs
//! on the same threads, so CPU use stays within `workers`.

use std::sync::Arc;
use thiserror::Error;
use tokio::sync::{Semaphore, oneshot};

/// Why a job did not run.
#[derive(Clone, Debug, Error)]
pub enum PoolError {
    /// Every worker is busy and the queue is full.
    #[error("all {0} tile workers are busy and the queue is full; retry shortly")]
    Busy(usize),
    /// The job panicked (a bug; the worker survives).
    #[error("a tile computation failed unexpectedly")]
    Lost,
}

/// Workers for CPU-bound jobs.
pub struct Pool {
    threads: rayon::ThreadPool,
    permits: Arc<Semaphore>,
    workers: usize,
}

impl Pool {
    /// `workers` threads (0 = one per core) and room for `queue` waiting jobs.
    pub fn new(workers: usize, queue: usize) -> std::io::Result<Pool> {
        let threads = rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .thread_name(|i| format!("sylva-tile-{i}"))
            .build()
            .map_err(std::io::Error::other)?;
        let workers = threads.current_num_threads();
        Ok(Pool { threads, permits: Arc::new(Semaphore::new(workers + queue)), workers })
    }

    /// Number of worker threads.
    pub fn workers(&self) -> usize {
        self.workers
    }

    /// Runs `job` on a worker and waits for it without blocking the executor.
    pub async fn run<T: Send + 'static>(&self, job: impl FnOnce() -> T + Send + 'static) -> Result<T, PoolError> {
        let permit = self.permits.clone().try_acquire_owned().map_err(|_| PoolError::Busy(self.workers))?;
        let (tx, rx) = oneshot::channel();
        self.threads.spawn(move || {
            let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job));
            // Free the slot before answering, so that a caller that has its
            // answer can use the slot again at once.
            drop(permit);
            let _ = tx.send(out);
        });
        match rx.await {
            Ok(Ok(value)) => Ok(value),
            _ => Err(PoolError::Lost),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn jobs_run_and_a_full_queue_refuses() {
        let pool = Arc::new(Pool::new(1, 1).unwrap());
        assert_eq!(pool.run(|| 6 * 7).await.unwrap(), 42);
        let (go_tx, go_rx) = std::sync::mpsc::channel::<()>();
        let go_rx = Arc::new(std::sync::Mutex::new(go_rx));
        let blocked: Vec<_> = (0..2)
            .map(|_| {
                let (pool, go_rx) = (pool.clone(), go_rx.clone());
                tokio::spawn(async move { pool.run(move || go_rx.lock().map(|r| r.recv()).is_ok()).await })
            })
            .collect();
        // Both jobs hold their slots (one running, one queued) before the third comes.
        while pool.permits.available_permits() > 0 {
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
        assert!(matches!(pool.run(|| ()).await, Err(PoolError::Busy(1))));
        go_tx.send(()).unwrap();
        go_tx.send(()).unwrap();
        for b in blocked {
            assert!(b.await.unwrap().unwrap());
        }
        assert!(matches!(pool.run(|| panic!("boom")).await, Err(PoolError::Lost)));
    }
}
