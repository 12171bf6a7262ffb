//! File formats in and out: detection from content, limits on untrusted input, and one
//! reader/writer module per format.
//!
//! Readers take bytes, not paths, so the HTTP layer can hand them a request body and tests
//! can hand them mutations.

use super::body::{Axis, Prior};
use super::error::{Error, Location, Result};
pub use super::format::Format;
use super::model::Motion;
use super::units::{Unit, UnitSource};

pub mod bvh;
pub mod c3d;
pub mod columns;
pub mod csv;
pub mod fbx;
pub mod gltf;
pub mod json;
pub mod npy;
mod posed;
pub mod rawf32;
pub mod rig;
mod text;
pub mod trc;
pub mod writer;

pub use writer::{FrameWriter, Shape};

/// Bounds on untrusted input, checked before anything proportional to them is allocated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    pub max_bytes: u64,
    pub max_points: u64,
    pub max_frames: u64,
    /// Points × frames: what memory really scales with.
    pub max_samples: u64,
    /// Nesting depth of a skeleton hierarchy (root = 1).
    pub max_depth: u64,
    /// Analog rows × channels.
    pub max_analog_samples: u64,
}

impl Default for ReadLimits {
    /// The service's defaults ([`crate::limits`], where every limit is set and explained).
    fn default() -> Self {
        ReadLimits::from(&crate::limits::Limits::default())
    }
}

impl From<&crate::limits::Limits> for ReadLimits {
    /// What file readers may accept under the service's policy.
    fn from(l: &crate::limits::Limits) -> Self {
        ReadLimits {
            max_bytes: l.upload_bytes,
            max_points: l.points,
            max_frames: l.frames,
            max_samples: l.samples,
            max_depth: l.hierarchy_depth,
            max_analog_samples: l.analog_samples,
        }
    }
}

impl ReadLimits {
    pub fn check_bytes(&self, n: usize) -> Result<()> {
        check("input size in bytes", n as u64, self.max_bytes)
    }

    /// Work a reader does per frame over `per_frame` things (an FBX or glTF node tree
    /// composed, its channels sampled), bounded like samples: a file of few joints and many
    /// other nodes cannot make reading it unbounded.
    pub fn check_work(&self, frames: usize, per_frame: usize) -> Result<()> {
        check(
            "evaluation work (frames × nodes or channels)",
            (frames as u64).saturating_mul(per_frame as u64),
            self.max_samples,
        )
    }

    pub fn check_shape(&self, frames: usize, points: usize) -> Result<()> {
        check("point count", points as u64, self.max_points)?;
        check("frame count", frames as u64, self.max_frames)?;
        check(
            "sample count (frames × points)",
            (frames as u64).saturating_mul(points as u64),
            self.max_samples,
        )
    }
}

fn check(what: &'static str, actual: u64, limit: u64) -> Result<()> {
    if actual > limit {
        Err(Error::Limit {
            what,
            actual,
            limit,
        })
    } else {
        Ok(())
    }
}

/// How to read: limits, and a unit that overrides whatever the file says or lacks.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    pub limits: ReadLimits,
    /// Metres per stored unit, stated by the user.
    pub unit: Option<f64>,
    /// Frames per second, stated by the user (overrides the file; NPY has none).
    pub fps: Option<f64>,
    /// Keep a file whose data contradicts its header or physical sense (fewer frames than
    /// declared, values that are not finite or lie beyond any physical scale), with a
    /// warning, instead of refusing it. Off by default: an archive that silently keeps half
    /// a take is worse than one that says no.
    pub lenient: bool,
    /// Which of a file's animations (FBX stacks, glTF animations) to read, counted from 0
    /// in the file's order ([`Extras::animations`]); none: the first.
    pub animation: Option<Pick>,
}

/// One of a file's animations, by its place in the file (from 0) or its name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Pick {
    Index(usize),
    Name(String),
}

impl std::str::FromStr for Pick {
    type Err = std::convert::Infallible;
    /// A number is a place; anything else a name.
    fn from_str(s: &str) -> std::result::Result<Pick, Self::Err> {
        Ok(match s.trim().parse::<usize>() {
            Ok(i) => Pick::Index(i),
            Err(_) => Pick::Name(s.trim().to_string()),
        })
    }
}

impl Pick {
    /// The place of the animation picked among a file's `names`; none picked: the first.
    pub(crate) fn place(pick: Option<&Pick>, names: &[String]) -> Result<usize> {
        let found = match pick {
            None if names.is_empty() => None,
            None => Some(0),
            Some(Pick::Index(i)) => Some(*i).filter(|&i| i < names.len()),
            Some(Pick::Name(n)) => names.iter().position(|a| a == n),
        };
        found.ok_or_else(|| {
            let asked = match pick {
                Some(Pick::Index(i)) => format!("animation {i}"),
                Some(Pick::Name(n)) => format!("animation {n:?}"),
                None => "an animation".into(),
            };
            match names.len() {
                0 => Error::Invalid(format!("{asked} asked for; the file holds no animation")),
                n => Error::Invalid(format!(
                    "{asked} asked for; the file has {n}, from 0: {}",
                    names.join(", ")
                )),
            }
        })
    }
}

/// A take as read from a file, with what the reader noticed but could work around.
#[derive(Debug, Clone)]
pub struct Loaded {
    pub motion: Motion,
    pub format: Format,
    /// What the format says of the up axis (BVH's convention, a C3D's parameters), for
    /// when the body cannot tell ([`super::body`]).
    pub up: Option<Prior>,
    pub warnings: Vec<String>,
    pub extras: Extras,
}

/// What a file holds beside its points: C3D's analog channels, events and parameter
/// section. Other formats have none.
#[derive(Debug, Clone, Default)]
pub struct Extras {
    /// The trial frame number of the take's first frame (C3D's header or
    /// `TRIAL:ACTUAL_START_FIELD`); `None` where the format has none (then 1).
    pub first_frame: Option<usize>,
    pub analog: Option<super::analog::Analog>,
    /// Model outputs (a C3D's joint angles, forces, moments, powers), apart from the
    /// markers.
    pub outputs: Option<super::outputs::Outputs>,
    pub events: Vec<super::events::Event>,
    pub parameters: Option<c3d::params::Parameters>,
    /// What the file says the take is of (a JSON document's `labels`).
    pub labels: crate::labels::Labels,
    /// The up axis the file states (an FBX's `GlobalSettings`), over its format's
    /// convention.
    pub up: Option<crate::motion::body::Prior>,
    /// The names of every animation the file holds (FBX stacks, glTF animations), in its
    /// order: each is a take of its own ([`ReadOptions::animation`] picks one).
    pub animations: Vec<String>,
    /// Which of them this take is (its place in `animations`).
    pub animation: usize,
}

/// What a format reader returns before units are settled.
#[derive(Debug)]
pub(crate) struct Parsed {
    pub motion: Motion,
    /// Unit the file declared, if it declares one.
    pub declared_unit: Option<f64>,
    pub warnings: Vec<String>,
    /// Where the data contradicts the file's own header or physical sense: refused unless
    /// the reader is lenient, then kept as warnings (with the bad samples as gaps).
    pub contradictions: Vec<String>,
    pub extras: Extras,
}

/// Samples (point triples) with an infinite coordinate (or one that overflowed f32): never
/// a position.
pub(crate) fn infinite_samples(positions: &[f32]) -> usize {
    positions
        .chunks_exact(3)
        .filter(|s| s.iter().any(|v| v.is_infinite()))
        .count()
}

/// The warning for `n` samples whose coordinates are not finite numbers (NaN where the
/// format marks gaps otherwise, ±infinity, overflow), kept as missing samples: a number
/// that is not one is a gap, not a broken file. Vicon writes NaN for unlabelled samples;
/// ezc3d and py-c3d read such files, and so do we.
pub(crate) fn non_finite_warning(n: usize) -> Option<String> {
    (n > 0).then(|| {
        format!(
            "{n} samples have coordinates that are not finite numbers (NaN or ±infinity); \
             stored as missing samples"
        )
    })
}

/// Guess the format from the first bytes.
pub fn detect(bytes: &[u8]) -> Result<Format> {
    let trimmed = skip_bom_and_space(bytes);
    if bytes.is_empty() || trimmed.is_empty() {
        return Err(Error::UnknownFormat("the input is empty".into()));
    }
    if bytes.starts_with(b"\x93NUMPY") {
        return Ok(Format::Npy);
    }
    if bytes.starts_with(b"Kaydara FBX Binary") {
        return Ok(Format::Fbx);
    }
    if bytes.starts_with(b"glTF") {
        return Ok(Format::Glb);
    }
    // C3D: byte 2 of the header is the key 0x50, byte 1 points at the parameter block.
    if bytes.len() >= 512 && bytes[1] == 0x50 && bytes[0] >= 2 {
        return Ok(Format::C3d);
    }
    let head = &trimmed[..trimmed.len().min(64)];
    let starts = |w: &[u8]| head.len() >= w.len() && head[..w.len()].eq_ignore_ascii_case(w);
    if starts(b"HIERARCHY") {
        return Ok(Format::Bvh);
    }
    if starts(b"PathFileType") {
        return Ok(Format::Trc);
    }
    // ASCII FBX opens with its comment line: "; FBX 7.4.0 project file".
    if starts(b"; FBX") {
        return Ok(Format::Fbx);
    }
    if trimmed[0] == b'{' {
        return Ok(if gltf::read::is_gltf_json(bytes) {
            Format::Gltf
        } else {
            Format::Json
        });
    }
    Err(Error::UnknownFormat(
        "not BVH (HIERARCHY), C3D (0x50 key), TRC (PathFileType), JSON ({), NPY (\\x93NUMPY) \
         FBX (Kaydara FBX Binary, ; FBX) or glTF (glTF, {\"asset\")"
            .into(),
    ))
}

/// Whether `bytes` hold motion this crate reads, by content: [`detect`]'s answer, and for
/// JSON a document with `points` and `frames` (a label file beside a take, such as
/// `{"content": 7, "style": 0}`, is JSON but no take). Parses nothing it does not need to.
pub fn is_motion(bytes: &[u8]) -> bool {
    #[derive(serde::Deserialize)]
    struct Shape {
        points: Option<serde::de::IgnoredAny>,
        frames: Option<serde::de::IgnoredAny>,
    }
    match detect(bytes) {
        Ok(Format::Json) => serde_json::from_slice::<Shape>(bytes)
            .is_ok_and(|s| s.points.is_some() && s.frames.is_some()),
        Ok(_) => true,
        Err(_) => false,
    }
}

fn skip_bom_and_space(bytes: &[u8]) -> &[u8] {
    let b = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let start = b
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(b.len());
    &b[start..]
}

/// Read a take from bytes of any supported format, detected from the content.
pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<Loaded> {
    options.limits.check_bytes(bytes.len())?;
    let format = detect(bytes)?;
    read_as(format, bytes, options)
}

/// Read bytes known to be of `format`.
pub fn read_as(format: Format, bytes: &[u8], options: &ReadOptions) -> Result<Loaded> {
    options.limits.check_bytes(bytes.len())?;
    let limits = &options.limits;
    let parsed = match format {
        Format::Bvh => bvh::read(bytes, limits)?,
        Format::C3d => c3d::read(bytes, limits)?,
        Format::Trc => trc::read(bytes, limits)?,
        Format::Json => json::read(bytes, limits)?,
        Format::Npy => npy::read(bytes, limits)?,
        Format::Fbx => fbx::read(bytes, limits, options.animation.as_ref())?,
        Format::Glb | Format::Gltf => gltf::read::read(bytes, options)?,
        Format::Csv | Format::F32 => {
            return Err(Error::Unsupported(format!(
                "{format} is an output format only"
            )))
        }
    };
    let Parsed {
        mut motion,
        declared_unit,
        mut warnings,
        mut contradictions,
        extras,
    } = parsed;
    motion.unit = settle_unit(&motion, declared_unit, options.unit, &mut warnings)?;
    // Beyond-scale samples: finite, but farther from the origin than any capture volume.
    let max_units = crate::limits::MAX_COORDINATE_M / motion.unit.metres_per_unit;
    let beyond = |s: &[f32]| s.iter().any(|v| f64::from(v.abs()) > max_units);
    let far = motion
        .positions()
        .chunks_exact(3)
        .filter(|s| beyond(s))
        .count();
    if far > 0 {
        contradictions.push(format!(
            "{far} samples lie more than {} m from the origin, beyond any physical scale",
            crate::limits::MAX_COORDINATE_M
        ));
    }
    if !contradictions.is_empty() {
        if !options.lenient {
            return Err(Error::Contradiction(format!(
                "{}; refused (state lenient to keep it, with the bad samples as gaps)",
                contradictions.join("; ")
            )));
        }
        motion.gap_where(beyond);
        warnings.extend(
            contradictions
                .into_iter()
                .map(|c| format!("{c}; kept because lenient was asked for")),
        );
    }
    match options.fps {
        Some(fps) => motion.fps = crate::limits::fps(fps).map_err(Error::Invalid)?,
        None if format == Format::Npy => warnings.push(format!(
            "NPY has no frame rate; assumed {} fps (state one to override)",
            npy::DEFAULT_FPS
        )),
        None => {}
    }
    // What the file states (an FBX's GlobalSettings), else its format's convention.
    let up = extras
        .up
        .clone()
        .or_else(|| up_prior(format, extras.parameters.as_ref()));
    Ok(Loaded {
        motion,
        format,
        up,
        warnings,
        extras,
    })
}

/// What a file of `format` says of its up axis before its body is looked at (a C3D by its
/// `parameters`): BVH and TRC are Y-up by convention (BVH's viewers, OpenSim's TRC), a C3D
/// says it in `POINT:Y_SCREEN` or is Z-up; the other formats say nothing.
pub fn up_prior(format: Format, parameters: Option<&c3d::params::Parameters>) -> Option<Prior> {
    let convention = |says: &str| Prior {
        up: Axis::Y,
        says: says.into(),
    };
    match format {
        Format::Bvh => Some(convention("BVH is Y-up by convention")),
        Format::Trc => Some(convention("a TRC is Y-up by OpenSim's convention")),
        Format::C3d => Some(c3d::up_prior(parameters)),
        _ => None,
    }
}

fn settle_unit(
    motion: &Motion,
    declared: Option<f64>,
    explicit: Option<f64>,
    warnings: &mut Vec<String>,
) -> Result<Unit> {
    if let Some(m) = explicit {
        return Unit::new(m, UnitSource::Explicit);
    }
    if let Some(m) = declared {
        return Unit::new(m, UnitSource::Declared);
    }
    // The posed figure, not the rest pose: some rigs (Bandai) lay bones along X in the
    // rest pose and only stand up once rotated.
    let height = motion
        .figure_height()
        .or_else(|| motion.skeleton.as_ref().map(|s| s.rest_height()));
    match height.and_then(Unit::infer_from_height) {
        Some(u) => {
            warnings.push(format!(
                "no unit in the file; inferred {} from the figure's height",
                u.name()
            ));
            Ok(u)
        }
        None => {
            warnings.push("no unit in the file and no figure to infer it from; assuming mm".into());
            Unit::new(
                0.001,
                UnitSource::Inferred("nothing to measure; default mm".into()),
            )
        }
    }
}

/// The writer of `format` for an answer of `shape`; `fields` are extra top-level members
/// of a JSON answer (which take, which frames), ignored by readers. BVH is written from
/// joint channels ([`bvh::ChannelWriter`]), C3D and glTF whole ([`c3d::write`],
/// [`gltf`]): they are refused here.
pub fn frame_writer(
    format: Format,
    shape: Shape,
    fields: serde_json::Map<String, serde_json::Value>,
) -> Result<Box<dyn FrameWriter>> {
    Ok(match format {
        Format::Json => Box::new(json::Writer::new(shape, fields)),
        Format::Csv => Box::new(csv::Writer::new(shape)),
        Format::Trc => Box::new(trc::Writer::new(shape)),
        Format::Npy => Box::new(npy::Writer::new(shape)),
        Format::F32 => Box::new(rawf32::Writer::new(shape)),
        Format::Bvh => {
            return Err(Error::Unsupported(
                "BVH is written from a skeleton's channels, not from points".into(),
            ))
        }
        Format::C3d | Format::Glb | Format::Gltf | Format::Fbx => {
            return Err(Error::Unsupported(format!(
                "{format} is written whole, not frame by frame"
            )))
        }
    })
}

/// Write a take in `format`.
pub fn write(motion: &Motion, format: Format) -> Result<Vec<u8>> {
    match format {
        Format::Bvh => bvh::write(motion),
        _ => Ok(writer::write_whole(
            frame_writer(format, Shape::of(motion), Default::default())?,
            motion.frame_count(),
            motion.positions(),
        )),
    }
}

/// Shorthand for a parse error at a location.
pub(crate) fn perr(format: Format, at: Location, reason: impl Into<String>) -> Error {
    Error::parse(format, at, reason)
}

/// Placeholder unit for readers that leave the decision to [`read_as`].
pub(crate) fn unsettled_unit() -> Unit {
    Unit::millimetres()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::synthetic::walker;

    /// A label file is JSON but no take; a take's JSON is motion, whatever its keys' order.
    #[test]
    fn motion_is_told_from_other_files_by_content() {
        assert!(is_motion(
            b"{\"frames\": [[[1,2,3]]], \"fps\": 30, \"points\": [\"a\"]}"
        ));
        assert!(!is_motion(b"{\"content\": 7, \"style\": 0}"));
        assert!(!is_motion(b"{\"points\": [\"a\"]"));
        assert!(!is_motion(b"just text"));
        assert!(is_motion(b"HIERARCHY\nROOT Hips"));
    }

    #[test]
    fn detects_from_content() {
        assert_eq!(
            detect(b"\xEF\xBB\xBF  HIERARCHY\nROOT").unwrap(),
            Format::Bvh
        );
        assert_eq!(detect(b"PathFileType\t4").unwrap(), Format::Trc);
        assert_eq!(detect(b"\n {\"fps\":1}").unwrap(), Format::Json);
        assert_eq!(detect(b"\x93NUMPY\x01\x00").unwrap(), Format::Npy);
        assert_eq!(
            detect(b"Kaydara FBX Binary  \0\x1a\0\xe8\x1c\0\0").unwrap(),
            Format::Fbx
        );
        assert_eq!(
            detect(b"; FBX 7.4.0 project file\n; ----").unwrap(),
            Format::Fbx
        );
        let mut c3d = vec![0u8; 512];
        c3d[0] = 2;
        c3d[1] = 0x50;
        assert_eq!(detect(&c3d).unwrap(), Format::C3d);
        assert!(matches!(detect(b""), Err(Error::UnknownFormat(_))));
        assert!(matches!(detect(b"  \n"), Err(Error::UnknownFormat(_))));
        assert!(matches!(detect(b"hello"), Err(Error::UnknownFormat(_))));
    }

    #[test]
    fn limits_are_enforced() {
        let l = ReadLimits {
            max_bytes: 10,
            max_points: 2,
            max_frames: 5,
            max_samples: 6,
            max_depth: 4,
            max_analog_samples: 10,
        };
        assert!(l.check_bytes(11).is_err());
        assert!(l.check_shape(5, 2).is_err()); // 10 samples
        assert!(l.check_shape(3, 2).is_ok());
        assert!(l.check_shape(1, 3).is_err());
        let opts = ReadOptions {
            limits: l,
            ..ReadOptions::default()
        };
        assert!(matches!(
            read(b"HIERARCHY\nROOT a", &opts),
            Err(Error::Limit { .. })
        ));
    }

    /// Written in blocks of any size, every format gives the bytes of the whole write, and
    /// a binary format's stated length is its real one.
    #[test]
    fn blocks_of_any_size_write_the_same_file() {
        let mut m = walker(37, 5, 60.0, 3, 0.0);
        m.gap_where(|s| s[0] > 500.0);
        // The longest values as text: the extremes of f32, printed without an exponent.
        let mut v = m.positions().to_vec();
        v[..6].copy_from_slice(&[
            -f32::from_bits(1),
            f32::MAX,
            f32::MIN,
            -1.1754944e-38,
            1e-7,
            -3.4e38,
        ]);
        let m = Motion::new(m.fps, m.unit.clone(), m.point_names.clone(), v, None).unwrap();
        let w = m.point_count() * 3;
        for format in [
            Format::Json,
            Format::Csv,
            Format::Trc,
            Format::Npy,
            Format::F32,
        ] {
            let whole = write(&m, format).unwrap();
            for block in [1, 2, 5, 36, 37] {
                let mut wr = frame_writer(format, Shape::of(&m), Default::default()).unwrap();
                let mut out = Vec::new();
                wr.head(&mut out);
                for b in m.positions().chunks(block * w) {
                    let before = out.len();
                    wr.frames(b.len() / w, b, &mut out);
                    assert!(out.len() - before <= b.len() / w * wr.frame_bytes());
                }
                wr.tail(&mut out);
                assert_eq!(out, whole, "{format} in blocks of {block}");
                if let Some(n) = wr.exact_len() {
                    assert_eq!(n, out.len() as u64, "{format}");
                }
            }
        }
    }

    #[test]
    fn bvh_c3d_and_gltf_are_not_frame_writers() {
        let m = walker(3, 1, 60.0, 1, 0.0);
        for f in [Format::Bvh, Format::C3d, Format::Glb, Format::Gltf] {
            assert!(frame_writer(f, Shape::of(&m), Default::default()).is_err());
        }
    }

    /// A coordinate that is not a finite number is a missing sample, counted in a warning,
    /// in every point format a strict read takes (the C3D case is in `c3d`'s tests; JSON
    /// has no such numbers, and one past f32 is a parse error there).
    #[test]
    fn non_finite_coordinates_are_counted_gaps_in_trc_and_npy() {
        let trc =
            "PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n\
                   100\t100\t2\t2\tmm\nFrame#\tTime\tA\t\t\tB\t\t\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n\n\
                   1\t0.00\t1\t2\t3\tNaN\tNaN\tNaN\n2\t0.01\t7\t8\tinf\t4\t5\t6\n";
        let mut npy = write(&walker(2, 2, 60.0, 1, 0.0), Format::Npy).unwrap();
        let at = npy.len() - 4 * 3 * 2 * 2;
        npy[at..at + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
        for (bytes, gaps, counted) in [(trc.as_bytes(), 2, 2), (&npy[..], 1, 1)] {
            let l = read(bytes, &ReadOptions::default()).unwrap();
            assert_eq!(l.motion.gap_count(), gaps, "{}", l.format);
            let want = format!("{counted} samples have coordinates that are not finite");
            assert!(
                l.warnings.iter().any(|w| w.starts_with(&want)),
                "{}: {:?}",
                l.format,
                l.warnings
            );
        }
    }

    #[test]
    fn format_names_parse() {
        assert_eq!("NPY".parse::<Format>().unwrap(), Format::Npy);
        assert_eq!(Format::from_extension("out/x.trc"), Some(Format::Trc));
        assert!("xls".parse::<Format>().is_err());
    }
}
