//! The host's one worker pool.
//!
//! The host owns the threads: a render's work units, the AOV pass and the pure-Rust BVH's
//! build all run on one rayon pool, made on first use and kept for later renders of the
//! process (a Python sweep renders many times; starting threads each time would count
//! against every render's budget). A render that asks for another thread count gets a pool
//! of that count, kept beside the first (a thread-scaling sweep keeps one per count; idle
//! rayon threads sleep). Rayon's global pool is never started by the host.

use super::effective_threads;
use rayon::ThreadPool;
use std::sync::{Arc, Mutex, PoisonError};

/// The kept pools, with the thread count each was asked for (0: one per core).
static KEPT: Mutex<Vec<(usize, Arc<ThreadPool>)>> = Mutex::new(Vec::new());

/// The worker pool for `requested` threads (0: one per core; clamped as
/// [`effective_threads`] says): the kept one of that count, else a new one, kept.
pub fn worker_pool(requested: usize) -> Result<Arc<ThreadPool>, String> {
    let threads = effective_threads(requested);
    let mut kept = KEPT.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some((_, pool)) = kept.iter().find(|(n, _)| *n == threads) {
        return Ok(pool.clone());
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("flowlight-worker-{i}"))
        .build()
        .map_err(|e| format!("cannot start the thread pool: {e}"))?;
    let pool = Arc::new(pool);
    kept.push((threads, pool.clone()));
    Ok(pool)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_pool_serves_every_call_with_the_same_thread_count() {
        let a = worker_pool(3).unwrap();
        let b = worker_pool(3).unwrap();
        assert!(Arc::ptr_eq(&a, &b), "a second render started another pool");
        assert_eq!(a.current_num_threads(), 3);
        let names = a.install(|| std::thread::current().name().map(str::to_owned));
        assert_eq!(
            names.as_deref().map(|n| n.starts_with("flowlight-worker-")),
            Some(true)
        );
    }

    #[test]
    fn another_thread_count_gets_its_own_pool() {
        let one = worker_pool(1).unwrap();
        let three = worker_pool(3).unwrap();
        assert!(!Arc::ptr_eq(&one, &three));
        assert_eq!(one.install(rayon::current_num_threads), 1);
        assert_eq!(three.install(rayon::current_num_threads), 3);
    }
}
