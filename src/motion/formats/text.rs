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
