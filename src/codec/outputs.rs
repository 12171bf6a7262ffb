//! Model outputs as stored ([`Outputs`]: a C3D's joint angles, forces, moments, powers):
//! exactly, each output's three components as channels of the lossless analog coder (its
//! linear prediction suits smooth curves, and values that lie on the file's integer grid
//! code as integers), behind a small description of the outputs.
//!
//! Layout: `version u8` (1), `description length u32` (little-endian), the description (JSON:
//! each output's name, kind, unit and point slot), then one analog container
//! ([`Container::to_bytes`]) of `3 × outputs` float channels at one row a frame.

use super::analog;
use super::container::{Container, DecodeLimits};
use super::error::{malformed, Error, Result};
use crate::motion::analog::{Analog, Channel, Samples};
use crate::motion::outputs::{Output, Outputs};

const VERSION: u8 = 1;

/// The components' suffixes, in order.
const AXES: [&str; 3] = ["x", "y", "z"];

/// `o` (of a take at `fps`) as stored bytes.
pub fn encode(o: &Outputs, fps: f64) -> Result<Vec<u8>> {
    let frames = o.frames();
    if frames == 0 {
        return Err(Error::Invalid("model outputs of no frames".into()));
    }
    let channels = o
        .outputs
        .iter()
        .flat_map(|out| {
            AXES.iter().map(|a| Channel {
                label: format!("{}.{a}", out.name),
                description: String::new(),
                unit: out.unit.clone(),
                scale: 1.0,
                offset: 0,
            })
        })
        .collect();
    let a = Analog::new(1, 1.0, channels, Samples::Float(o.values.clone()))
        .map_err(|e| Error::Invalid(e.to_string()))?;
    let c = analog::encode(&a, fps, &[frames], &[])?.container;
    let description = serde_json::to_vec(&o.outputs).map_err(|e| Error::Invalid(e.to_string()))?;
    let mut out = vec![VERSION];
    out.extend_from_slice(&(description.len() as u32).to_le_bytes());
    out.extend_from_slice(&description);
    out.extend_from_slice(&c.to_bytes());
    Ok(out)
}

/// Stored bytes back as the outputs they were.
pub fn decode(bytes: &[u8], limits: &DecodeLimits) -> Result<Outputs> {
    let bad = |what: &str| malformed(format!("model outputs: {what}"));
    let (&version, rest) = bytes.split_first().ok_or_else(|| bad("empty"))?;
    if version != VERSION {
        return Err(bad(&format!("version {version}")));
    }
    let (len, rest) = rest
        .split_first_chunk::<4>()
        .ok_or_else(|| bad("cut short"))?;
    let len = u32::from_le_bytes(*len) as usize;
    if len > rest.len() {
        return Err(bad("description past the end"));
    }
    let (description, rest) = rest.split_at(len);
    let outputs: Vec<Output> =
        serde_json::from_slice(description).map_err(|e| bad(&e.to_string()))?;
    let c = Container::parse(rest, limits)?;
    let a = analog::decode_all(&c)?;
    if a.channel_count() != outputs.len() * 3 || a.per_frame != 1 {
        return Err(bad(&format!(
            "{} channels for {} outputs",
            a.channel_count(),
            outputs.len()
        )));
    }
    let Samples::Float(values) = a.samples else {
        return Err(bad("integer samples"));
    };
    Outputs::new(outputs, values).map_err(|e| bad(&e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::outputs::Kind;

    #[test]
    fn outputs_come_back_bit_for_bit_gaps_included() {
        let outputs = vec![
            Output {
                name: "LHipAngles".into(),
                kind: Kind::Angle,
                unit: "deg".into(),
                slot: 3,
            },
            Output {
                name: "LHipMoment".into(),
                kind: Kind::Moment,
                unit: "Nmm".into(),
                slot: 0,
            },
        ];
        let mut values: Vec<f32> = (0..300 * 6)
            .map(|i| (i as f32 * 0.01).sin() * 28.5 + 0.1 * (i % 6) as f32)
            .collect();
        values[12..15].fill(f32::NAN);
        let o = Outputs::new(outputs, values).unwrap();
        let bytes = encode(&o, 100.0).unwrap();
        assert!(bytes.len() < o.values.len() * 4);
        let back = decode(&bytes, &DecodeLimits::default()).unwrap();
        assert_eq!(back.outputs, o.outputs);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.values), bits(&o.values));
        for cut in [0, 1, 5, 20, bytes.len() - 1] {
            assert!(decode(&bytes[..cut], &DecodeLimits::default()).is_err());
        }
    }
}
