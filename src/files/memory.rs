//! Host memory: what the machine has free, so that a load or a build that cannot fit is
//! refused before it allocates, with the number, the limit and what changes it.
//!
//! The limit is `MemAvailable` of `/proc/meminfo` (memory the kernel can hand out without
//! swapping), or less where this process's memory cgroup allows less (a container: its
//! limit minus its usage, cgroup v2 `memory.max`/`memory.current` or v1
//! `memory.limit_in_bytes`/`memory.usage_in_bytes`), read when asked; `VMLS_HOST_MEMORY=BYTES`
//! sets it instead (a lower ceiling on a shared machine, or a test). Where none is known (not
//! Linux), nothing is refused.

/// The variable that sets the host memory limit.
pub const VARIABLE: &str = "VMLS_HOST_MEMORY";

/// Bytes a load or build may take, or `None` when unknown; a bad `VMLS_HOST_MEMORY` is an
/// error naming it.
pub fn available() -> Result<Option<u64>, String> {
    if let Some(v) = std::env::var_os(VARIABLE) {
        let text = v.to_string_lossy();
        return text.trim().parse::<u64>().map(Some).map_err(|_| {
            format!(
                "{VARIABLE}={}: expected a byte count",
                super::excerpt_text(&text, 40)
            )
        });
    }
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let meminfo = read("/proc/meminfo").and_then(|info| {
        info.lines()
            .find_map(|l| l.strip_prefix("MemAvailable:"))
            .and_then(|rest| {
                rest.trim()
                    .trim_end_matches("kB")
                    .trim()
                    .parse::<u64>()
                    .ok()
            })
            .map(|kib| kib * 1024)
    });
    let cgroup = read("/proc/self/cgroup").and_then(|c| cgroup_headroom(&c, read));
    Ok(match (meminfo, cgroup) {
        (Some(m), Some(c)) => Some(m.min(c)),
        (m, c) => m.or(c),
    })
}

/// What this process's memory cgroup still allows (limit − usage, where usage leaves out the
/// inactive file cache the kernel reclaims first), from `/proc/self/cgroup`'s text and a file
/// reader; `None` without a limit (v1 reports "no limit" as a number near 2^63) or where the
/// files cannot be read. Limits set on parent groups are not looked at.
fn cgroup_headroom(cgroup: &str, read: impl Fn(&str) -> Option<String>) -> Option<u64> {
    let number = |p: String| read(&p)?.trim().parse::<u64>().ok();
    // memory.stat's inactive file cache: "inactive_file N" (v2), "total_inactive_file N" (v1).
    let cache = |dir: &str, key: &str| {
        read(&format!("{dir}/memory.stat"))
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix(key)?.trim().parse::<u64>().ok())
            })
            .unwrap_or(0)
    };
    let headroom = |limit: Option<u64>, usage: Option<u64>, cache: u64| match (limit, usage) {
        (Some(l), Some(u)) if l < 1 << 62 => Some(l.saturating_sub(u.saturating_sub(cache))),
        _ => None,
    };
    for line in cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let path = path.trim_end_matches('/');
        if controllers.is_empty() {
            // v2: the unified hierarchy ("max" means no limit).
            let dir = format!("/sys/fs/cgroup{path}");
            if let Some(found) = headroom(
                number(format!("{dir}/memory.max")),
                number(format!("{dir}/memory.current")),
                cache(&dir, "inactive_file "),
            ) {
                return Some(found);
            }
        } else if controllers.split(',').any(|c| c == "memory") {
            // v1: the group's directory, or the mount's root where a container sees only its
            // own group there.
            for dir in [
                format!("/sys/fs/cgroup/memory{path}"),
                "/sys/fs/cgroup/memory".into(),
            ] {
                if let Some(found) = headroom(
                    number(format!("{dir}/memory.limit_in_bytes")),
                    number(format!("{dir}/memory.usage_in_bytes")),
                    cache(&dir, "total_inactive_file "),
                ) {
                    return Some(found);
                }
            }
        }
    }
    None
}

/// Refuses `bytes` of host memory for `what` when more than is available: the message says
/// how much, the limit, and `change` (the key or flag that lowers the need).
pub fn check(what: &str, bytes: u64, change: &str) -> Result<(), String> {
    match available()? {
        Some(limit) if bytes > limit => Err(format!(
            "{what} needs {bytes} bytes of host memory, more than the {limit} available \
             (MemAvailable or the memory cgroup's headroom, or {VARIABLE}); {change}"
        )),
        _ => Ok(()),
    }
}

/// This process's peak resident memory in bytes (`VmHWM` of `/proc/self/status`), for
/// `--stats`; `None` where unknown. On a unified-memory device (lavapipe) it includes the
/// device's buffers.
pub fn peak_resident() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse::<u64>()
        .ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_memory_cgroup_limits_what_is_available() {
        let files = |entries: &'static [(&'static str, &'static str)]| {
            move |p: &str| {
                entries
                    .iter()
                    .find(|(name, _)| *name == p)
                    .map(|(_, text)| text.to_string())
            }
        };
        // v2: 2 GiB limit, 0.5 GiB used of which 0.25 GiB is inactive file cache.
        let v2 = files(&[
            ("/sys/fs/cgroup/job/memory.max", "2147483648\n"),
            ("/sys/fs/cgroup/job/memory.current", "536870912\n"),
            (
                "/sys/fs/cgroup/job/memory.stat",
                "anon 1000\nactive_file 5\ninactive_file 268435456\n",
            ),
        ]);
        assert_eq!(super::cgroup_headroom("0::/job\n", v2), Some(1879048192));
        // v2 without a limit.
        let unlimited = files(&[
            ("/sys/fs/cgroup/memory.max", "max\n"),
            ("/sys/fs/cgroup/memory.current", "1000\n"),
        ]);
        assert_eq!(super::cgroup_headroom("0::/\n", unlimited), None);
        // v1: the group's own directory is absent, the mount's root holds the limit.
        let v1 = files(&[
            ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "1000000\n"),
            ("/sys/fs/cgroup/memory/memory.usage_in_bytes", "1200000\n"),
        ]);
        let text = "5:devices:/\n4:memory:/docker/abc\n0::/\n";
        assert_eq!(super::cgroup_headroom(text, v1), Some(0));
        // v1 "no limit" (this machine's: 9223372036854771712).
        let none = files(&[
            (
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "9223372036854771712\n",
            ),
            ("/sys/fs/cgroup/memory/memory.usage_in_bytes", "5\n"),
        ]);
        assert_eq!(super::cgroup_headroom("4:memory:/\n", none), None);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn this_machine_reports_its_free_memory() {
        // Unset here (tests that set it run vmls as a child process).
        if std::env::var_os(super::VARIABLE).is_none() {
            let free = super::available()
                .expect("readable")
                .expect("Linux has MemAvailable");
            assert!(free > 1 << 20, "{free}");
            assert!(super::check("nothing", 0, "").is_ok());
            let e = super::check("a test", u64::MAX, "lower it").expect_err("too much");
            assert!(e.contains("a test needs") && e.contains("lower it"), "{e}");
        }
    }
}
