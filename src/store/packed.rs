//! A take's record (its meta JSON: unit, decision record, axes, warnings) as the store keeps
//! it: zstd with a dictionary of the words records repeat, about 270 bytes where the JSON
//! text is 1,850 (a Bandai Namco BVH take).
//!
//! Why here and why a dictionary: records are small, so zstd alone finds little to reuse
//! inside one (1,850 → 740 bytes). What they repeat is each other: the same keys, codec ids,
//! skip reasons and provenance prose in every record. A raw-content dictionary
//! (`records/dictionary-1.json`, written once from the code's own words and the Plug-in
//! Gait marker names, no recording's values) gives zstd those words to point at.
//!
//! The format is the store's, beside the migration that packs old rows; the service packs a
//! record when it writes a row and unpacks it when it parses one (`service::take`), so that
//! a record that does not unpack is its take's problem, which `verify` reports, and not a
//! listing that fails.
//!
//! A packed record is one format byte, then a zstd frame with its checksum (XXH64's low four
//! bytes: a record changed on disk does not unpack). The byte names the dictionary, so
//! a new dictionary is a new byte and a new file beside this one; a dictionary once used is
//! frozen (the records packed with it name it). Rows written through migration 0017 held
//! the JSON text; the store packs them when it opens (`Store::pack_records`).

use std::sync::OnceLock;

use super::{Error, Result};
use crate::limits::MAX_RECORD_BYTES;

/// The format byte of a record packed with `DICTIONARY_1`.
const WITH_DICTIONARY_1: u8 = 1;

/// Frozen: records packed with it name it (`WITH_DICTIONARY_1`).
const DICTIONARY_1: &[u8] = include_bytes!("records/dictionary-1.json");

/// zstd's level for records. With the dictionary, 9 packs a Bandai record as small as 19
/// does (146 and 147 bytes of 1,783) at 20× the speed (11 µs): what the dictionary gives is
/// most of it, and a listing counts each take's record size by packing it.
const LEVEL: i32 = 9;

/// The dictionary prepared once for every packing and unpacking (loading it is a good share
/// of the work for a record this small).
fn encoder_dictionary() -> &'static zstd::dict::EncoderDictionary<'static> {
    static D: OnceLock<zstd::dict::EncoderDictionary<'static>> = OnceLock::new();
    D.get_or_init(|| zstd::dict::EncoderDictionary::copy(DICTIONARY_1, LEVEL))
}

fn decoder_dictionary() -> &'static zstd::dict::DecoderDictionary<'static> {
    static D: OnceLock<zstd::dict::DecoderDictionary<'static>> = OnceLock::new();
    D.get_or_init(|| zstd::dict::DecoderDictionary::copy(DICTIONARY_1))
}

/// Pack a record's text.
pub fn pack(text: &str) -> Result<Vec<u8>> {
    if text.len() > MAX_RECORD_BYTES {
        return Err(Error::Corrupt(format!(
            "a take's record of {} bytes is longer than the store keeps ({MAX_RECORD_BYTES})",
            text.len()
        )));
    }
    let mut c = zstd::bulk::Compressor::with_prepared_dictionary(encoder_dictionary())
        .map_err(|e| Error::Corrupt(format!("packing a take's record: {e}")))?;
    // Four bytes that make a flipped bit an error, not a different record.
    c.set_parameter(zstd::zstd_safe::CParameter::ChecksumFlag(true))
        .map_err(|e| Error::Corrupt(format!("packing a take's record: {e}")))?;
    let frame = c
        .compress(text.as_bytes())
        .map_err(|e| Error::Corrupt(format!("packing a take's record: {e}")))?;
    let mut out = Vec::with_capacity(frame.len() + 1);
    out.push(WITH_DICTIONARY_1);
    out.extend_from_slice(&frame);
    Ok(out)
}

/// A packed record's text; `Corrupt` if the bytes are not a record this store packs.
pub fn unpack(bytes: &[u8]) -> Result<String> {
    let corrupt = |what: String| Error::Corrupt(format!("a take's record: {what}"));
    let (&format, frame) = bytes.split_first().ok_or_else(|| corrupt("empty".into()))?;
    if format != WITH_DICTIONARY_1 {
        return Err(corrupt(format!(
            "format byte {format} is not one this store writes (1)"
        )));
    }
    let mut d = zstd::bulk::Decompressor::with_prepared_dictionary(decoder_dictionary())
        .map_err(|e| corrupt(e.to_string()))?;
    let text = d
        .decompress(frame, MAX_RECORD_BYTES)
        .map_err(|e| corrupt(format!("does not unpack: {e}")))?;
    String::from_utf8(text).map_err(|e| corrupt(format!("not UTF-8: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_come_back_as_written_and_smaller() {
        let text = r#"{"unit":{"metres_per_unit":0.01,"source":{"kind":"declared"}},"warnings":[],"decision":{"winner":"rot","reason":"rot is the smallest that meets max 1 mm","tried":[],"skipped":[{"codec":"raw","reason":"keeps joint positions only, and keep=animation (the default for skeleton takes)"},{"codec":"quant","reason":"keeps joint positions only, and keep=animation (the default for skeleton takes)"}]}}"#;
        let packed = pack(text).unwrap();
        assert_eq!(unpack(&packed).unwrap(), text);
        assert!(
            packed.len() * 3 < text.len(),
            "{} of {}",
            packed.len(),
            text.len()
        );
        // Any text, even one the dictionary knows nothing of.
        let other = "{\"ü\": \"".to_string() + &"xyz".repeat(10_000) + "\"}";
        assert_eq!(unpack(&pack(&other).unwrap()).unwrap(), other);
    }

    #[test]
    fn what_is_not_a_packed_record_is_refused() {
        let packed = pack("{}").unwrap();
        for bad in [
            Vec::new(),
            b"{}".to_vec(),
            [&[2u8][..], &packed[1..]].concat(),
            packed[..packed.len() - 1].to_vec(),
            [&packed[..], b"x"].concat(),
            // A byte changed inside the frame: its checksum says so.
            {
                let mut p = pack(&"{\"a\": 1}".repeat(50)).unwrap();
                let mid = p.len() / 2;
                p[mid] ^= 0x10;
                p
            },
        ] {
            assert!(matches!(unpack(&bad), Err(Error::Corrupt(_))), "{bad:?}");
        }
    }

    /// The dictionary is frozen: records already packed name it. If this fails, a change
    /// touched it; add a new dictionary and format byte instead.
    #[test]
    fn the_first_dictionary_is_frozen() {
        assert_eq!(
            blake3::hash(DICTIONARY_1).to_hex().to_string(),
            "8fe3146e080d0ee14cbb5f6850a5d8cde7791cbd1bb2c78fe858fa281997a3d7"
        );
    }
}
