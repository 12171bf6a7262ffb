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

/// The records of a binary FBX, walked by their lengths.
struct Walk<'a> {
    bytes: &'a [u8],
    wide: bool,
    /// Nested lists found without their null record.
    open: usize,
}

/// One record's header: where it ends, its property count and the end of its name and
/// properties (where its children begin).
struct Head {
    end: usize,
    props: u64,
    body_end: usize,
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

    /// The record at `at` within a list ending at `end`, or `None` for the null record
    /// there; `Err(())` where the file contradicts itself.
    fn head(&self, at: usize, end: usize) -> Result<Option<Head>, ()> {
        let h = self.header_len();
        let header = self.bytes.get(at..at + h).ok_or(())?;
        if header.iter().all(|&b| b == 0) {
            return Ok(None);
        }
        let record_end = usize::try_from(self.word(at, 0).ok_or(())?).map_err(|_| ())?;
        let props = self.word(at, 1).ok_or(())?;
        let props_len = usize::try_from(self.word(at, 2).ok_or(())?).map_err(|_| ())?;
        let name_len = usize::from(header[h - 1]);
        let body_end = (at + h)
            .checked_add(name_len)
            .and_then(|e| e.checked_add(props_len))
            .ok_or(())?;
        if record_end > end || body_end > record_end || record_end <= at {
            return Err(());
        }
        Ok(Some(Head {
            end: record_end,
            props,
            body_end,
        }))
    }

    /// Counts the lists from `at` to `end` (and below) that lack their null record; the
    /// offset where this list stops (its null record, or `end`) and whether it is closed.
    /// Holds nothing per record: a file of millions of records costs a walk, not a tree.
    fn scan(&mut self, mut at: usize, end: usize, depth: usize) -> Result<(usize, bool), ()> {
        if depth > MAX_DEPTH {
            return Err(());
        }
        while at < end {
            let Some(head) = self.head(at, end)? else {
                return Ok((at, true));
            };
            if head.body_end < head.end {
                let (_, closed) = self.scan(head.body_end, head.end, depth + 1)?;
                self.open += usize::from(!closed);
            }
            at = head.end;
        }
        Ok((end, false))
    }

    /// Writes the records from `at` to `end` with every nested list closed; `scan` has
    /// walked them, so every header reads.
    fn copy(&self, mut at: usize, end: usize, out: &mut Vec<u8>) -> Result<(), ()> {
        let h = self.header_len();
        while at < end {
            let Some(head) = self.head(at, end)? else {
                return Ok(());
            };
            let start = out.len();
            let props_len = head.body_end - (at + h) - usize::from(self.bytes[at + h - 1]);
            for w in [0u64, head.props, props_len as u64] {
                if self.wide {
                    out.extend(w.to_le_bytes());
                } else {
                    out.extend((w as u32).to_le_bytes());
                }
            }
            out.extend_from_slice(&self.bytes[at + h - 1..head.body_end]);
            if head.body_end < head.end {
                self.copy(head.body_end, head.end, out)?;
                out.extend(std::iter::repeat_n(0u8, h));
            }
            let record_end = out.len() as u64;
            if self.wide {
                out[start..start + 8].copy_from_slice(&record_end.to_le_bytes());
            } else {
                out[start..start + 4].copy_from_slice(&(record_end as u32).to_le_bytes());
            }
            at = head.end;
        }
        Ok(())
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
    let (top_end, closed) = walk.scan(HEADER, bytes.len(), 0).ok()?;
    if walk.open == 0 || !closed {
        return None;
    }
    let h = walk.header_len();
    // The footer after the top list's null record is kept as it is.
    let footer = bytes.get(top_end + h..)?;
    let mut out = Vec::with_capacity(bytes.len() + walk.open * h);
    out.extend_from_slice(&bytes[..HEADER]);
    walk.copy(HEADER, top_end, &mut out).ok()?;
    out.extend(std::iter::repeat_n(0u8, h));
    out.extend_from_slice(footer);
    Some(out)
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
