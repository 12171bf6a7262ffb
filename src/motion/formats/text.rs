//! Helpers shared by the text formats.

use std::borrow::Cow;

/// The input as text. Invalid UTF-8 (Latin-1 joint names from old exporters) is replaced
/// rather than rejected: names are labels, the numbers are ASCII either way.
pub(crate) fn as_text(bytes: &[u8]) -> Cow<'_, str> {
    let b = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    String::from_utf8_lossy(b)
}

/// Lines with their 1-based numbers, without trailing `\r`.
pub(crate) fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.split('\n')
        .enumerate()
        .map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)))
}

/// Append `v` in the shortest form that parses back to the same f32; NaN as `nan_text`.
pub(crate) fn push_f32(out: &mut String, v: f32, nan_text: &str) {
    use std::fmt::Write;
    if v.is_finite() {
        let _ = write!(out, "{v}");
    } else {
        out.push_str(nan_text);
    }
}
