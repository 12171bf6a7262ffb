//! C3D out: points, analog channels, events and the whole parameter tree of a take, so
//! that an archived file comes back as a file every reader (py-c3d, ezc3d, BTK, Vicon,
//! Visual3D) opens with the same labels, rates, scales, offsets, units, events and force
//! plates.
//!
//! Written as Intel floats (`POINT:SCALE` negative): the points are what the archive
//! decoded, and an integer file would round them once more to its scale. Analog values
//! are written as the floats of their stored values (an ADC integer is exact in an f32),
//! with the file's own `ANALOG:SCALE`, `OFFSET`, `GEN_SCALE` and `FORMAT`, so a reader's
//! `(value − offset) × scale × gen_scale` gives what it gave for the upload. The counts
//! and layout parameters (`POINT:USED`, `FRAMES`, `DATA_START`, `RATE`, `LABELS…`,
//! `ANALOG:USED`, `RATE`, `LABELS…`, `TRIAL:ACTUAL_*_FIELD`) are set from the data
//! written; every other parameter is the upload's, untouched.

use super::params::{Parameter, Parameters, Values};
use super::BLOCK;
use crate::motion::analog::{Analog, Samples};
use crate::motion::error::{Error, Result};
use crate::motion::model::Motion;
use crate::motion::outputs::{Kind, Outputs};

/// What to write: the points (a take or a range of it), its analog channels over the
/// same frames, the parameters it was uploaded with, and the number of its first frame
/// (1 for a whole take, as C3D counts).
pub struct Out<'a> {
    pub motion: &'a Motion,
    pub analog: Option<&'a Analog>,
    /// Model outputs over the same frames, written back among the points where the file
    /// had them.
    pub outputs: Option<&'a Outputs>,
    pub parameters: Option<&'a Parameters>,
    pub first_frame: usize,
}

/// Bytes of the data section: 4 floats per point and one per analog value, per frame.
pub fn data_len(frames: usize, points: usize, analog_words: usize) -> u64 {
    frames as u64 * (points as u64 * 4 + analog_words as u64) * 4
}

/// Strings as a C3D character array `[width, count]`, space padded.
fn strings(v: &[String]) -> Parameter {
    let width = v.iter().map(String::len).max().unwrap_or(0).clamp(1, 255);
    let mut d = Vec::with_capacity(width * v.len());
    for s in v {
        let b = &s.as_bytes()[..s.len().min(width)];
        d.extend_from_slice(b);
        d.resize(d.len() + width - b.len(), b' ');
    }
    Parameter::new("", vec![width as u8, v.len() as u8], Values::Char(d))
}

/// Set `NAME`, `NAME2`, … of `group` from `items` (255 per parameter), removing stale
/// continuations left from the upload.
fn set_continued(p: &mut Parameters, group: &str, name: &str, items: Vec<Parameter>) {
    for k in 2..=64 {
        p.remove(group, &format!("{name}{k}"));
    }
    for (k, mut item) in items.into_iter().enumerate() {
        item.name = if k == 0 {
            name.to_string()
        } else {
            format!("{name}{}", k + 1)
        };
        p.set(group, item);
    }
}

fn string_lists(v: &[String]) -> Vec<Parameter> {
    if v.is_empty() {
        return vec![strings(&[])];
    }
    v.chunks(255).map(strings).collect()
}

fn float_lists(v: &[f32]) -> Vec<Parameter> {
    if v.is_empty() {
        return vec![Parameter::new("", vec![0], Values::Float(vec![]))];
    }
    v.chunks(255)
        .map(|c| Parameter::new("", vec![c.len() as u8], Values::Float(c.to_vec())))
        .collect()
}

fn int_lists(v: &[i16]) -> Vec<Parameter> {
    if v.is_empty() {
        return vec![Parameter::new("", vec![0], Values::Int(vec![]))];
    }
    v.chunks(255)
        .map(|c| Parameter::new("", vec![c.len() as u8], Values::Int(c.to_vec())))
        .collect()
}

fn int(name: &str, v: i16) -> Parameter {
    Parameter::new(name, vec![], Values::Int(vec![v]))
}

fn float(name: &str, v: f32) -> Parameter {
    Parameter::new(name, vec![], Values::Float(vec![v]))
}

/// The unit the points are written in and the factor from the take's unit to it.
fn point_unit(metres_per_unit: f64) -> (&'static str, f32) {
    for (name, m) in [("mm", 0.001), ("cm", 0.01), ("m", 1.0)] {
        if (metres_per_unit - m).abs() <= m * 1e-9 {
            return (name, 1.0);
        }
    }
    ("mm", (metres_per_unit / 0.001) as f32)
}

/// The file's bytes.
pub fn write(out: &Out<'_>) -> Result<Vec<u8>> {
    let m = out.motion;
    let frames = m.frame_count();
    let invalid = |what: String| Error::Invalid(format!("C3D out: {what}"));
    if let Some(o) = out.outputs.filter(|o| o.frames() != frames) {
        return Err(invalid(format!(
            "{} model output frames for {frames} point frames",
            o.frames()
        )));
    }
    // Every point slot written: the markers, and the model outputs where the file had them.
    let order = out.outputs.map_or_else(
        || (0..m.point_count()).map(Err).collect(),
        |o| o.interleave(m.point_count()),
    );
    let points = order.len();
    let point_names: Vec<String> = order
        .iter()
        .map(|s| match (s, out.outputs) {
            (Ok(o), Some(outputs)) => outputs.outputs[*o].name.clone(),
            (Err(k), _) | (Ok(k), None) => m.point_names[*k].clone(),
        })
        .collect();
    if points > 65_535 {
        return Err(invalid(format!("{points} points (at most 65535)")));
    }
    let (analog_words, per_frame) = match out.analog {
        Some(a) => {
            if a.frames() != frames {
                return Err(invalid(format!(
                    "{} analog frames for {frames} point frames",
                    a.frames()
                )));
            }
            (a.channel_count() * a.per_frame, a.per_frame)
        }
        None => (0, 1),
    };
    if analog_words > 65_535 || per_frame > 65_535 {
        return Err(invalid(format!("{analog_words} analog values per frame")));
    }
    let mut p = out.parameters.cloned().unwrap_or_default();
    let (unit, to_unit) = point_unit(m.unit.metres_per_unit);
    let old_scale = p
        .number("POINT", "SCALE")
        .map_or(1.0, |s| s.abs() as f32)
        .max(f32::MIN_POSITIVE);
    let scale = -old_scale;
    let rate = m.fps as f32;
    // Readers count last − first + 1 frames: a take of none ends the frame before it starts.
    let first_frame = if frames == 0 {
        out.first_frame.max(1)
    } else {
        out.first_frame
    };
    let last = (first_frame + frames).saturating_sub(1);
    p.set("POINT", int("USED", points as u16 as i16));
    p.set("POINT", float("SCALE", scale));
    p.set("POINT", float("RATE", rate));
    p.set("POINT", int("FRAMES", frames.min(65_535) as u16 as i16));
    p.set(
        "POINT",
        Parameter {
            name: "UNITS".into(),
            ..strings(&[unit.to_string()])
        },
    );
    // The upload's labels stand where they still name the points written (blank and
    // repeated labels, and bytes that are not UTF-8, come back as they were).
    if super::labels(&p, "POINT", points, "P") != point_names {
        set_continued(&mut p, "POINT", "LABELS", string_lists(&point_names));
        p.remove("POINT", "DESCRIPTIONS");
    }
    if let Some(o) = out.outputs {
        // Each kind's list and unit name the outputs written (a list the upload kept
        // stands when it still does).
        for kind in Kind::ALL {
            let of: Vec<&crate::motion::outputs::Output> =
                o.outputs.iter().filter(|x| x.kind == kind).collect();
            let Some(first) = of.first() else { continue };
            let names: Vec<String> = of.iter().map(|x| x.name.clone()).collect();
            let listed = p.strings_continued("POINT", kind.list());
            if !names.iter().all(|n| listed.contains(n)) {
                set_continued(&mut p, "POINT", kind.list(), string_lists(&names));
            }
            if p.get("POINT", kind.unit_parameter()).is_none() {
                p.set(
                    "POINT",
                    Parameter {
                        name: kind.unit_parameter().into(),
                        ..strings(std::slice::from_ref(&first.unit))
                    },
                );
            }
        }
    }
    if last > 65_535 {
        let pair = |v: usize| Values::Int(vec![v as u16 as i16, (v >> 16) as u16 as i16]);
        p.set(
            "TRIAL",
            Parameter::new("ACTUAL_START_FIELD", vec![2], pair(first_frame)),
        );
        p.set(
            "TRIAL",
            Parameter::new("ACTUAL_END_FIELD", vec![2], pair(last)),
        );
    } else if p.group("TRIAL").is_some() {
        p.remove("TRIAL", "ACTUAL_START_FIELD");
        p.remove("TRIAL", "ACTUAL_END_FIELD");
    }
    match out.analog {
        Some(a) => {
            let labels: Vec<String> = a.channels.iter().map(|c| c.label.clone()).collect();
            let desc: Vec<String> = a.channels.iter().map(|c| c.description.clone()).collect();
            let units: Vec<String> = a.channels.iter().map(|c| c.unit.clone()).collect();
            let scales: Vec<f32> = a.channels.iter().map(|c| c.scale).collect();
            let offsets: Vec<i16> = a.channels.iter().map(|c| c.offset as u16 as i16).collect();
            // The upload's channel parameters stand where they still describe the channels
            // written, byte for byte; otherwise they are written from the channels.
            let n = a.channel_count();
            let kept = p.number("ANALOG", "USED").map(|u| u as u16 as usize) == Some(n)
                && super::labels(&p, "ANALOG", n, "A") == labels;
            p.set("ANALOG", int("USED", n as u16 as i16));
            p.set("ANALOG", float("RATE", (m.fps * a.per_frame as f64) as f32));
            p.set("ANALOG", float("GEN_SCALE", a.gen_scale));
            if !kept {
                set_continued(&mut p, "ANALOG", "LABELS", string_lists(&labels));
                set_continued(&mut p, "ANALOG", "DESCRIPTIONS", string_lists(&desc));
                set_continued(&mut p, "ANALOG", "UNITS", string_lists(&units));
                set_continued(&mut p, "ANALOG", "SCALE", float_lists(&scales));
                set_continued(&mut p, "ANALOG", "OFFSET", int_lists(&offsets));
            }
            let unsigned = matches!(a.samples, Samples::Int { unsigned: true, .. });
            if unsigned {
                p.set(
                    "ANALOG",
                    Parameter {
                        name: "FORMAT".into(),
                        ..strings(&["UNSIGNED".to_string()])
                    },
                );
            }
        }
        None => {
            p.set("ANALOG", int("USED", 0));
            p.set("ANALOG", float("RATE", rate));
        }
    }
    // DATA_START depends on the section's size, which does not depend on its value.
    p.set("POINT", int("DATA_START", 0));
    let param_blocks = p.to_section()?.len() / BLOCK;
    let data_start = 2 + param_blocks;
    if data_start > 65_535 {
        return Err(invalid("parameter section too large".into()));
    }
    p.set("POINT", int("DATA_START", data_start as u16 as i16));
    let section = p.to_section()?;

    let data = data_len(frames, points, analog_words);
    let total = BLOCK as u64 + section.len() as u64 + data;
    let mut b =
        Vec::with_capacity(usize::try_from(total).map_err(|_| invalid("too large".into()))?);
    b.resize(BLOCK, 0);
    b[0] = 2;
    b[1] = 0x50;
    let word = |b: &mut Vec<u8>, w: usize, v: u16| {
        b[(w - 1) * 2..(w - 1) * 2 + 2].copy_from_slice(&v.to_le_bytes())
    };
    word(&mut b, 2, points as u16);
    word(&mut b, 3, analog_words as u16);
    // Past 65535 the header's words are clamped (TRIAL holds the frames); no frames at
    // all stay 1..0 there, whatever the first frame, so that they count none.
    let (head_first, head_last) = if frames == 0 {
        (
            first_frame.clamp(1, 65_535),
            first_frame.clamp(1, 65_535) - 1,
        )
    } else {
        (first_frame.min(65_535), last.min(65_535))
    };
    word(&mut b, 4, head_first as u16);
    word(&mut b, 5, head_last as u16);
    word(&mut b, 6, 10);
    b[12..16].copy_from_slice(&scale.to_le_bytes());
    word(&mut b, 9, data_start as u16);
    word(&mut b, 10, per_frame as u16);
    b[20..24].copy_from_slice(&rate.to_le_bytes());
    b.extend_from_slice(&section);
    for f in 0..frames {
        let row = m.frame(f);
        for slot in &order {
            // Markers in the point unit; outputs as the file had them, in their own.
            let (xyz, factor) = match (slot, out.outputs) {
                (Ok(o), Some(outputs)) => (outputs.get(f, *o), 1.0),
                (Err(k), _) | (Ok(k), None) => {
                    ([row[k * 3], row[k * 3 + 1], row[k * 3 + 2]], to_unit)
                }
            };
            if xyz[0].is_finite() {
                for v in xyz {
                    b.extend_from_slice(&(v * factor).to_le_bytes());
                }
                b.extend_from_slice(&0f32.to_le_bytes());
            } else {
                for _ in 0..3 {
                    b.extend_from_slice(&0f32.to_le_bytes());
                }
                b.extend_from_slice(&(-1f32).to_le_bytes());
            }
        }
        if let Some(a) = out.analog {
            let rows = f * analog_words..(f + 1) * analog_words;
            match &a.samples {
                Samples::Int { values, .. } => {
                    for &v in &values[rows] {
                        b.extend_from_slice(&(v as f32).to_le_bytes());
                    }
                }
                Samples::Float(v) => {
                    for x in &v[rows] {
                        b.extend_from_slice(&x.to_le_bytes());
                    }
                }
            }
        }
    }
    // The data section fills whole blocks.
    b.resize(b.len().div_ceil(BLOCK) * BLOCK, 0);
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::analog::Channel;
    use crate::motion::formats::{read_as, Format, ReadOptions};
    use crate::motion::units::{Unit, UnitSource};

    #[test]
    fn a_written_file_reads_back_whole() {
        let names: Vec<String> = ["HEAD", "LTOE"].iter().map(|s| s.to_string()).collect();
        let mut pos: Vec<f32> = (0..4 * 2 * 3).map(|v| v as f32 * 1.5).collect();
        pos[3..6].fill(f32::NAN); // LTOE missing in frame 0
        let unit = Unit::new(0.001, UnitSource::Declared).unwrap();
        let m = Motion::new(50.0, unit, names, pos, None).unwrap();
        let a = Analog::new(
            4,
            0.5,
            vec![
                Channel {
                    label: "Fz1".into(),
                    description: "force".into(),
                    unit: "N".into(),
                    scale: 2.0,
                    offset: 40_000,
                },
                Channel {
                    label: "EMG".into(),
                    description: String::new(),
                    unit: "V".into(),
                    scale: 0.001,
                    offset: 5,
                },
            ],
            Samples::Int {
                values: (0..4 * 4 * 2).map(|v| 39_990 + v).collect(),
                unsigned: true,
            },
        )
        .unwrap();
        let mut params = Parameters::default();
        params.set("FORCE_PLATFORM", int("USED", 1));
        params.set(
            "EVENT",
            Parameter::new("TIMES", vec![2, 1], Values::Float(vec![0.0, 0.04])),
        );
        params.set("EVENT", int("USED", 1));
        let bytes = write(&Out {
            motion: &m,
            analog: Some(&a),
            outputs: None,
            parameters: Some(&params),
            first_frame: 1,
        })
        .unwrap();
        let back = read_as(Format::C3d, &bytes, &ReadOptions::default()).unwrap();
        assert_eq!(back.motion.point_names, m.point_names);
        assert_eq!(back.motion.fps, 50.0);
        for f in 0..4 {
            for p in 0..2 {
                assert_eq!(
                    back.motion.sample(f, p),
                    m.sample(f, p),
                    "frame {f} point {p}"
                );
            }
        }
        let ba = back.extras.analog.unwrap();
        assert_eq!(ba.rows(), a.rows());
        for r in 0..a.rows() {
            for c in 0..2 {
                assert_eq!(ba.value(r, c), a.value(r, c));
            }
        }
        assert_eq!(ba.channels, a.channels);
        assert_eq!(back.extras.events.len(), 1);
        assert!((back.extras.events[0].time_s - 0.04).abs() < 1e-6);
        let bp = back.extras.parameters.unwrap();
        assert_eq!(bp.number("FORCE_PLATFORM", "USED"), Some(1.0));

        // A take that ends past frame 65535 of its trial keeps every frame and its start.
        let late = write(&Out {
            motion: &m,
            analog: Some(&a),
            outputs: None,
            parameters: Some(&params),
            first_frame: 65_534,
        })
        .unwrap();
        let back = read_as(Format::C3d, &late, &ReadOptions::default()).unwrap();
        assert_eq!(back.motion.frame_count(), 4);
        assert_eq!(back.extras.first_frame, Some(65_534));
        // The event at 0.04 s of the trial lies far before this take's first frame.
        assert!(back.extras.events[0].frame < 0);
    }
}
