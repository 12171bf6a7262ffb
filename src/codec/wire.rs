//! Little helpers to write and read codec parameter blocks.

use super::error::{malformed, Error, Result};

pub struct Writer(pub Vec<u8>);

impl Writer {
    pub fn new() -> Self {
        Writer(Vec::new())
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.0.extend_from_slice(b);
        self
    }
}

/// Reads little-endian fields, failing with `Malformed` ("<what> is truncated") at the end.
pub struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
    what: &'static str,
}

impl<'a> Reader<'a> {
    /// A reader of codec parameters.
    pub fn new(b: &'a [u8]) -> Self {
        Reader::named(b, "codec parameters")
    }
    pub fn named(b: &'a [u8], what: &'static str) -> Self {
        Reader { b, pos: 0, what }
    }
    pub fn position(&self) -> usize {
        self.pos
    }
    /// The magic and the format version that open one of our stored objects (a bitstream,
    /// a basis, a skeleton): not ours is malformed, a version this build does not read is
    /// unsupported.
    pub fn opening(&mut self, magic: &[u8; 4], version: u16, kind: &str) -> Result<()> {
        if self.take(4)? != magic {
            return Err(malformed(format!("not a mocapstore {kind} (bad magic)")));
        }
        let v = self.u16()?;
        if v != version {
            return Err(Error::Unsupported(format!("{kind} version {v}")));
        }
        Ok(())
    }
    pub fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| malformed(format!("{} is truncated", self.what)))?;
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    pub fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }
    pub fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2)?.try_into().expect("2")))
    }
    pub fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4")))
    }
    pub fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(self.take(4)?.try_into().expect("4")))
    }
    pub fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().expect("8")))
    }
    pub fn finish(&self) -> Result<()> {
        if self.pos == self.b.len() {
            Ok(())
        } else {
            Err(malformed(format!("trailing bytes in {}", self.what)))
        }
    }
}
