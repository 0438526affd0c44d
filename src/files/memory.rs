//! Host memory: what the machine has free, so that a load or a build that cannot fit is
//! refused before it allocates, with the number, the limit and what changes it.
//!
//! The limit is `MemAvailable` of `/proc/meminfo` (memory the kernel can hand out without
//! swapping), read when asked; `VMLS_HOST_MEMORY=BYTES` sets it instead (a lower ceiling on a
//! shared machine, or a test). Where neither is known (not Linux), nothing is refused.

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
    let Ok(info) = std::fs::read_to_string("/proc/meminfo") else {
        return Ok(None);
    };
    Ok(info
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|rest| {
            rest.trim()
                .trim_end_matches("kB")
                .trim()
                .parse::<u64>()
                .ok()
        })
        .map(|kib| kib * 1024))
}

/// Refuses `bytes` of host memory for `what` when more than is available: the message says
/// how much, the limit, and `change` (the key or flag that lowers the need).
pub fn check(what: &str, bytes: u64, change: &str) -> Result<(), String> {
    match available()? {
        Some(limit) if bytes > limit => Err(format!(
            "{what} needs {bytes} bytes of host memory, more than the {limit} available \
             (MemAvailable, or {VARIABLE}); {change}"
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
