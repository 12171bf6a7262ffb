//! The C3D parameter section as a typed tree: groups of named, typed, dimensioned
//! parameters, every one a vendor wrote, read once into [`Parameters`] and written back from
//! it ([`Parameters::to_section`]).
//!
//! The tree is what the archive keeps of a file beside its samples, so it must lose nothing
//! a later analysis reads: values are converted from the file's processor type (DEC floats,
//! big-endian integers) to native numbers once, here, and written back in Intel order, the
//! form every reader accepts. The stored copy of a take's parameters is that Intel section,
//! so the parser that reads uploads also reads what we stored (and is fuzzed for both).

use serde::Serialize;

use super::Processor;
use crate::motion::error::{Error, Location, Result};
use crate::motion::formats::{perr, Format};

/// Bytes of the parameter section's own header (two reserved bytes, the block count and
/// the processor type), before the first group or parameter.
pub const SECTION_HEAD: usize = 4;

/// A parameter's values, typed as the file declared them. Character data keeps its raw
/// bytes (C3D strings are fixed-width, space padded, and not always ASCII).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", content = "values", rename_all = "lowercase")]
pub enum Values {
    #[serde(serialize_with = "chars")]
    Char(Vec<u8>),
    Byte(Vec<u8>),
    Int(Vec<i16>),
    Float(Vec<f32>),
}

fn chars<S: serde::Serializer>(b: &[u8], s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(&String::from_utf8_lossy(b))
}

impl Values {
    /// The C3D type code: -1 char, 1 byte, 2 int, 4 float.
    pub fn kind(&self) -> i8 {
        match self {
            Values::Char(_) => -1,
            Values::Byte(_) => 1,
            Values::Int(_) => 2,
            Values::Float(_) => 4,
        }
    }

    fn element_bytes(kind: i8) -> Option<usize> {
        match kind {
            -1 | 1 => Some(1),
            2 => Some(2),
            4 => Some(4),
            _ => None,
        }
    }

    fn len(&self) -> usize {
        match self {
            Values::Char(v) | Values::Byte(v) => v.len(),
            Values::Int(v) => v.len(),
            Values::Float(v) => v.len(),
        }
    }
}

/// One parameter: a name unique in its group, its dimensions (first varies fastest, as in
/// the file) and values.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Parameter {
    pub name: String,
    pub description: String,
    /// A negative name length in the file: "do not edit".
    pub locked: bool,
    pub dims: Vec<u8>,
    #[serde(flatten)]
    pub values: Values,
}

impl Parameter {
    pub fn new(name: &str, dims: Vec<u8>, values: Values) -> Parameter {
        Parameter {
            name: name.to_string(),
            description: String::new(),
            locked: false,
            dims,
            values,
        }
    }

    /// Every value as a number (characters have none).
    pub fn numbers(&self) -> Vec<f64> {
        match &self.values {
            Values::Char(_) => Vec::new(),
            Values::Byte(v) => v.iter().map(|&b| f64::from(b)).collect(),
            Values::Int(v) => v.iter().map(|&i| f64::from(i)).collect(),
            Values::Float(v) => v.iter().map(|&f| f64::from(f)).collect(),
        }
    }

    /// The first value as a number.
    pub fn number(&self) -> Option<f64> {
        self.numbers().first().copied()
    }

    /// 16-bit integers read unsigned (counts in C3D overflow i16 long before u16).
    pub fn u16s(&self) -> Option<Vec<u16>> {
        match &self.values {
            Values::Int(v) => Some(v.iter().map(|&i| i as u16).collect()),
            _ => None,
        }
    }

    /// A character parameter as strings: dims `[len, count…]` (or `[len]` for one),
    /// trimmed of padding.
    pub fn strings(&self) -> Option<Vec<String>> {
        let Values::Char(d) = &self.values else {
            return None;
        };
        let width = self
            .dims
            .first()
            .map_or(d.len(), |&w| usize::from(w))
            .max(1);
        Some(
            d.chunks(width)
                .map(|c| {
                    String::from_utf8_lossy(c)
                        .trim_matches(|ch: char| ch == '\0' || ch.is_whitespace())
                        .to_string()
                })
                .collect(),
        )
    }

    /// Bytes of this entry in a section: name, offset, type, dims, data, description.
    fn entry_len(&self) -> usize {
        2 + self.name.len() + 2 + 2 + self.dims.len() + self.data_len() + 1 + self.description.len()
    }

    fn data_len(&self) -> usize {
        self.values.len() * Values::element_bytes(self.values.kind()).unwrap_or(1)
    }
}

/// One group: its number (1..=127, what its parameters refer to), name and parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Group {
    pub id: u8,
    pub name: String,
    pub description: String,
    pub locked: bool,
    pub params: Vec<Parameter>,
}

/// A file's whole parameter section.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Parameters {
    pub groups: Vec<Group>,
}

fn err(offset: usize, reason: impl Into<String>) -> Error {
    perr(Format::C3d, Location::Offset(offset), reason)
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).trim().to_string()
}

impl Parameters {
    /// The group named `group` (case-insensitive, as C3D names are).
    pub fn group(&self, group: &str) -> Option<&Group> {
        self.groups
            .iter()
            .find(|g| g.name.eq_ignore_ascii_case(group))
    }

    pub fn get(&self, group: &str, name: &str) -> Option<&Parameter> {
        self.group(group)?
            .params
            .iter()
            .find(|p| p.name.eq_ignore_ascii_case(name))
    }

    pub fn number(&self, group: &str, name: &str) -> Option<f64> {
        self.get(group, name)?.number()
    }

    pub fn u16s(&self, group: &str, name: &str) -> Option<Vec<u16>> {
        self.get(group, name)?.u16s()
    }

    pub fn strings(&self, group: &str, name: &str) -> Option<Vec<String>> {
        self.get(group, name)?.strings()
    }

    /// Strings of `NAME`, `NAME2`, `NAME3`… joined: how writers continue a list past 255
    /// entries (POINT:LABELS2, ANALOG:UNITS2).
    pub fn strings_continued(&self, group: &str, name: &str) -> Vec<String> {
        let mut out = self.strings(group, name).unwrap_or_default();
        for k in 2.. {
            match self.strings(group, &format!("{name}{k}")) {
                Some(more) => out.extend(more),
                None => break,
            }
        }
        out
    }

    /// Numbers of `NAME`, `NAME2`, … joined, as [`Parameters::strings_continued`].
    pub fn numbers_continued(&self, group: &str, name: &str) -> Vec<f64> {
        let mut out = self
            .get(group, name)
            .map(Parameter::numbers)
            .unwrap_or_default();
        for k in 2.. {
            match self.get(group, &format!("{name}{k}")) {
                Some(more) => out.extend(more.numbers()),
                None => break,
            }
        }
        out
    }

    /// Set (or add) `group:name`, creating the group if needed; what a writer does to
    /// make the counts it writes agree with the data it writes.
    pub fn set(&mut self, group: &str, p: Parameter) {
        let gi = match self
            .groups
            .iter()
            .position(|g| g.name.eq_ignore_ascii_case(group))
        {
            Some(i) => i,
            None => {
                let id = (1..=127u8)
                    .find(|id| self.groups.iter().all(|g| g.id != *id))
                    .unwrap_or(127);
                self.groups.push(Group {
                    id,
                    name: group.to_string(),
                    description: String::new(),
                    locked: false,
                    params: Vec::new(),
                });
                self.groups.len() - 1
            }
        };
        let g = &mut self.groups[gi];
        match g
            .params
            .iter_mut()
            .find(|q| q.name.eq_ignore_ascii_case(&p.name))
        {
            Some(q) => {
                q.dims = p.dims;
                q.values = p.values;
            }
            None => g.params.push(p),
        }
    }

    /// Remove `group:name` if present.
    pub fn remove(&mut self, group: &str, name: &str) {
        if let Some(g) = self
            .groups
            .iter_mut()
            .find(|g| g.name.eq_ignore_ascii_case(group))
        {
            g.params.retain(|p| !p.name.eq_ignore_ascii_case(name));
        }
    }

    /// Parse the section that starts at `start` (its 4-byte head) in `bytes`, with values
    /// in `proc`'s encoding. `end` bounds the list: some writers leave a bogus "next"
    /// offset on the last entry, which is taken as the end rather than followed into the
    /// data. Parameters of a group that is never declared are kept in a group named
    /// `#id`, so that nothing is dropped.
    pub(super) fn parse(
        bytes: &[u8],
        start: usize,
        end: usize,
        proc: Processor,
    ) -> Result<Parameters> {
        let mut groups: Vec<Group> = Vec::new();
        let mut orphans: Vec<(u8, Parameter)> = Vec::new();
        let mut pos = start + SECTION_HEAD;
        loop {
            if pos + 2 > bytes.len() {
                return Err(err(pos, "parameter section runs past the end of the file"));
            }
            let raw_len = bytes[pos] as i8;
            let name_len = raw_len.unsigned_abs() as usize;
            let id = bytes[pos + 1] as i8;
            if name_len == 0 || id == 0 {
                break;
            }
            let name_end = pos + 2 + name_len;
            if name_end + 2 > bytes.len() {
                return Err(err(pos, "parameter name runs past the end of the file"));
            }
            let name = text(&bytes[pos + 2..name_end]).to_ascii_uppercase();
            let next = proc.i16(&bytes[name_end..]);
            // Where this entry ends by its own offset (or the section's end, for the last).
            let entry_end = if next > 0 {
                (name_end + next as usize).min(bytes.len())
            } else {
                end.min(bytes.len())
            };
            let body = name_end + 2;
            // A description: one length byte then text, cut at the entry's end.
            let description = |at: usize| -> String {
                let n = bytes.get(at).map_or(0, |&n| usize::from(n));
                let from = (at + 1).min(bytes.len());
                let to = (at + 1 + n).min(entry_end).min(bytes.len()).max(from);
                text(&bytes[from..to])
            };
            if id < 0 {
                let gid = id.unsigned_abs();
                if groups.iter().any(|g| g.id == gid) {
                    return Err(err(pos, format!("group {gid} ({name}) is declared twice")));
                }
                groups.push(Group {
                    id: gid,
                    name,
                    description: description(body),
                    locked: raw_len < 0,
                    params: Vec::new(),
                });
            } else {
                if body + 2 > bytes.len() {
                    return Err(err(pos, format!("parameter {name} is cut off")));
                }
                let kind = bytes[body] as i8;
                let ndims = bytes[body + 1] as usize;
                let dims_end = body + 2 + ndims;
                if dims_end > bytes.len() {
                    return Err(err(
                        body,
                        format!("parameter {name} dimensions are cut off"),
                    ));
                }
                let dims = bytes[body + 2..dims_end].to_vec();
                let Some(elem) = Values::element_bytes(kind) else {
                    return Err(err(
                        body,
                        format!("parameter {name} has unknown type {kind}"),
                    ));
                };
                let len = dims
                    .iter()
                    .try_fold(elem, |acc, &d| acc.checked_mul(usize::from(d)))
                    .filter(|&len| dims_end + len <= bytes.len());
                let Some(len) = len else {
                    return Err(err(
                        dims_end,
                        format!("parameter {name} data runs past the end"),
                    ));
                };
                let d = &bytes[dims_end..dims_end + len];
                let values = match kind {
                    -1 => Values::Char(d.to_vec()),
                    1 => Values::Byte(d.to_vec()),
                    2 => Values::Int(d.chunks_exact(2).map(|c| proc.i16(c)).collect()),
                    _ => Values::Float(d.chunks_exact(4).map(|c| proc.f32(c)).collect()),
                };
                let p = Parameter {
                    name,
                    description: description(dims_end + len),
                    locked: raw_len < 0,
                    dims,
                    values,
                };
                orphans.push((id as u8, p));
            }
            if next <= 0 {
                break;
            }
            let np = name_end + next as usize;
            if np >= end {
                break;
            }
            pos = np;
        }
        for (id, p) in orphans {
            let g = match groups.iter().position(|g| g.id == id) {
                Some(i) => i,
                None => {
                    groups.push(Group {
                        id,
                        name: format!("#{id}"),
                        description: String::new(),
                        locked: false,
                        params: Vec::new(),
                    });
                    groups.len() - 1
                }
            };
            // A name repeated in a group: the first stands, as readers look it up.
            if groups[g].params.iter().all(|q| q.name != p.name) {
                groups[g].params.push(p);
            }
        }
        Ok(Parameters { groups })
    }

    /// The section in Intel order: its 4-byte head (`first_data_block` is the head's
    /// second byte's partner, kept as C3D writers do: 1 then the key 0x50), then every
    /// group followed by its parameters, padded to whole 512-byte blocks. `Invalid` if an
    /// entry or name cannot be written in C3D's fields (names over 127 bytes, an entry
    /// longer than an i16 offset reaches, more than 127 groups, more than 255 blocks).
    pub fn to_section(&self) -> Result<Vec<u8>> {
        let invalid = |what: String| Error::Invalid(format!("C3D parameters: {what}"));
        if self.groups.len() > 127 {
            return Err(invalid(format!(
                "{} groups (at most 127)",
                self.groups.len()
            )));
        }
        let mut out = vec![1u8, 0x50, 0, 84];
        let mut entries: Vec<(usize, usize)> = Vec::new(); // (start, offset field)
        let name_ok = |n: &str| !n.is_empty() && n.len() <= 127;
        for g in &self.groups {
            if !name_ok(&g.name) || g.id == 0 || g.id > 127 {
                return Err(invalid(format!("group {:?} (id {})", g.name, g.id)));
            }
            let start = out.len();
            let len = g.name.len() as i8;
            out.push(if g.locked { -len } else { len } as u8);
            out.push((-(g.id as i8)) as u8);
            out.extend_from_slice(g.name.as_bytes());
            entries.push((start, out.len()));
            out.extend_from_slice(&[0, 0]);
            let desc = &g.description.as_bytes()[..g.description.len().min(255)];
            out.push(desc.len() as u8);
            out.extend_from_slice(desc);
            for p in &g.params {
                if !name_ok(&p.name) {
                    return Err(invalid(format!("parameter {:?} of {}", p.name, g.name)));
                }
                if p.entry_len() > i16::MAX as usize {
                    return Err(invalid(format!(
                        "{}:{} is {} bytes, more than a C3D offset reaches",
                        g.name,
                        p.name,
                        p.entry_len()
                    )));
                }
                let expected: usize = p.dims.iter().map(|&d| usize::from(d)).product();
                if expected != p.values.len() || p.dims.len() > 7 {
                    return Err(invalid(format!(
                        "{}:{} has {} values for dimensions {:?}",
                        g.name,
                        p.name,
                        p.values.len(),
                        p.dims
                    )));
                }
                let start = out.len();
                let len = p.name.len() as i8;
                out.push(if p.locked { -len } else { len } as u8);
                out.push(g.id);
                out.extend_from_slice(p.name.as_bytes());
                entries.push((start, out.len()));
                out.extend_from_slice(&[0, 0]);
                out.push(p.values.kind() as u8);
                out.push(p.dims.len() as u8);
                out.extend_from_slice(&p.dims);
                match &p.values {
                    Values::Char(v) | Values::Byte(v) => out.extend_from_slice(v),
                    Values::Int(v) => v.iter().for_each(|x| out.extend(x.to_le_bytes())),
                    Values::Float(v) => v.iter().for_each(|x| out.extend(x.to_le_bytes())),
                }
                let desc = &p.description.as_bytes()[..p.description.len().min(255)];
                out.push(desc.len() as u8);
                out.extend_from_slice(desc);
            }
        }
        // Each entry's offset points at the next entry's start; the last's is 0 (end).
        for i in 0..entries.len() {
            let (_, field) = entries[i];
            let next = match entries.get(i + 1) {
                Some(&(start, _)) => (start - field) as i16,
                None => 0,
            };
            out[field..field + 2].copy_from_slice(&next.to_le_bytes());
        }
        // A terminating empty entry for readers that walk past a 0 offset.
        out.extend_from_slice(&[0, 0]);
        let blocks = out.len().div_ceil(super::BLOCK);
        if blocks > 255 {
            return Err(invalid(format!("{blocks} blocks (at most 255)")));
        }
        out[2] = blocks as u8;
        out.resize(blocks * super::BLOCK, 0);
        Ok(out)
    }

    /// Read a section written by [`Parameters::to_section`] (what the archive stores).
    pub fn from_section(bytes: &[u8]) -> Result<Parameters> {
        if bytes.len() < SECTION_HEAD || bytes[3] != 84 {
            return Err(err(0, "not an Intel C3D parameter section"));
        }
        Parameters::parse(bytes, 0, bytes.len(), Processor::Intel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn sample() -> Parameters {
        let mut p = Parameters::default();
        p.set(
            "POINT",
            Parameter::new("LABELS", vec![4, 2], Values::Char(b"HEADLTOE".to_vec())),
        );
        p.set(
            "POINT",
            Parameter::new("SCALE", vec![], Values::Float(vec![-0.1])),
        );
        p.set(
            "FORCE_PLATFORM",
            Parameter::new("CHANNEL", vec![6, 1], Values::Int(vec![1, 2, 3, 4, 5, 6])),
        );
        p.set(
            "VENDOR",
            Parameter::new("FLAGS", vec![3], Values::Byte(vec![0, 255, 7])),
        );
        p.groups[0].description = "3-D point parameters".into();
        p.groups[1].params[0].locked = true;
        p
    }

    #[test]
    fn a_tree_round_trips_through_its_section() {
        let p = sample();
        let bytes = p.to_section().unwrap();
        assert_eq!(bytes.len() % 512, 0);
        let back = Parameters::from_section(&bytes).unwrap();
        assert_eq!(back, p);
        assert_eq!(back.strings("point", "labels").unwrap(), ["HEAD", "LTOE"]);
        assert_eq!(back.number("POINT", "SCALE"), Some(-0.1f32 as f64));
    }

    #[test]
    fn set_replaces_and_adds() {
        let mut p = sample();
        p.set(
            "POINT",
            Parameter::new("SCALE", vec![], Values::Float(vec![-1.0])),
        );
        p.set(
            "TRIAL",
            Parameter::new("RATE", vec![], Values::Int(vec![100])),
        );
        assert_eq!(p.number("POINT", "SCALE"), Some(-1.0));
        assert_eq!(p.number("TRIAL", "RATE"), Some(100.0));
        assert_eq!(p.groups.len(), 4);
    }

    #[test]
    fn unwritable_trees_are_refused() {
        let mut p = sample();
        p.set("X", Parameter::new("BAD", vec![3], Values::Int(vec![1, 2])));
        assert!(p.to_section().is_err());
    }

    #[test]
    fn damaged_sections_never_panic() {
        let good = sample().to_section().unwrap();
        for cut in 0..good.len().min(200) {
            let _ = Parameters::from_section(&good[..cut]);
        }
        for i in 0..200 {
            let mut b = good.clone();
            b[i] ^= 0x5A;
            let _ = Parameters::from_section(&b);
        }
    }
}
