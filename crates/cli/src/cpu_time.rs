//! CPU time of this process (all threads, user + system), for the render summary's
//! `cpu time` line.
//!
//! On a shared machine a render's wall time depends on what else runs; its CPU time (the sum
//! over the worker threads of the time they were on a core) much less. The peer comparison
//! (`crates/flowlight-bench/peers/peers.py`, docs/performance.md) divides it by the samples
//! rendered to compare CPU per sample with Mitsuba 3, which it measures the same way
//! (`time.process_time()` around the render, which is `getrusage(RUSAGE_SELF)` too). Taken
//! around the render only, it leaves out scene loading and the BVH build; it includes the
//! progress bar's thread (idle with `--quiet`).

use std::time::Duration;

/// User + system CPU time of the whole process so far (`getrusage(RUSAGE_SELF)`), or `None`
/// where that call is not available or fails.
pub fn process_cpu_time() -> Option<Duration> {
    #[cfg(unix)]
    {
        let mut ru = std::mem::MaybeUninit::<libc::rusage>::zeroed();
        // SAFETY: `ru` is a valid, writable rusage; getrusage only writes into it.
        let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, ru.as_mut_ptr()) };
        if rc != 0 {
            return None;
        }
        // SAFETY: getrusage returned 0, so it filled the struct (and zeroed() made every
        // field initialised to begin with).
        let ru = unsafe { ru.assume_init() };
        let tv = |t: libc::timeval| {
            Duration::from_secs(t.tv_sec.max(0) as u64)
                + Duration::from_micros(t.tv_usec.max(0) as u64)
        };
        Some(tv(ru.ru_utime) + tv(ru.ru_stime))
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// Peak resident memory of this process so far (`VmHWM` of `/proc/self/status`, bytes), for
/// the summary's `peak memory` line; `None` where there is no such file.
pub fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Busy work on two threads for a measured wall time: the process CPU time must grow by
    /// at least most of one thread's wall time (each thread spins the whole time; a loaded
    /// machine may deschedule them, hence the lenient bound) and never go backwards.
    #[test]
    fn cpu_time_counts_busy_threads() {
        let Some(t0) = process_cpu_time() else {
            return; // not available on this platform
        };
        let spin = || {
            let start = std::time::Instant::now();
            let mut x = 0u64;
            while start.elapsed() < Duration::from_millis(200) {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
            start.elapsed()
        };
        let h = std::thread::spawn(spin);
        let wall = spin();
        h.join().unwrap();
        let t1 = process_cpu_time().unwrap();
        assert!(t1 >= t0);
        let used = (t1 - t0).as_secs_f64();
        // Two spinning threads use up to 2 × wall; on 2 shared cores at least a fifth of one.
        assert!(
            used > 0.2 * wall.as_secs_f64() && used < 2.0 * wall.as_secs_f64() + 0.1,
            "cpu {used} s for two threads spinning {} s",
            wall.as_secs_f64()
        );
    }
}
