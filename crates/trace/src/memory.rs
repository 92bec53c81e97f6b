//! The memory a run may use, for checking sizes that come from input before they are
//! allocated: a clear error naming the request instead of an abort in the allocator.

/// Bytes of memory available to new allocations: `MemAvailable` of `/proc/meminfo` on Linux,
/// `None` where the system does not say.
pub fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// A request for more memory than is available, or a byte count that cannot be parsed.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum MemoryError {
    /// `what` needs more memory than is available.
    #[error("{what} needs about {} of memory, more than the {} available", human(*needed), human(*available))]
    TooLarge {
        /// What needs the memory.
        what: String,
        /// Bytes it needs.
        needed: u64,
        /// Bytes available.
        available: u64,
    },
    /// The text is not a byte count.
    #[error("`{0}`: not a byte count (e.g. 4096, 512M, 2G)")]
    NotBytes(String),
}

/// An error when `bytes` (what `what` needs) exceed the available memory.
pub fn check_fits(what: &str, bytes: u64) -> Result<(), MemoryError> {
    match available_bytes() {
        Some(free) if bytes > free => Err(MemoryError::TooLarge {
            what: what.to_string(),
            needed: bytes,
            available: free,
        }),
        _ => Ok(()),
    }
}

/// Parses a byte count: digits with an optional binary unit `K`, `M`, `G` or `T` (`KiB`,
/// `MB`... also read as powers of 1024), e.g. `2G`, `512MiB`, `1048576`.
pub fn parse_bytes(text: &str) -> Result<u64, MemoryError> {
    let t = text.trim();
    let digits = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (number, unit) = t.split_at(digits);
    let shift = match unit.trim().to_ascii_uppercase().as_str() {
        "" | "B" => 0,
        "K" | "KB" | "KIB" => 10,
        "M" | "MB" | "MIB" => 20,
        "G" | "GB" | "GIB" => 30,
        "T" | "TB" | "TIB" => 40,
        _ => return Err(MemoryError::NotBytes(text.to_string())),
    };
    number
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(1u64 << shift))
        .ok_or_else(|| MemoryError::NotBytes(text.to_string()))
}

/// A byte count with a binary unit.
pub fn human(bytes: u64) -> String {
    const UNITS: [&str; 7] = ["bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} bytes")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_beyond_the_machine_are_refused_by_name() {
        assert!(check_fits("a small scan", 1024).is_ok());
        if available_bytes().is_some() {
            let e = check_fits("--count 10^9", u64::MAX)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("--count 10^9 needs about 16.0 EiB"), "{e}");
        }
        assert_eq!(human(3 * 1024 * 1024 * 1024), "3.0 GiB");
        assert_eq!(human(12), "12 bytes");
    }
}
