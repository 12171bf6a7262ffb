//! The general-purpose alternative to the range coder: zigzag varints, then zstd. Kept for
//! the measured comparison in `mocapstore bench entropy`.

use super::{get_varint, put_varint, unzigzag, zigzag};

pub fn encode(values: &[i32], level: i32) -> Vec<u8> {
    let mut raw = Vec::with_capacity(values.len());
    for &v in values {
        put_varint(&mut raw, u64::from(zigzag(v)));
    }
    zstd::bulk::compress(&raw, level).expect("in-memory zstd compression does not fail")
}

/// Decode `count` values; `None` if the bytes do not hold them.
pub fn decode(bytes: &[u8], count: usize) -> Option<Vec<i32>> {
    let raw = zstd::bulk::decompress(bytes, count.checked_mul(5)?).ok()?;
    let mut pos = 0;
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let u = u32::try_from(get_varint(&raw, &mut pos)?).ok()?;
        out.push(unzigzag(u));
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trips() {
        let v: Vec<i32> = (-1000..1000).map(|i| i * 37 % 101).collect();
        let b = super::encode(&v, 3);
        assert_eq!(super::decode(&b, v.len()).unwrap(), v);
        assert!(super::decode(&b[..b.len() / 2], v.len()).is_none());
    }
}
