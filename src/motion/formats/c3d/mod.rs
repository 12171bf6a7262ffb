//! C3D: the biomechanics binary format (a 512-byte header block, a parameter section of
//! groups and typed parameters, then frames of points and analog samples).
//!
//! Everything is read: points, analog channels (values exactly as stored, with their
//! scale and offset: [`crate::motion::analog`]), events (`EVENT`) and the whole parameter
//! section as a typed tree ([`params`]), so that a file can be archived and written back
//! ([`write`]). Supported: Intel (IEEE LE), DEC (VAX F-float, LE integers) and SGI/MIPS
//! (IEEE BE) processor types; integer storage with `POINT:SCALE` and float storage;
//! `TRIAL:ACTUAL_START_FIELD/END_FIELD` for files longer than 65535 frames; residual < 0
//! as a missing sample; `ANALOG:FORMAT UNSIGNED`.
//!
//! Why not the `c3dio` crate: on this project's corpus it refuses 9 files that ezc3d reads
//! (force-plate and analog parameter checks that fail on real files, `POINT:UNITS` treated
//! as mandatory) and has no DEC/SGI float path we could verify; reading points needs a
//! fraction of what it does, so we keep a small reader we can test against the manifest.

pub mod params;
pub mod write;

use super::{perr, unsettled_unit, Extras, Format, Parsed, ReadLimits};
use crate::motion::analog::{self, Analog, Samples};
use crate::motion::error::{Error, Location, Result};
use crate::motion::events::Event;
use crate::motion::model::Motion;
use crate::motion::outputs::{Kind, Output, Outputs};
use crate::motion::units::parse_unit;
use params::Parameters;

const BLOCK: usize = 512;
const FMT: Format = Format::C3d;

fn err(offset: usize, reason: impl Into<String>) -> Error {
    perr(FMT, Location::Offset(offset), reason)
}

/// Byte order and float encoding, from the parameter section's processor byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Processor {
    Intel,
    Dec,
    Mips,
}

impl Processor {
    fn from_byte(b: u8) -> Option<Self> {
        match b {
            84 => Some(Processor::Intel),
            85 => Some(Processor::Dec),
            86 => Some(Processor::Mips),
            _ => None,
        }
    }

    fn i16(self, b: &[u8]) -> i16 {
        let a = [b[0], b[1]];
        match self {
            Processor::Mips => i16::from_be_bytes(a),
            _ => i16::from_le_bytes(a),
        }
    }

    fn u16(self, b: &[u8]) -> u16 {
        self.i16(b) as u16
    }

    fn f32(self, b: &[u8]) -> f32 {
        match self {
            Processor::Intel => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            Processor::Mips => f32::from_be_bytes([b[0], b[1], b[2], b[3]]),
            Processor::Dec => dec_f32([b[0], b[1], b[2], b[3]]),
        }
    }
}

/// VAX F-float to IEEE: the two 16-bit words are swapped relative to IEEE little-endian,
/// and the exponent bias and hidden-bit position together make the value 4 times larger.
fn dec_f32(b: [u8; 4]) -> f32 {
    let ieee = f32::from_le_bytes([b[2], b[3], b[0], b[1]]);
    if (b[1] & 0x7f) == 0 && (b[0] & 0x80) == 0 {
        // Exponent zero is zero on a VAX (no denormals).
        return 0.0;
    }
    ieee / 4.0
}

pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<Parsed> {
    if bytes.len() < BLOCK {
        return Err(err(
            0,
            format!("{} bytes is shorter than the 512-byte header", bytes.len()),
        ));
    }
    if bytes[1] != 0x50 {
        return Err(err(1, "missing the C3D key byte 0x50"));
    }
    let pstart = (bytes[0] as usize)
        .checked_sub(1)
        .map(|b| b * BLOCK)
        .filter(|&s| s + 4 <= bytes.len())
        .ok_or_else(|| {
            err(
                0,
                format!("parameter block {} is outside the file", bytes[0]),
            )
        })?;
    let proc = Processor::from_byte(bytes[pstart + 3]).ok_or_else(|| {
        err(
            pstart + 3,
            format!(
                "unknown processor type {} (84 Intel, 85 DEC, 86 MIPS)",
                bytes[pstart + 3]
            ),
        )
    })?;
    let h = |word: usize| proc.u16(&bytes[(word - 1) * 2..]);
    let header_points = h(2) as usize;
    let analog_words = h(3) as usize;
    let first = h(4) as usize;
    let last = h(5) as usize;
    let header_scale = proc.f32(&bytes[12..16]);
    let header_data_start = h(9) as usize;
    let header_rate = proc.f32(&bytes[20..24]);

    // A parameter section is at most 255 blocks (its block count is a byte).
    let params_end = match header_data_start.checked_sub(1).map(|b| b * BLOCK) {
        Some(d) if d > pstart => d.min(bytes.len()),
        _ => bytes.len(),
    }
    .min(pstart + 255 * BLOCK);
    let params = Parameters::parse(bytes, pstart, params_end, proc)?;
    let mut warnings = Vec::new();
    let mut contradictions = Vec::new();

    let points = params
        .u16s("POINT", "USED")
        .and_then(|v| v.first().copied())
        .map(usize::from)
        .unwrap_or(header_points);
    if points != header_points {
        warnings.push(format!(
            "header says {header_points} points, POINT:USED says {points}; using POINT:USED"
        ));
    }

    // Frame count: the header's 16-bit range, extended by TRIAL for long files.
    let mut frames = if last >= first && last > 0 {
        last - first + 1
    } else {
        0
    };
    let field = |name: &str| {
        params.u16s("TRIAL", name).and_then(|v| match v.as_slice() {
            [lo, hi, ..] => Some(usize::from(*lo) + (usize::from(*hi) << 16)),
            [lo] => Some(usize::from(*lo)),
            [] => None,
        })
    };
    if let (Some(s), Some(e)) = (field("ACTUAL_START_FIELD"), field("ACTUAL_END_FIELD")) {
        if e >= s && e - s + 1 > frames {
            frames = e - s + 1;
        }
    }
    limits.check_shape(frames, points)?;

    let scale = params
        .number("POINT", "SCALE")
        .map(|v| v as f32)
        .unwrap_or(header_scale);
    let float = scale < 0.0;
    let value_size = if float { 4 } else { 2 };
    let rate = params
        .number("POINT", "RATE")
        .filter(|r| r.is_finite() && *r > 0.0)
        .unwrap_or(f64::from(header_rate));
    if !(rate.is_finite() && rate > 0.0) {
        return Err(err(20, format!("frame rate {rate} is not positive")));
    }
    let data_block = if header_data_start > 0 {
        header_data_start
    } else {
        params
            .number("POINT", "DATA_START")
            .unwrap_or(0.0)
            .clamp(0.0, 65_535.0) as usize
    };
    let data_start = data_block
        .checked_sub(1)
        .map(|b| b * BLOCK)
        .ok_or_else(|| err(16, "data start block is 0"))?;

    let analog_words = analog_words_per_frame(
        &params,
        analog_words,
        h(10) as usize,
        AnalogCheck {
            rate,
            points,
            frames,
            value_size,
            data_bytes: bytes.len().saturating_sub(data_start),
        },
        &mut warnings,
    );
    let frame_bytes = (points * 4 + analog_words) * value_size;
    let available = bytes
        .len()
        .saturating_sub(data_start)
        .checked_div(frame_bytes)
        .unwrap_or(frames);
    if available < frames {
        if available == 0 && frames > 0 {
            return Err(err(
                data_start.min(bytes.len()),
                format!("data section holds no whole frame ({frames} declared)"),
            ));
        }
        contradictions.push(format!(
            "file is truncated: {frames} frames declared, {available} present"
        ));
        frames = available;
    }

    let unit = match params
        .strings("POINT", "UNITS")
        .and_then(|v| v.into_iter().next())
    {
        Some(u) if !u.is_empty() => match parse_unit(&u) {
            Ok(m) => Some(m),
            Err(_) => {
                warnings.push(format!(
                    "POINT:UNITS {u:?} is not a unit we know; inferring"
                ));
                None
            }
        },
        _ => {
            warnings.push("POINT:UNITS missing; assuming mm, the C3D default".into());
            Some(0.001)
        }
    };

    let names = labels(&params, "POINT", points, "P");
    let abs_scale = scale.abs();
    let mut positions = vec![f32::NAN; frames * points * 3];
    // Samples whose residual says valid but whose numbers are not finite (Vicon writes NaN
    // for unlabelled samples): gaps, counted.
    let mut not_finite = 0usize;
    // Frames with no point data (analog-only files) read nothing from the data section.
    for f in (0..frames).filter(|_| points > 0) {
        // `available` counted whole frames after data_start: each lies inside the file.
        let frame = &bytes[data_start + f * frame_bytes..];
        for p in 0..points {
            let at = p * 4 * value_size;
            let (xyz, residual) = if float {
                let v = |k: usize| proc.f32(&frame[at + k * 4..]);
                ([v(0), v(1), v(2)], v(3))
            } else {
                let v = |k: usize| f32::from(proc.i16(&frame[at + k * 2..]));
                ([v(0) * abs_scale, v(1) * abs_scale, v(2) * abs_scale], v(3))
            };
            // A gap as py-c3d reads one: the residual word's integer is negative (-1 marks
            // a gap; a float residual is that integer stored as a float, and it truncates
            // like a cast), or any of the four numbers is not finite.
            let marked_valid = residual.is_nan() || residual.trunc() >= 0.0;
            if !marked_valid {
                continue;
            }
            if xyz.iter().all(|c| c.is_finite()) && residual.is_finite() {
                positions[(f * points + p) * 3..(f * points + p) * 3 + 3].copy_from_slice(&xyz);
            } else {
                not_finite += 1;
            }
        }
    }
    warnings.extend(super::non_finite_warning(not_finite));
    let analog = read_analog(
        &params,
        AnalogLayout {
            words: analog_words,
            float,
            proc,
            frames,
            frame_bytes,
            at: data_start + points * 4 * value_size,
            value_size,
            rate,
        },
        bytes,
        limits,
        &mut warnings,
    )?;
    let (names, positions, outputs) = model_outputs(&params, names, positions, &mut warnings)?;
    let motion = if names.is_empty() {
        Motion::without_points(rate, unsettled_unit(), frames)?
    } else {
        Motion::new(rate, unsettled_unit(), names, positions, None)?
    };
    let first_frame = field("ACTUAL_START_FIELD")
        .filter(|&f| f >= 1)
        .unwrap_or(first.max(1));
    let events = events(&params, rate, first_frame, &mut warnings);
    Ok(Parsed {
        motion,
        declared_unit: unit,
        warnings,
        contradictions,
        extras: Extras {
            first_frame: Some(first_frame),
            analog,
            outputs,
            events,
            parameters: Some(params),
            ..Default::default()
        },
    })
}

/// The points that `POINT:ANGLES`, `FORCES`, `MOMENTS` and `POWERS` name, taken out of
/// the markers as model outputs ([`Outputs`]) in their units; the markers and their
/// positions that remain.
fn model_outputs(
    params: &Parameters,
    names: Vec<String>,
    positions: Vec<f32>,
    warnings: &mut Vec<String>,
) -> Result<(Vec<String>, Vec<f32>, Option<Outputs>)> {
    let mut kinds: Vec<Option<Kind>> = vec![None; names.len()];
    let mut counts = Vec::new();
    for kind in Kind::ALL {
        let listed = params.strings_continued("POINT", kind.list());
        let mut n = 0;
        for (slot, name) in names.iter().enumerate() {
            if kinds[slot].is_none() && listed.iter().any(|l| l == name) {
                kinds[slot] = Some(kind);
                n += 1;
            }
        }
        if n > 0 {
            counts.push(format!("{n} {}", kind.list().to_lowercase()));
        }
    }
    if counts.is_empty() {
        return Ok((names, positions, None));
    }
    let unit = |kind: Kind| {
        params
            .strings("POINT", kind.unit_parameter())
            .and_then(|v| v.into_iter().find(|u| !u.is_empty()))
            .unwrap_or_else(|| kind.default_unit().to_string())
    };
    let points = names.len();
    let outputs: Vec<Output> = kinds
        .iter()
        .enumerate()
        .filter_map(|(slot, k)| {
            k.map(|kind| Output {
                name: names[slot].clone(),
                kind,
                unit: unit(kind),
                slot,
            })
        })
        .collect();
    let frames = positions.len() / (points * 3).max(1);
    let mut values = Vec::with_capacity(frames * outputs.len() * 3);
    let mut kept = Vec::with_capacity(frames * (points - outputs.len()) * 3);
    for row in positions.chunks_exact(points * 3) {
        for (p, xyz) in row.chunks_exact(3).enumerate() {
            match kinds[p] {
                Some(_) => values.extend_from_slice(xyz),
                None => kept.extend_from_slice(xyz),
            }
        }
    }
    let markers: Vec<String> = names
        .into_iter()
        .zip(&kinds)
        .filter(|(_, k)| k.is_none())
        .map(|(n, _)| n)
        .collect();
    warnings.push(format!(
        "{} model outputs ({}) kept apart from the markers, in their own units",
        outputs.len(),
        counts.join(", ")
    ));
    let outputs = Outputs::new(outputs, values).map_err(|e| err(0, e.to_string()))?;
    Ok((markers, kept, Some(outputs)))
}

/// What decides how many analog values a frame holds, beside the header.
struct AnalogCheck {
    rate: f64,
    points: usize,
    frames: usize,
    value_size: usize,
    data_bytes: usize,
}

/// Analog values per frame. The standard's header word 3 holds it (channels × samples
/// per frame), but some writers (MotionMonitor) put the channel count there and the
/// samples per frame in word 10: where `ANALOG:USED` × word 10 (or × `ANALOG:RATE /
/// POINT:RATE`) is the count that fills the data section and word 3 is not, that count is
/// used, with a warning — as ezc3d reads such files.
fn analog_words_per_frame(
    params: &Parameters,
    header_words: usize,
    header_per_frame: usize,
    c: AnalogCheck,
    warnings: &mut Vec<String>,
) -> usize {
    let used = params
        .u16s("ANALOG", "USED")
        .and_then(|v| v.first().copied())
        .map_or(0, usize::from);
    if used == 0 || c.frames == 0 || Some(header_words) == used.checked_mul(header_per_frame.max(1))
    {
        return header_words;
    }
    let fits = |words: usize| {
        let frame = (c.points * 4 + words) * c.value_size;
        let need = frame.saturating_mul(c.frames);
        need <= c.data_bytes && c.data_bytes - need < BLOCK + frame
    };
    if fits(header_words) {
        return header_words;
    }
    let by_rate = params
        .number("ANALOG", "RATE")
        .map(|r| r / c.rate)
        .filter(|k| k.is_finite() && *k >= 1.0 && *k <= 65_535.0 && (k - k.round()).abs() < 1e-6)
        .map(|k| k.round() as usize);
    for per_frame in [Some(header_per_frame).filter(|&k| k > 0), by_rate]
        .into_iter()
        .flatten()
    {
        // A frame holds at most 65535 analog words (the header's 16-bit count).
        let words = used * per_frame;
        if words <= 65_535 && fits(words) {
            warnings.push(format!(
                "header word 3 says {header_words} analog values per frame; the data holds \
                 {used} channels × {per_frame} samples ({words}), which are read"
            ));
            return words;
        }
    }
    header_words
}

/// Where a file's analog values lie: `words` per frame after the points, from `at`.
struct AnalogLayout {
    words: usize,
    float: bool,
    proc: Processor,
    frames: usize,
    frame_bytes: usize,
    at: usize,
    value_size: usize,
    rate: f64,
}

/// The analog channels of a file, if it has any: `ANALOG:USED` channels, the header's
/// analog words per frame divided among them (`ANALOG:RATE / POINT:RATE` where the header
/// has none), values exactly as stored.
fn read_analog(
    params: &Parameters,
    l: AnalogLayout,
    bytes: &[u8],
    limits: &ReadLimits,
    warnings: &mut Vec<String>,
) -> Result<Option<Analog>> {
    let used = params
        .u16s("ANALOG", "USED")
        .and_then(|v| v.first().copied())
        .map_or(0, usize::from);
    if l.words == 0 || used == 0 {
        if l.words > 0 {
            warnings.push(format!(
                "{} analog values per frame but ANALOG:USED is 0; analog data not kept",
                l.words
            ));
        }
        return Ok(None);
    }
    if !l.words.is_multiple_of(used) {
        return Err(err(
            4,
            format!(
                "{} analog values per frame do not divide among ANALOG:USED {used} channels",
                l.words
            ),
        ));
    }
    let per_frame = l.words / used;
    if let Some(r) = params.number("ANALOG", "RATE") {
        let stated = r / l.rate;
        if (stated - per_frame as f64).abs() > 1e-3 * per_frame as f64 {
            warnings.push(format!(
                "ANALOG:RATE {r} is not {per_frame} × the point rate {}; the header's {per_frame} \
                 samples per frame are used",
                l.rate
            ));
        }
    }
    let rows = l.frames * per_frame;
    let total = (rows as u64).saturating_mul(used as u64);
    if total > limits.max_analog_samples {
        return Err(Error::Limit {
            what: "analog sample count (rows × channels)",
            actual: total,
            limit: limits.max_analog_samples,
        });
    }
    let unsigned = params
        .strings("ANALOG", "FORMAT")
        .and_then(|v| v.into_iter().next())
        .is_some_and(|f| f.eq_ignore_ascii_case("UNSIGNED"));
    let names = labels(params, "ANALOG", used, "A");
    let descriptions = params.strings_continued("ANALOG", "DESCRIPTIONS");
    let units = params.strings_continued("ANALOG", "UNITS");
    let scales = params.numbers_continued("ANALOG", "SCALE");
    let offsets: Vec<i32> = {
        let raw = params.numbers_continued("ANALOG", "OFFSET");
        raw.into_iter()
            .map(|o| {
                let o = o as i32;
                if unsigned && o < 0 {
                    o + 65_536
                } else {
                    o
                }
            })
            .collect()
    };
    let gen_scale = params.number("ANALOG", "GEN_SCALE").unwrap_or(1.0) as f32;
    let channels = names
        .into_iter()
        .enumerate()
        .map(|(i, label)| analog::Channel {
            label,
            description: descriptions.get(i).cloned().unwrap_or_default(),
            unit: units.get(i).cloned().unwrap_or_default(),
            scale: scales.get(i).map_or(1.0, |&s| s as f32),
            offset: offsets.get(i).copied().unwrap_or(0),
        })
        .collect();
    let n = rows * used;
    let word = |f: usize, k: usize| &bytes[l.at + f * l.frame_bytes + k * l.value_size..];
    let samples = if l.float {
        let mut v = Vec::with_capacity(n);
        for f in 0..l.frames {
            v.extend((0..l.words).map(|k| l.proc.f32(word(f, k))));
        }
        Samples::Float(v)
    } else {
        let mut v = Vec::with_capacity(n);
        for f in 0..l.frames {
            v.extend((0..l.words).map(|k| {
                let w = word(f, k);
                if unsigned {
                    i32::from(l.proc.u16(w))
                } else {
                    i32::from(l.proc.i16(w))
                }
            }));
        }
        Samples::Int {
            values: v,
            unsigned,
        }
    };
    Ok(Some(Analog::new(per_frame, gen_scale, channels, samples)?))
}

/// What a C3D says of its up axis. Its force plates lie in the floor: when
/// `FORCE_PLATFORM:CORNERS` lie in one plane across an axis, that axis is up, the way
/// `POINT:Y_SCREEN` points along it if it names that axis, else the positive way (labs put
/// the origin on the floor, the subject above it). Else `POINT:Y_SCREEN` names the axis a
/// viewer shows pointing up (`+Z`, `-Y`, …), as Vicon, Qualisys and Motion Analysis write
/// it; else the lab convention (ISB, c3d.org) of Z up.
pub(crate) fn up_prior(params: Option<&Parameters>) -> crate::motion::body::Prior {
    use crate::motion::body::{Axis, Prior};
    let stated = params
        .and_then(|p| p.strings("POINT", "Y_SCREEN"))
        .and_then(|v| v.first().map(|s| s.trim().to_string()))
        .and_then(|s| s.parse::<Axis>().ok().map(|a| (a, s)));
    if let Some(plane) = params.and_then(plates_normal) {
        return match &stated {
            Some((up, s)) if up.index() == plane.index() => Prior {
                up: *up,
                says: format!(
                    "the file's force plates lie in a plane across {plane} (the floor), and \
                     its POINT:Y_SCREEN is {s}"
                ),
            },
            _ => Prior {
                up: plane,
                says: format!("the file's force plates lie in a plane across {plane} (the floor)"),
            },
        };
    }
    match stated {
        Some((up, s)) => Prior {
            up,
            says: format!("the file's POINT:Y_SCREEN is {s}"),
        },
        None => Prior {
            up: Axis::Z,
            says: "a lab C3D is Z-up by convention".into(),
        },
    }
}

/// The axis across which every force plate corner lies in one plane: their coordinates
/// along it spread less than 5% of their widest spread along another.
fn plates_normal(params: &Parameters) -> Option<crate::motion::body::Axis> {
    use crate::motion::body::Axis;
    let corners = params.get("FORCE_PLATFORM", "CORNERS")?.numbers();
    if corners.len() < 12 || corners.len() % 3 != 0 || corners.iter().any(|c| !c.is_finite()) {
        return None;
    }
    let spread = |k: usize| {
        let v = corners.iter().skip(k).step_by(3);
        let (lo, hi) = v.fold((f64::MAX, f64::MIN), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        hi - lo
    };
    let spreads = [spread(0), spread(1), spread(2)];
    let (flat, &least) = spreads
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let others = spreads.iter().enumerate().filter(|(k, _)| *k != flat);
    let wide = others.map(|(_, s)| *s).fold(0.0, f64::max);
    (wide > 0.0 && least <= 0.05 * wide).then(|| [Axis::X, Axis::Y, Axis::Z][flat])
}

/// `base`, or `base_2`, `base_3`… if taken.
fn unique(taken: &[String], base: &str) -> String {
    let mut name = base.to_string();
    let mut k = 2;
    while taken.contains(&name) {
        name = format!("{base}_{k}");
        k += 1;
    }
    name
}

/// `EVENT:USED` events: contexts, labels, descriptions, subjects and times (`TIMES` is
/// `2 × n`: minutes, seconds).
fn events(params: &Parameters, rate: f64, first: usize, warnings: &mut Vec<String>) -> Vec<Event> {
    let used = params
        .u16s("EVENT", "USED")
        .and_then(|v| v.first().copied())
        .map_or(0, usize::from);
    if used == 0 {
        return Vec::new();
    }
    let times = params
        .get("EVENT", "TIMES")
        .map(|p| p.numbers())
        .unwrap_or_default();
    let contexts = params.strings_continued("EVENT", "CONTEXTS");
    let labels = params.strings_continued("EVENT", "LABELS");
    let descriptions = params.strings_continued("EVENT", "DESCRIPTIONS");
    let subjects = params.strings_continued("EVENT", "SUBJECTS");
    if times.len() < used * 2 {
        warnings.push(format!(
            "EVENT:USED is {used} but EVENT:TIMES holds {} times; the rest are not events",
            times.len() / 2
        ));
    }
    let text = |v: &[String], i: usize| v.get(i).cloned().unwrap_or_default();
    let not_finite = (0..used.min(times.len() / 2))
        .filter(|&i| !(times[2 * i] * 60.0 + times[2 * i + 1]).is_finite())
        .count();
    if not_finite > 0 {
        warnings.push(format!(
            "{not_finite} events have a time that is not a number; they are left out"
        ));
    }
    (0..used.min(times.len() / 2))
        .filter(|&i| (times[2 * i] * 60.0 + times[2 * i + 1]).is_finite())
        .map(|i| {
            let time_s = times[2 * i] * 60.0 + times[2 * i + 1];
            let trial_frame = (time_s * rate).round().clamp(-1e15, 1e15) as i64 + 1;
            Event {
                context: text(&contexts, i),
                label: text(&labels, i),
                time_s,
                frame: trial_frame - first as i64,
                description: text(&descriptions, i),
                subject: text(&subjects, i),
            }
        })
        .collect()
}

/// The first `n` labels of `group:LABELS`, `LABELS2`, …, as names: a blank one becomes
/// `{prefix}{i}` (1-based) and a repeated one gets `_2`, `_3`…, so that every point and
/// channel can be asked for by name. The writer uses the same rule to tell whether the
/// upload's labels still name what it writes.
pub(crate) fn labels(params: &Parameters, group: &str, n: usize, prefix: &str) -> Vec<String> {
    let labels = params.strings_continued(group, "LABELS");
    let mut names: Vec<String> = Vec::with_capacity(n);
    for i in 0..n {
        let base = labels
            .get(i)
            .filter(|s| !s.is_empty())
            .cloned()
            .unwrap_or_else(|| format!("{prefix}{}", i + 1));
        names.push(unique(&names, &base));
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Force plates lie in the floor: their corners' plane is up, whatever axis Y_SCREEN
    /// names (its sign counts when it names the same one); plates standing on edge across
    /// no axis say nothing.
    #[test]
    fn force_plates_tell_up() {
        use crate::motion::body::Axis;
        use params::{Parameter, Values};
        let with = |corners: Vec<f32>, screen: Option<&str>| {
            let mut p = Parameters::default();
            let n = (corners.len() / 12) as u8;
            p.set(
                "FORCE_PLATFORM",
                Parameter::new("CORNERS", vec![3, 4, n], Values::Float(corners)),
            );
            if let Some(s) = screen {
                let v = s.as_bytes().to_vec();
                p.set(
                    "POINT",
                    Parameter::new("Y_SCREEN", vec![v.len() as u8], Values::Char(v)),
                );
            }
            up_prior(Some(&p))
        };
        // Two plates in the y ≈ 0 plane (MotionMonitor's, metres).
        let flat_y = vec![
            0.5, 0.003, 0.4, -0.5, 0.001, 0.4, -0.5, -0.02, -0.2, 0.5, -0.029, -0.2, //
            1.5, 0.0, 0.4, 0.6, 0.0, 0.4, 0.6, -0.01, -0.2, 1.5, 0.0, -0.2,
        ];
        let p = with(flat_y.clone(), Some("+Z"));
        assert_eq!(p.up, Axis::Y, "{}", p.says);
        assert!(p.says.contains("force plates"), "{}", p.says);
        let p = with(flat_y, Some("-Y"));
        assert_eq!(p.up, Axis::Y.flipped(), "{}", p.says);
        // A tilted plate: no plane across an axis; Y_SCREEN then.
        let tilted = vec![0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 0.0];
        assert_eq!(with(tilted, Some("+Z")).up, Axis::Z);
        assert_eq!(with(vec![0.0; 12], None).up, Axis::Z);
    }

    #[test]
    fn dec_floats_convert() {
        // 1.0 in VAX F is 0x4080 0x0000 (words), stored little-endian per word.
        assert_eq!(dec_f32([0x80, 0x40, 0x00, 0x00]), 1.0);
        // -2.5: IEEE 0xC0200000 → VAX exponent +2 → 0xC120 0000.
        assert_eq!(dec_f32([0x20, 0xC1, 0x00, 0x00]), -2.5);
        assert_eq!(dec_f32([0, 0, 0, 0]), 0.0);
    }

    /// Builds small Intel integer C3D files (scale 0.5, 100 fps, one point "HEAD").
    struct Builder {
        params: Vec<u8>,
    }

    impl Builder {
        fn new() -> Self {
            let mut b = Builder { params: Vec::new() };
            b.group(1, "POINT");
            b.group(2, "TRIAL");
            b.param(1, "UNITS", -1, &[2], b"mm");
            b.param(1, "LABELS", -1, &[4, 1], b"HEAD");
            b
        }

        fn group(&mut self, id: i8, name: &str) {
            self.params
                .extend_from_slice(&[name.len() as u8, (-id) as u8]);
            self.params.extend_from_slice(name.as_bytes());
            self.params.extend_from_slice(&3i16.to_le_bytes());
            self.params.push(0);
        }

        fn param(&mut self, group: i8, name: &str, kind: i8, dims: &[u8], data: &[u8]) {
            self.params
                .extend_from_slice(&[name.len() as u8, group as u8]);
            self.params.extend_from_slice(name.as_bytes());
            let next = 2 + 2 + dims.len() + data.len() + 1;
            self.params.extend_from_slice(&(next as i16).to_le_bytes());
            self.params
                .extend_from_slice(&[kind as u8, dims.len() as u8]);
            self.params.extend_from_slice(dims);
            self.params.extend_from_slice(data);
            self.params.push(0);
        }

        /// `frames` rows of `[x, y, z, residual]` raw integers; the header claims
        /// `header_frames`.
        fn build(&self, header_frames: u16, frames: &[[i16; 4]]) -> Vec<u8> {
            let mut b = vec![0u8; 2 * BLOCK];
            b[0] = 2;
            b[1] = 0x50;
            let w = |b: &mut Vec<u8>, word: usize, v: u16| {
                b[(word - 1) * 2..(word - 1) * 2 + 2].copy_from_slice(&v.to_le_bytes())
            };
            w(&mut b, 2, 1);
            w(&mut b, 4, 1);
            w(&mut b, 5, header_frames);
            b[12..16].copy_from_slice(&0.5f32.to_le_bytes());
            w(&mut b, 9, 3);
            b[20..24].copy_from_slice(&100f32.to_le_bytes());
            b[BLOCK + 2] = 1;
            b[BLOCK + 3] = 84;
            b[BLOCK + 4..BLOCK + 4 + self.params.len()].copy_from_slice(&self.params);
            for f in frames {
                for v in f {
                    b.extend_from_slice(&v.to_le_bytes());
                }
            }
            b
        }
    }

    /// As [`Builder::build`], in float storage (`POINT:SCALE` -0.5): `[x, y, z, residual]`
    /// floats, as Vicon Nexus writes them.
    fn build_float(b: &Builder, frames: &[[f32; 4]]) -> Vec<u8> {
        let mut out = b.build(frames.len() as u16, &[]);
        out[12..16].copy_from_slice(&(-0.5f32).to_le_bytes());
        for f in frames {
            for v in f {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    #[test]
    fn non_finite_samples_are_gaps_as_py_c3d_reads_them() {
        let nan = f32::NAN;
        let rows = [
            [1.0, 2.0, 3.0, 0.0],  // valid
            [nan, nan, nan, 0.0],  // Vicon's unlabelled sample: NaN, residual 0
            [4.0, 5.0, 6.0, -1.0], // a gap by its residual
            [7.0, 8.0, 9.0, -0.5], // py-c3d casts the residual to an integer: 0, valid
            [1.0, 1.0, 1.0, nan],  // a residual that is not a number: a gap, counted
            [f32::INFINITY, 0.0, 0.0, 2.0],
        ];
        let p = read(&build_float(&Builder::new(), &rows), &ReadLimits::default()).unwrap();
        assert!(p.contradictions.is_empty(), "{:?}", p.contradictions);
        let m = &p.motion;
        let valid: Vec<bool> = (0..6).map(|f| m.sample(f, 0).is_some()).collect();
        assert_eq!(valid, [true, false, false, true, false, false]);
        assert_eq!(m.sample(3, 0), Some([7.0, 8.0, 9.0]));
        assert!(
            p.warnings
                .iter()
                .any(|w| w.starts_with("3 samples") && w.contains("not finite")),
            "{:?}",
            p.warnings
        );
    }

    fn tiny_c3d(residual_frame1: i16) -> Vec<u8> {
        Builder::new().build(2, &[[2, 4, 6, 0], [8, 10, 12, residual_frame1]])
    }

    fn u16s(v: &[u16]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    #[test]
    fn trial_fields_extend_the_16_bit_frame_count() {
        let rows = [[1, 1, 1, 0], [2, 2, 2, 0], [3, 3, 3, 0]];
        let mut b = Builder::new();
        b.param(2, "ACTUAL_START_FIELD", 2, &[2], &u16s(&[1, 0]));
        b.param(2, "ACTUAL_END_FIELD", 2, &[2], &u16s(&[3, 0]));
        let p = read(&b.build(2, &rows), &ReadLimits::default()).unwrap();
        assert_eq!(p.motion.frame_count(), 3);
        // The high word counts 65536 frames: more than the file holds, so it is cut to what
        // is present, and the reader reports that the file contradicts its header (refused
        // unless the read is lenient).
        let mut b = Builder::new();
        b.param(2, "ACTUAL_START_FIELD", 2, &[2], &u16s(&[1, 0]));
        b.param(2, "ACTUAL_END_FIELD", 2, &[2], &u16s(&[2, 1]));
        let p = read(&b.build(2, &rows), &ReadLimits::default()).unwrap();
        assert_eq!(p.motion.frame_count(), 3);
        assert!(p
            .contradictions
            .iter()
            .any(|w| w.contains("65538 frames declared")));
    }

    #[test]
    fn reads_a_hand_made_file() {
        let p = read(&tiny_c3d(0), &ReadLimits::default()).unwrap();
        let m = p.motion;
        assert_eq!(m.point_names, vec!["HEAD"]);
        assert_eq!(m.frame_count(), 2);
        assert_eq!(m.fps, 100.0);
        assert_eq!(p.declared_unit, Some(0.001));
        assert_eq!(m.positions(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    }

    #[test]
    fn negative_residual_is_a_gap() {
        let m = read(&tiny_c3d(-1), &ReadLimits::default()).unwrap().motion;
        assert_eq!(m.gap_count(), 1);
        assert!(m.sample(1, 0).is_none());
    }

    #[test]
    fn truncation_and_corruption_never_panic() {
        let good = tiny_c3d(0);
        for cut in 0..good.len() {
            let _ = read(&good[..cut], &ReadLimits::default());
        }
        for i in 0..good.len() {
            let mut b = good.clone();
            b[i] ^= 0xA5;
            let _ = read(&b, &ReadLimits::default());
        }
    }
}
