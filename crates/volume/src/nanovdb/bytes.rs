//! Checked little-endian reads from byte buffers: every read is `None` past the end.

/// `N` bytes at `off`, or `None` when they do not all lie in `b`.
fn array<const N: usize>(b: &[u8], off: usize) -> Option<[u8; N]> {
    b.get(off..off.checked_add(N)?)?.try_into().ok()
}

pub(crate) fn u8_at(b: &[u8], off: usize) -> Option<u8> {
    b.get(off).copied()
}

pub(crate) fn u16_at(b: &[u8], off: usize) -> Option<u16> {
    array(b, off).map(u16::from_le_bytes)
}

pub(crate) fn u32_at(b: &[u8], off: usize) -> Option<u32> {
    array(b, off).map(u32::from_le_bytes)
}

pub(crate) fn i32_at(b: &[u8], off: usize) -> Option<i32> {
    array(b, off).map(i32::from_le_bytes)
}

pub(crate) fn u64_at(b: &[u8], off: usize) -> Option<u64> {
    array(b, off).map(u64::from_le_bytes)
}

pub(crate) fn i64_at(b: &[u8], off: usize) -> Option<i64> {
    array(b, off).map(i64::from_le_bytes)
}

pub(crate) fn f32_at(b: &[u8], off: usize) -> Option<f32> {
    array(b, off).map(f32::from_le_bytes)
}

pub(crate) fn f64_at(b: &[u8], off: usize) -> Option<f64> {
    array(b, off).map(f64::from_le_bytes)
}

/// The text of a NUL-terminated (or full-length) name field.
pub(crate) fn c_string(b: &[u8]) -> String {
    let end = b.iter().position(|c| *c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

/// `base + delta` as a buffer position, or `None` when it is negative or overflows.
pub(crate) fn offset_by(base: usize, delta: i64) -> Option<usize> {
    usize::try_from(i128::try_from(base).ok()? + delta as i128).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_stop_at_the_end() {
        let b = [1u8, 2, 3, 4, 5];
        assert_eq!(u32_at(&b, 1), Some(u32::from_le_bytes([2, 3, 4, 5])));
        assert_eq!(u32_at(&b, 2), None);
        assert_eq!(u64_at(&b, usize::MAX), None);
        assert_eq!(offset_by(10, -11), None);
        assert_eq!(offset_by(10, -10), Some(0));
        assert_eq!(c_string(b"ab\0cd"), "ab");
        assert_eq!(c_string(b"abc"), "abc");
    }
}
