//! What the Linux kernel reports about this process and the machine
//! (`/proc`): resident memory now and at its peak, and the memory
//! available. Elsewhere these read as unknown (`None` or 0).

/// A `kB` field `key` (e.g. `VmRSS:`) of a `/proc` file, in kB.
fn kb_field(file: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(file).ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix(key))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

/// The process's resident memory now (`VmRSS`, bytes).
pub fn resident_bytes() -> Option<u64> {
    kb_field("/proc/self/status", "VmRSS:")?.checked_mul(1024)
}

/// The process's peak resident memory (`VmHWM`, kB; 0 where unknown).
pub fn peak_resident_kb() -> u64 {
    kb_field("/proc/self/status", "VmHWM:").unwrap_or(0)
}

/// The machine's `MemAvailable` (bytes).
pub fn available_memory() -> Option<u64> {
    kb_field("/proc/meminfo", "MemAvailable:")?.checked_mul(1024)
}

#[cfg(test)]
mod tests {
    #[test]
    fn this_process_has_memory_on_linux() {
        if cfg!(target_os = "linux") {
            let now = super::resident_bytes().unwrap();
            assert!(now > 0 && super::peak_resident_kb() * 1024 >= now / 2);
            assert!(super::available_memory().unwrap() > 0);
        }
    }
}
