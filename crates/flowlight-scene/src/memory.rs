//! How many bytes this process may still allocate, for the checks that refuse a scene or an
//! image too large for the machine before anything is allocated.
//!
//! The room is the least of three limits, each read where Linux publishes it:
//!
//! - the host's free memory: `MemAvailable` of `/proc/meminfo`;
//! - the memory cgroup the process runs in, which is how Slurm (`task/cgroup`), Kubernetes
//!   and `systemd-run -p MemoryMax=` confine a task: for cgroup v2 `memory.max − memory.current`,
//!   for cgroup v1 `memory.limit_in_bytes − memory.usage_in_bytes`, at the process's own
//!   cgroup (from `/proc/self/cgroup`) and at each ancestor up to the mount point, since a
//!   parent's limit binds its children too;
//! - the address space under `RLIMIT_AS` (`ulimit -v`, Slurm's `VSizeFactor`): the soft limit
//!   of `/proc/self/limits` minus the process's `VmSize` of `/proc/self/status`.
//!
//! `MemAvailable` alone sees neither of the last two: a render sized by it was OOM-killed
//! inside a 1 GiB cgroup, or aborted on a failed allocation under `ulimit -v`, with no message.
//! Every file is optional: a limit that cannot be read is no limit.

use std::path::{Path, PathBuf};

/// cgroup v1 reports "no limit" as the largest page-aligned `i64`; anything this large is none.
const UNLIMITED_V1: u64 = 1 << 62;

/// Where the limits are read: `/proc` and `/sys/fs/cgroup` on a real system, a fake tree in
/// the tests.
#[derive(Clone, Debug)]
pub struct MemorySources {
    pub proc_root: PathBuf,
    pub cgroup_root: PathBuf,
}

/// The bytes this process may still allocate ([`MemorySources::available`] of the system's
/// files), `None` where no limit can be read.
pub fn available_memory() -> Option<u64> {
    MemorySources::system().available()
}

impl MemorySources {
    pub fn system() -> MemorySources {
        MemorySources {
            proc_root: PathBuf::from("/proc"),
            cgroup_root: PathBuf::from("/sys/fs/cgroup"),
        }
    }

    /// The least of the host's `MemAvailable`, the cgroup's room and the address space left.
    pub fn available(&self) -> Option<u64> {
        [
            self.mem_available(),
            self.cgroup_room(),
            self.address_space_room(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn read(&self, path: &Path) -> Option<String> {
        std::fs::read_to_string(path).ok()
    }

    /// `MemAvailable` of `meminfo`, in bytes.
    pub fn mem_available(&self) -> Option<u64> {
        let info = self.read(&self.proc_root.join("meminfo"))?;
        kib_field(&info, "MemAvailable:")
    }

    /// The least room left under the memory cgroup limits of the process's cgroup and its
    /// ancestors (v2 and v1 alike).
    pub fn cgroup_room(&self) -> Option<u64> {
        let membership = self.read(&self.proc_root.join("self/cgroup"))?;
        let mut rooms = Vec::new();
        for line in membership.lines() {
            let mut fields = line.splitn(3, ':');
            let (Some(id), Some(controllers), Some(rel)) =
                (fields.next(), fields.next(), fields.next())
            else {
                continue;
            };
            let rel = rel.trim_start_matches('/');
            if id == "0" && controllers.is_empty() {
                // cgroup v2: mounted at the root, or beside v1 controllers under `unified`.
                let base = if self.cgroup_root.join("cgroup.controllers").exists() {
                    self.cgroup_root.clone()
                } else {
                    self.cgroup_root.join("unified")
                };
                rooms.extend(room_up_the_tree(&base, rel, "memory.max", "memory.current"));
            } else if controllers.split(',').any(|c| c == "memory") {
                let base = self.cgroup_root.join("memory");
                rooms.extend(room_up_the_tree(
                    &base,
                    rel,
                    "memory.limit_in_bytes",
                    "memory.usage_in_bytes",
                ));
            }
        }
        rooms.into_iter().min()
    }

    /// The soft `RLIMIT_AS` less the process's current `VmSize`, in bytes.
    pub fn address_space_room(&self) -> Option<u64> {
        let limits = self.read(&self.proc_root.join("self/limits"))?;
        let line = limits
            .lines()
            .find(|l| l.starts_with("Max address space"))?;
        let soft: u64 = line
            .trim_start_matches("Max address space")
            .split_whitespace()
            .next()?
            .parse()
            .ok()?;
        let status = self.read(&self.proc_root.join("self/status"))?;
        let used = kib_field(&status, "VmSize:").unwrap_or(0);
        Some(soft.saturating_sub(used))
    }
}

/// `key   N kB` of a `/proc` file, in bytes.
fn kib_field(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line[key.len()..].split_whitespace().next()?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The least `limit − usage` over the cgroup directory `base/rel` and its ancestors up to
/// `base`. Where `rel` is not under `base` (a cgroup namespace shows the process its own
/// cgroup as the root), only `base` is read.
fn room_up_the_tree(base: &Path, rel: &str, limit_file: &str, usage_file: &str) -> Option<u64> {
    let own = base.join(rel);
    let start = if own.is_dir() {
        own
    } else {
        base.to_path_buf()
    };
    let mut least: Option<u64> = None;
    for dir in start.ancestors().take_while(|d| d.starts_with(base)) {
        let Ok(limit) = std::fs::read_to_string(dir.join(limit_file)) else {
            continue;
        };
        let Ok(limit) = limit.trim().parse::<u64>() else {
            continue; // "max": no limit at this level.
        };
        if limit >= UNLIMITED_V1 {
            continue;
        }
        let usage = std::fs::read_to_string(dir.join(usage_file))
            .ok()
            .and_then(|u| u.trim().parse::<u64>().ok())
            .unwrap_or(0);
        let room = limit.saturating_sub(usage);
        least = Some(least.map_or(room, |l| l.min(room)));
    }
    least
}

#[cfg(test)]
mod tests {
    use super::*;

    const GIB: u64 = 1 << 30;

    /// A fake `/proc` and `/sys/fs/cgroup` with 20 GiB available on the host.
    struct Fake {
        root: PathBuf,
    }

    impl Fake {
        fn new(tag: &str) -> Fake {
            let root =
                std::env::temp_dir().join(format!("flowlight-memory-{}-{tag}", std::process::id()));
            let _ = std::fs::remove_dir_all(&root);
            let f = Fake { root };
            f.write(
                "proc/meminfo",
                &format!(
                    "MemTotal: 33554432 kB\nMemAvailable: {} kB\n",
                    20 * GIB / 1024
                ),
            );
            f
        }
        fn write(&self, rel: &str, text: &str) {
            let p = self.root.join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        }
        fn sources(&self) -> MemorySources {
            MemorySources {
                proc_root: self.root.join("proc"),
                cgroup_root: self.root.join("cgroup"),
            }
        }
    }

    impl Drop for Fake {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.root);
        }
    }

    #[test]
    fn d5_cgroup_v2_memory_max_bounds_the_room() {
        let f = Fake::new("v2");
        f.write("proc/self/cgroup", "0::/job_7/step_0/task_1\n");
        f.write("cgroup/cgroup.controllers", "cpu memory\n");
        f.write("cgroup/job_7/memory.max", &format!("{}\n", GIB));
        f.write("cgroup/job_7/memory.current", &format!("{}\n", GIB / 4));
        f.write("cgroup/job_7/step_0/memory.max", "max\n");
        f.write("cgroup/job_7/step_0/task_1/memory.max", "max\n");
        f.write("cgroup/job_7/step_0/task_1/memory.current", "0\n");
        // The job's 1 GiB limit, of which a quarter is used, binds the task below it.
        assert_eq!(f.sources().available(), Some(3 * GIB / 4));
        assert_eq!(f.sources().mem_available(), Some(20 * GIB));
    }

    #[test]
    fn d5_cgroup_v1_limit_in_bytes_bounds_the_room() {
        let f = Fake::new("v1");
        f.write(
            "proc/self/cgroup",
            "5:cpu,cpuacct:/\n4:memory:/slurm/uid_0/job_3\n0::/\n",
        );
        f.write(
            "cgroup/memory/memory.limit_in_bytes",
            "9223372036854771712\n",
        );
        f.write(
            "cgroup/memory/slurm/uid_0/job_3/memory.limit_in_bytes",
            &format!("{}\n", 2 * GIB),
        );
        f.write(
            "cgroup/memory/slurm/uid_0/job_3/memory.usage_in_bytes",
            &format!("{}\n", GIB / 2),
        );
        assert_eq!(f.sources().available(), Some(3 * GIB / 2));
        // Seen from inside a cgroup namespace the process's cgroup is the mount's root.
        f.write("proc/self/cgroup", "4:memory:/elsewhere\n");
        f.write("cgroup/memory/memory.limit_in_bytes", &format!("{}\n", GIB));
        assert_eq!(f.sources().available(), Some(GIB));
    }

    #[test]
    fn d5_rlimit_as_less_vmsize_bounds_the_room() {
        let f = Fake::new("rlimit");
        f.write(
            "proc/self/limits",
            "Limit                     Soft Limit           Hard Limit           Units\n\
             Max address space         1536000000           unlimited            bytes\n",
        );
        f.write(
            "proc/self/status",
            "Name:\tflowlight\nVmSize:\t  500000 kB\n",
        );
        assert_eq!(f.sources().available(), Some(1_536_000_000 - 512_000_000));
        f.write(
            "proc/self/limits",
            "Max address space         unlimited            unlimited            bytes\n",
        );
        assert_eq!(f.sources().available(), Some(20 * GIB));
    }

    #[test]
    fn this_process_has_some_room() {
        assert!(available_memory().is_some_and(|b| b > 0));
    }
}
