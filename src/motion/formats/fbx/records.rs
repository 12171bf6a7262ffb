//! Binary FBX's node records (the layout Blender's developers wrote down in 2013): each
//! record is its end offset, property count, property bytes and name, then its properties,
//! then its children, which end with a null record. Records ≥ 7500 use 64-bit fields.
//!
//! Here: [`mend`], which gives a file back with the null record every nested list must end
//! with, where its writer left them out. assimp 5.2's FBX writer does (its NULL_RECORD is
//! written as a C string, so as nothing: assimp issue #4686); readers that trust the end
//! offsets (assimp's own, Blender's) read such files, ufbx stops at the first list without
//! one. The records are walked with every offset checked against its parent's end, so a
//! hostile file costs one bounded walk and one copy of itself.

/// The deepest nesting a binary FBX is walked to (ufbx's own limit is 32).
const MAX_DEPTH: usize = 32;

const MAGIC: &[u8] = b"Kaydara FBX Binary  \0";
/// The magic, two bytes (0x1A 0x00) and the version.
const HEADER: usize = 27;

/// One record: where its name and properties lie, and its children.
struct Record {
    /// Name length byte, name and property bytes, as in the file.
    head: std::ops::Range<usize>,
    props: u64,
    children: Vec<Record>,
    /// Its children's list ended with a null record.
    closed: bool,
}

struct Walk<'a> {
    bytes: &'a [u8],
    wide: bool,
    /// Nested lists found without their null record.
    open: usize,
}

impl Walk<'_> {
    fn header_len(&self) -> usize {
        if self.wide {
            25
        } else {
            13
        }
    }

    fn word(&self, at: usize, i: usize) -> Option<u64> {
        let b = self.bytes;
        if self.wide {
            let s = b.get(at + 8 * i..at + 8 * i + 8)?;
            Some(u64::from_le_bytes(s.try_into().ok()?))
        } else {
            let s = b.get(at + 4 * i..at + 4 * i + 4)?;
            Some(u64::from(u32::from_le_bytes(s.try_into().ok()?)))
        }
    }

    /// The records from `at` to `end`: `(records, closed)`.
    fn list(&mut self, mut at: usize, end: usize, depth: usize) -> Option<(Vec<Record>, bool)> {
        if depth > MAX_DEPTH {
            return None;
        }
        let h = self.header_len();
        let mut out = Vec::new();
        while at < end {
            let header = self.bytes.get(at..at + h)?;
            if header.iter().all(|&b| b == 0) {
                return Some((out, true));
            }
            let record_end = usize::try_from(self.word(at, 0)?).ok()?;
            let props = self.word(at, 1)?;
            let props_len = usize::try_from(self.word(at, 2)?).ok()?;
            let name_len = usize::from(*self.bytes.get(at + h - 1)?);
            let head = at + h - 1..(at + h).checked_add(name_len)?.checked_add(props_len)?;
            if record_end > end || head.end > record_end || record_end <= at {
                return None;
            }
            let (children, closed) = if head.end < record_end {
                let (c, closed) = self.list(head.end, record_end, depth + 1)?;
                self.open += usize::from(!closed);
                (c, closed)
            } else {
                (Vec::new(), false)
            };
            out.push(Record {
                head,
                props,
                children,
                closed,
            });
            at = record_end;
        }
        Some((out, false))
    }
}

/// The file with every nested list closed by its null record, when its writer left some
/// out (`Some(mended)`); `None` when it needs nothing or is not a binary FBX this walk can
/// read (ufbx then says what is wrong with it).
pub(crate) fn mend(bytes: &[u8]) -> Option<Vec<u8>> {
    if !bytes.starts_with(MAGIC) || bytes.len() < HEADER {
        return None;
    }
    let version = u32::from_le_bytes(bytes[23..27].try_into().ok()?);
    let mut walk = Walk {
        bytes,
        wide: version >= 7500,
        open: 0,
    };
    let (top, closed) = walk.list(HEADER, bytes.len(), 0)?;
    if walk.open == 0 || !closed {
        return None;
    }
    let h = walk.header_len();
    // Where the top list's null record ends: the footer after it is kept as it is.
    let mut top_end = HEADER;
    for r in &top {
        top_end = end_of(r, bytes, &walk);
    }
    let footer = bytes.get(top_end + h..)?;
    let mut out = Vec::with_capacity(bytes.len() + walk.open * h);
    out.extend_from_slice(&bytes[..HEADER]);
    for r in &top {
        write(r, bytes, walk.wide, &mut out);
    }
    out.extend(std::iter::repeat_n(0u8, h));
    out.extend_from_slice(footer);
    Some(out)
}

/// Where record `r` ends in the original file.
fn end_of(r: &Record, bytes: &[u8], walk: &Walk) -> usize {
    let at = r.head.start + 1 - walk.header_len();
    walk.word(at, 0).map_or(bytes.len(), |e| e as usize)
}

fn write(r: &Record, bytes: &[u8], wide: bool, out: &mut Vec<u8>) {
    let start = out.len();
    let h = if wide { 25 } else { 13 };
    let props_len = r.head.len() - 1 - usize::from(bytes[r.head.start]);
    let words = [0u64, r.props, props_len as u64];
    for w in words {
        if wide {
            out.extend(w.to_le_bytes());
        } else {
            out.extend((w as u32).to_le_bytes());
        }
    }
    out.extend_from_slice(&bytes[r.head.clone()]);
    for c in &r.children {
        write(c, bytes, wide, out);
    }
    if !r.children.is_empty() || r.closed {
        out.extend(std::iter::repeat_n(0u8, h));
    }
    let end = out.len() as u64;
    if wide {
        out[start..start + 8].copy_from_slice(&end.to_le_bytes());
    } else {
        out[start..start + 4].copy_from_slice(&(end as u32).to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record: name, one i32 property, children, and whether its list is closed.
    fn record(name: &str, children: &[Vec<u8>], closed: bool, at: usize) -> Vec<u8> {
        let props = [b"I".as_slice(), &7i32.to_le_bytes()].concat();
        let mut body = vec![name.len() as u8];
        body.extend(name.as_bytes());
        body.extend(&props);
        let mut kids = Vec::new();
        for c in children {
            kids.extend(c);
        }
        if closed {
            kids.extend([0u8; 25]);
        }
        let end = at + 24 + body.len() + kids.len();
        let mut out = Vec::new();
        for w in [end as u64, 1, props.len() as u64] {
            out.extend(w.to_le_bytes());
        }
        out.extend(body);
        out.extend(kids);
        out
    }

    fn file(closed: bool) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend([0x1a, 0]);
        out.extend(7500u32.to_le_bytes());
        // Offsets are absolute: a child begins after its parent's header, name and props.
        let parent_at = out.len();
        let child_at = parent_at + 25 + "Objects".len() + 5;
        let child = record("Model", &[], false, child_at);
        out.extend(record("Objects", &[child], closed, parent_at));
        out.extend([0u8; 25]);
        out.extend(b"footer");
        out
    }

    #[test]
    fn lists_without_their_null_record_are_closed() {
        let good = file(true);
        assert_eq!(mend(&good), None, "a file that needs nothing is left alone");
        let mended = mend(&file(false)).expect("the open list is closed");
        assert_eq!(mended, good);
        // Not FBX, cut short, or an offset past its parent: nothing to mend.
        assert_eq!(mend(b"; FBX 7.4.0 project file"), None);
        let broken = file(false);
        assert_eq!(mend(&broken[..broken.len() - 40]), None);
    }
}
