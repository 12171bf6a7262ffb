//! BVH (Biovision Hierarchy): a joint tree with per-joint channel lists, then one row of
//! channel values per frame.
//!
//! Read: any rotation order per joint, 3 or 6 (or any subset of the six) channels on any
//! joint, End Sites as points, tabs/CRLF, scientific notation, names with spaces. A header
//! frame count that disagrees with the rows present is a warning, not an error: the rows are
//! the data. Write: the same hierarchy, and the channel values with the characters the file
//! printed them with when they were read from one ([`crate::motion::decimal`]), else in the
//! shortest form that parses back to the same f64.

use std::fmt::Write as _;

use super::text::{as_text, numbered_lines};
use super::{perr, unsettled_unit, Format, Parsed, ReadLimits};
use crate::motion::decimal::PrintedValues;
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;
use crate::motion::skeleton::{Animation, Channel, Joint};

const FMT: Format = Format::Bvh;

fn err(line: usize, reason: impl Into<String>) -> Error {
    perr(FMT, Location::Line(line), reason)
}

/// Header tokens with the line each came from.
struct Tokens<'a> {
    toks: Vec<(usize, &'a str)>,
    pos: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self) -> Result<(usize, &'a str)> {
        let t = self
            .toks
            .get(self.pos)
            .copied()
            .ok_or_else(|| err(self.last_line, "unexpected end of the hierarchy"))?;
        self.pos += 1;
        Ok(t)
    }

    fn expect(&mut self, want: &str) -> Result<usize> {
        let (line, t) = self.next()?;
        if t != want {
            return Err(err(line, format!("expected {want:?}, found {t:?}")));
        }
        Ok(line)
    }

    fn number(&mut self, what: &str) -> Result<f64> {
        let (line, t) = self.next()?;
        parse_f64(t).ok_or_else(|| err(line, format!("{what}: {t:?} is not a number")))
    }

    /// The rest of `line`'s tokens (a joint name may contain spaces), stopping at `{`.
    fn name_on(&mut self, line: usize) -> Result<String> {
        let mut parts = Vec::new();
        while let Some(&(l, t)) = self.toks.get(self.pos) {
            if l != line || t == "{" {
                break;
            }
            parts.push(t);
            self.pos += 1;
        }
        if parts.is_empty() {
            return Err(err(line, "joint without a name"));
        }
        Ok(parts.join(" "))
    }
}

fn parse_f64(t: &str) -> Option<f64> {
    t.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Parse a BVH file.
pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<Parsed> {
    let text = as_text(bytes);
    let mut lines = numbered_lines(&text);

    // Hierarchy: every token up to the MOTION line.
    let mut toks = Vec::new();
    let mut motion_line = None;
    let mut last_line = 1;
    for (n, line) in lines.by_ref() {
        last_line = n;
        let trimmed = line.trim();
        if trimmed.eq_ignore_ascii_case("MOTION") {
            motion_line = Some(n);
            break;
        }
        for t in trimmed.split_ascii_whitespace() {
            // A brace glued to a name ("Hips{") is still a brace.
            if t.len() > 1 && t.ends_with('{') {
                toks.push((n, &t[..t.len() - 1]));
                toks.push((n, "{"));
            } else {
                toks.push((n, t));
            }
        }
    }
    let mut tokens = Tokens {
        toks,
        pos: 0,
        last_line,
    };
    let joints = parse_hierarchy(&mut tokens, limits)?;
    let motion_line = motion_line.ok_or_else(|| err(last_line, "no MOTION section"))?;

    // Frames: N / Frame Time: t
    let mut header_frames = None;
    let mut frame_time = None;
    let mut line_no = motion_line;
    for (n, line) in lines.by_ref() {
        line_no = n;
        let l = line.trim();
        if l.is_empty() {
            continue;
        }
        let (key, value) = l.split_once(':').ok_or_else(|| {
            err(
                n,
                format!("expected \"Frames:\" or \"Frame Time:\", found {l:?}"),
            )
        })?;
        let key = key.split_ascii_whitespace().collect::<Vec<_>>().join(" ");
        let value = value.trim();
        if key.eq_ignore_ascii_case("Frames") {
            let v: usize = value
                .parse()
                .map_err(|_| err(n, format!("frame count {value:?} is not a whole number")))?;
            header_frames = Some(v);
        } else if key.eq_ignore_ascii_case("Frame Time") {
            let v = parse_f64(value)
                .filter(|v| *v > 0.0)
                .ok_or_else(|| err(n, format!("frame time {value:?} is not a positive number")))?;
            frame_time = Some(v);
        } else {
            return Err(err(n, format!("unexpected {key:?} in the MOTION header")));
        }
        if header_frames.is_some() && frame_time.is_some() {
            break;
        }
    }
    let header_frames = header_frames.ok_or_else(|| err(line_no, "missing \"Frames:\""))?;
    let frame_time = frame_time.ok_or_else(|| err(line_no, "missing \"Frame Time:\""))?;
    limits.check_shape(header_frames, joints.len())?;

    let cc: usize = joints.iter().map(|j| j.channels.len()).sum();
    // Trust the header for the reservation only as far as the input could back it up (every
    // value takes at least two bytes), so a forged frame count cannot make us allocate.
    let reserve = (header_frames * cc).min(bytes.len() / 2);
    let mut values: Vec<f64> = Vec::with_capacity(reserve);
    let mut printed = PrintedValues {
        values: Vec::with_capacity(reserve),
        verbatim: Vec::new(),
    };
    let mut rows = 0usize;
    for (n, line) in lines {
        let mut count = 0;
        for t in line.split_ascii_whitespace() {
            let v = parse_f64(t)
                .ok_or_else(|| err(n, format!("channel value {t:?} is not a number")))?;
            values.push(v);
            printed.push_token(t);
            count += 1;
        }
        if count == 0 {
            continue;
        }
        if count != cc {
            return Err(err(
                n,
                format!(
                    "frame {} has {count} values, the hierarchy has {cc} channels",
                    rows + 1
                ),
            ));
        }
        rows += 1;
        limits.check_shape(rows, joints.len())?;
    }
    let mut warnings = Vec::new();
    let mut contradictions = Vec::new();
    if rows < header_frames {
        // A file cut short: keeping what is there would archive part of a take as if whole.
        contradictions.push(format!(
            "header says {header_frames} frames but only {rows} rows are present (the file is cut short)"
        ));
    } else if rows > header_frames {
        // Nothing is lost; some exporters count one frame short.
        warnings.push(format!(
            "header says {header_frames} frames but {rows} rows are present; loaded the {rows} rows"
        ));
    }
    if cc == 0 && rows == 0 && header_frames > 0 {
        return Err(err(
            line_no,
            "frames declared but the hierarchy has no channels",
        ));
    }

    let names = joints.iter().map(|j| j.name.clone()).collect();
    let skeleton = Animation::new(joints, values)?.with_printed(printed)?;
    let positions: Vec<f32> = skeleton
        .forward_kinematics()
        .into_iter()
        .map(|v| v as f32)
        .collect();
    // BVH has no gaps: a position that is not finite came from values beyond any scale.
    let bad = positions.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        contradictions.push(format!(
            "{bad} joint coordinates are not finite (channel values beyond any physical scale)"
        ));
    }
    let motion = Motion::new(
        1.0 / frame_time,
        unsettled_unit(),
        names,
        positions,
        Some(skeleton),
    )?;
    Ok(Parsed {
        motion,
        declared_unit: None,
        warnings,
        contradictions,
        extras: Default::default(),
    })
}

fn parse_hierarchy(t: &mut Tokens<'_>, limits: &ReadLimits) -> Result<Vec<Joint>> {
    let (line, first) = t.next()?;
    if !first.eq_ignore_ascii_case("HIERARCHY") {
        return Err(err(line, format!("expected HIERARCHY, found {first:?}")));
    }
    let (line, root) = t.next()?;
    if root != "ROOT" {
        return Err(err(line, format!("expected ROOT, found {root:?}")));
    }
    let mut joints = Vec::new();
    parse_joints(t, line, &mut joints, limits)?;
    if let Some(&(line, extra)) = t.toks.get(t.pos) {
        return Err(err(
            line,
            format!("{extra:?} after the root joint (only one ROOT is supported)"),
        ));
    }
    Ok(joints)
}

/// A joint block being read: its index and where it opened.
struct Open {
    index: usize,
    line: usize,
    seen_offset: bool,
}

/// Parse the root joint (its keyword already consumed) and everything nested in it.
///
/// The nesting is walked with an explicit stack, never by recursion: a hostile file nests
/// as deep as it likes, and the thread's stack is not the place to find out how deep.
fn parse_joints(
    t: &mut Tokens<'_>,
    root_line: usize,
    joints: &mut Vec<Joint>,
    limits: &ReadLimits,
) -> Result<()> {
    let mut open = vec![open_joint(t, root_line, None, false, joints, limits)?];
    while let Some(top) = open.last_mut() {
        let index = top.index;
        let end_site = joints[index].end_site;
        let (l, kw) = t.next()?;
        match kw {
            "}" => {
                if !top.seen_offset {
                    return Err(err(
                        top.line,
                        format!("joint {:?} has no OFFSET", joints[index].name),
                    ));
                }
                open.pop();
            }
            "OFFSET" => {
                let mut o = [0.0; 3];
                for v in &mut o {
                    *v = t.number("OFFSET")?;
                }
                joints[index].offset = o;
                top.seen_offset = true;
            }
            "CHANNELS" if !end_site => {
                let (cl, n) = t.next()?;
                let n: usize = n
                    .parse()
                    .ok()
                    .filter(|n| *n <= 6)
                    .ok_or_else(|| err(cl, format!("channel count {n:?} is not 0..=6")))?;
                let mut chans = Vec::with_capacity(n);
                for _ in 0..n {
                    let (cl, c) = t.next()?;
                    let ch = Channel::parse(c)
                        .ok_or_else(|| err(cl, format!("unknown channel {c:?}")))?;
                    if chans.contains(&ch) {
                        return Err(err(cl, format!("channel {c} listed twice")));
                    }
                    chans.push(ch);
                }
                joints[index].channels = chans;
            }
            "JOINT" | "End" if !end_site => {
                if open.len() as u64 >= limits.max_depth {
                    return Err(Error::Limit {
                        what: "hierarchy depth",
                        actual: open.len() as u64 + 1,
                        limit: limits.max_depth,
                    });
                }
                let child = open_joint(t, l, Some(index), kw == "End", joints, limits)?;
                open.push(child);
            }
            other => return Err(err(l, format!("unexpected {other:?} in joint block"))),
        }
    }
    Ok(())
}

/// Read a joint's name (or `End Site`) and its opening brace, and add it.
fn open_joint(
    t: &mut Tokens<'_>,
    line: usize,
    parent: Option<usize>,
    end_site: bool,
    joints: &mut Vec<Joint>,
    limits: &ReadLimits,
) -> Result<Open> {
    if joints.len() as u64 >= limits.max_points {
        return Err(Error::Limit {
            what: "joint count",
            actual: joints.len() as u64 + 1,
            limit: limits.max_points,
        });
    }
    let name = if end_site {
        // "End Site" — the word "Site" follows on the same line.
        let (l, site) = t.next()?;
        if !site.eq_ignore_ascii_case("Site") {
            return Err(err(
                l,
                format!("expected \"End Site\", found \"End {site}\""),
            ));
        }
        let parent_name = parent.map_or("root", |p| joints[p].name.as_str());
        unique_name(joints, &format!("{parent_name}_End"))
    } else {
        t.name_on(line)?
    };
    t.expect("{")?;
    joints.push(Joint {
        name,
        parent,
        offset: [0.0; 3],
        channels: Vec::new(),
        end_site,
    });
    Ok(Open {
        index: joints.len() - 1,
        line,
        seen_offset: false,
    })
}

fn unique_name(joints: &[Joint], base: &str) -> String {
    let mut name = base.to_string();
    let mut k = 2;
    while joints.iter().any(|j| j.name == name) {
        name = format!("{base}{k}");
        k += 1;
    }
    name
}

/// Write a take that has a skeleton as BVH.
pub fn write(motion: &Motion) -> Result<Vec<u8>> {
    let s = motion.skeleton.as_ref().ok_or_else(|| {
        Error::Unsupported("BVH output needs a skeleton; this take is point data only".into())
    })?;
    Ok(write_skeleton(s, motion.fps))
}

/// Write a skeleton and its channel values at `fps` as BVH.
pub fn write_skeleton(s: &Animation, fps: f64) -> Vec<u8> {
    let w = ChannelWriter::new(s.joints.clone(), fps, s.frame_count());
    let mut out = Vec::with_capacity(64 * s.joints.len() + 12 * s.values.len());
    w.head(&mut out);
    w.frames(&s.values, s.printed.as_ref(), 0..s.frame_count(), &mut out);
    out
}

/// The most characters one channel value takes as written: as printed in the file, 18
/// digits after up to 400 zeros (the exponents a lossless bitstream keeps) with a sign and a
/// point; an f64 in `Display` form, 328 at most (the smallest subnormal); a verbatim token,
/// at most 256 (what `bvh-lossless` keeps).
pub const MAX_VALUE_CHARS: usize = 422;

/// BVH block by block: the hierarchy and the `MOTION` header (which states the frame
/// count), then a line of channel values per frame.
pub struct ChannelWriter {
    joints: Vec<Joint>,
    channels: usize,
    fps: f64,
    frames: usize,
}

impl ChannelWriter {
    /// A writer of `frames` frames of the skeleton `joints` at `fps`.
    pub fn new(joints: Vec<Joint>, fps: f64, frames: usize) -> ChannelWriter {
        let channels = joints.iter().map(|j| j.channels.len()).sum();
        ChannelWriter {
            joints,
            channels,
            fps,
            frames,
        }
    }

    /// Channel values a frame has.
    pub fn channels(&self) -> usize {
        self.channels
    }

    pub fn head(&self, out: &mut Vec<u8>) {
        let mut text = String::from("HIERARCHY\n");
        if !self.joints.is_empty() {
            write_hierarchy(&self.joints, &mut text);
        }
        let _ = write!(text, "MOTION\nFrames: {}\nFrame Time: ", self.frames);
        text.push_str(&format_frame_time(1.0 / self.fps));
        text.push('\n');
        out.extend_from_slice(text.as_bytes());
    }

    /// Frames `frames` of whole frames of channel values, printed as `printed` holds them
    /// when given (values as a lossless archive keeps them), else in the shortest form that
    /// reads back.
    pub fn frames(
        &self,
        values: &[f64],
        printed: Option<&PrintedValues>,
        frames: std::ops::Range<usize>,
        out: &mut Vec<u8>,
    ) {
        let cc = self.channels;
        let mut text = String::with_capacity(frames.len() * cc * 12);
        for f in frames {
            for (k, v) in values[f * cc..(f + 1) * cc].iter().enumerate() {
                if k > 0 {
                    text.push(' ');
                }
                match printed {
                    Some(p) => p.write(f * cc + k, &mut text),
                    None => {
                        let _ = write!(text, "{v}");
                    }
                }
            }
            text.push('\n');
        }
        out.extend_from_slice(text.as_bytes());
    }

    /// The most bytes one frame takes: [`MAX_VALUE_CHARS`] and a separator per channel,
    /// and the line's end.
    pub fn frame_bytes(&self) -> usize {
        self.channels * (MAX_VALUE_CHARS + 1) + 1
    }
}

fn format_frame_time(t: f64) -> String {
    // 1/fps rarely prints back exactly; 10 decimals keep fps exact to ~1e-6 at 1000 fps.
    let s = format!("{t:.10}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Print the hierarchy: each joint's block opens before its children's and closes after
/// them. Walked with an explicit stack (no recursion on depth), children found once.
fn write_hierarchy(joints: &[Joint], out: &mut String) {
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); joints.len()];
    for (k, j) in joints.iter().enumerate() {
        if let Some(p) = j.parent {
            children[p].push(k);
        }
    }
    // (joint, depth, opened): a joint is pushed unopened, opened (header printed, then
    // its children pushed after it), and closed when it comes back to the top.
    let mut stack = vec![(0usize, 0usize, false)];
    while let Some((i, depth, opened)) = stack.pop() {
        let ind = "\t".repeat(depth);
        if opened {
            let _ = writeln!(out, "{ind}}}");
            continue;
        }
        let j = &joints[i];
        if j.end_site {
            let _ = writeln!(out, "{ind}End Site");
        } else if j.parent.is_none() {
            let _ = writeln!(out, "{ind}ROOT {}", j.name);
        } else {
            let _ = writeln!(out, "{ind}JOINT {}", j.name);
        }
        let _ = writeln!(out, "{ind}{{");
        let [x, y, z] = j.offset;
        let _ = writeln!(out, "{ind}\tOFFSET {x} {y} {z}");
        if !j.end_site {
            let _ = write!(out, "{ind}\tCHANNELS {}", j.channels.len());
            for c in &j.channels {
                let _ = write!(out, " {}", c.name());
            }
            out.push('\n');
        }
        stack.push((i, depth, true));
        stack.extend(children[i].iter().rev().map(|&k| (k, depth + 1, false)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOY: &str = "HIERARCHY\r\nROOT Hips\r\n{\r\n\tOFFSET 0 0 0\r\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\r\n\tJOINT Left Leg\r\n\t{\r\n\t\tOFFSET 1.5e0 -2 0\r\n\t\tCHANNELS 3 Xrotation Yrotation Zrotation\r\n\t\tEnd Site\r\n\t\t{\r\n\t\t\tOFFSET 0 -3 0\r\n\t\t}\r\n\t}\r\n}\r\nMOTION\r\nFrames:\t2\r\nFrame Time:\t0.0333333\r\n0 10 0 0 0 0 0 0 0\r\n1 10 0 90 0 0 0 0 90\r\n";

    #[test]
    fn reads_joints_end_sites_and_positions() {
        let p = read(TOY.as_bytes(), &ReadLimits::default()).unwrap();
        let m = p.motion;
        assert_eq!(m.point_names, vec!["Hips", "Left Leg", "Left Leg_End"]);
        assert_eq!(m.frame_count(), 2);
        assert!((m.fps - 30.0).abs() < 1e-3);
        assert!(p.warnings.is_empty());
        // Frame 0: root at (0,10,0), leg at (1.5,8,0), foot at (1.5,5,0).
        assert_eq!(m.frame(0), &[0.0, 10.0, 0.0, 1.5, 8.0, 0.0, 1.5, 5.0, 0.0]);
        // Frame 1: root Z 90° maps the leg offset (1.5,-2,0) to (2,1.5,0); the leg's own
        // Z 90° composed with the root's makes 180°: (0,-3,0) → (0,3,0).
        let f1 = m.frame(1);
        let want = [1.0, 10.0, 0.0, 3.0, 11.5, 0.0, 3.0, 14.5, 0.0];
        for (a, b) in f1.iter().zip(want) {
            assert!((a - b).abs() < 1e-5, "{f1:?}");
        }
    }

    #[test]
    fn round_trips_channel_values_exactly() {
        let m = read(TOY.as_bytes(), &ReadLimits::default()).unwrap().motion;
        let text = write(&m).unwrap();
        let again = read(&text, &ReadLimits::default()).unwrap().motion;
        assert_eq!(again.skeleton, m.skeleton);
        assert_eq!(again.point_names, m.point_names);
        assert!((again.fps - m.fps).abs() < 1e-6);
    }

    #[test]
    fn a_frame_of_the_longest_values_fits_the_writers_bound() {
        let p = read(TOY.as_bytes(), &ReadLimits::default()).unwrap();
        let joints = p.motion.skeleton.unwrap().joints;
        let w = ChannelWriter::new(joints, 30.0, 1);
        let values = [
            -5e-324,
            f64::MAX,
            f64::MIN,
            -2.2250738585072014e-308,
            1e-7,
            0.0,
            1.0,
            2.0,
            3.0,
        ];
        let mut out = Vec::new();
        w.frames(&values, None, 0..1, &mut out);
        assert!(
            out.len() <= w.frame_bytes(),
            "{} > {}",
            out.len(),
            w.frame_bytes()
        );
        // As printed: a verbatim token as long as a lossless bitstream keeps, and the most
        // zeros one keeps before 18 digits.
        let mut printed = PrintedValues::default();
        printed.push_token(&"9".repeat(256));
        printed.push_token(&format!("-0.{}123456789012345678", "0".repeat(399)));
        for _ in 0..7 {
            printed.push_token("1.5");
        }
        let mut out = Vec::new();
        w.frames(&values, Some(&printed), 0..1, &mut out);
        assert!(
            out.len() <= w.frame_bytes(),
            "{} > {}",
            out.len(),
            w.frame_bytes()
        );
    }

    #[test]
    fn more_rows_than_declared_is_a_warning_fewer_a_contradiction() {
        let more = TOY.replace("Frames:\t2", "Frames:\t1");
        let p = read(more.as_bytes(), &ReadLimits::default()).unwrap();
        assert_eq!(p.motion.frame_count(), 2);
        assert_eq!(p.warnings.len(), 1);
        assert!(p.contradictions.is_empty());
        let fewer = TOY.replace("Frames:\t2", "Frames:\t3");
        let p = read(fewer.as_bytes(), &ReadLimits::default()).unwrap();
        assert_eq!(p.contradictions.len(), 1, "{:?}", p.contradictions);
    }

    #[test]
    fn values_beyond_any_scale_are_a_contradiction() {
        let huge = TOY.replace("1 10 0 90 0 0 0 0 90", "1e308 10 0 90 0 0 0 0 90");
        let p = read(huge.as_bytes(), &ReadLimits::default()).unwrap();
        assert_eq!(p.contradictions.len(), 1, "{:?}", p.contradictions);
    }

    #[test]
    fn errors_name_the_line() {
        let bad = TOY.replace("1 10 0 90 0 0 0 0 90", "1 10 0 90 0 0 0 0");
        match read(bad.as_bytes(), &ReadLimits::default()) {
            Err(Error::Parse { at, .. }) => assert_eq!(at, Location::Line(20)),
            other => panic!("{other:?}"),
        }
        let bad = TOY.replace(
            "Xrotation Yrotation Zrotation",
            "Xrotation Wrotation Zrotation",
        );
        assert!(matches!(
            read(bad.as_bytes(), &ReadLimits::default()),
            Err(Error::Parse {
                at: Location::Line(9),
                ..
            })
        ));
        let bad = TOY.replace("0.0333333", "0");
        assert!(read(bad.as_bytes(), &ReadLimits::default()).is_err());
        assert!(read(b"HIERARCHY\nROOT", &ReadLimits::default()).is_err());
        assert!(read(
            b"HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n}\n",
            &ReadLimits::default()
        )
        .is_err());
    }

    #[test]
    fn deep_hierarchies_are_refused_by_the_limit_not_the_stack() {
        // 6,000 levels overflowed the stack of the recursive parser (an abort, not an error).
        use crate::motion::synthetic::chain_bvh;
        let deep = chain_bvh(6_000);
        assert!(matches!(
            read(deep.as_bytes(), &ReadLimits::default()),
            Err(Error::Limit {
                what: "hierarchy depth",
                ..
            })
        ));
        // Past the default depth limit, with the limit raised: parsed without recursion.
        let limits = ReadLimits {
            max_depth: 100_000,
            ..ReadLimits::default()
        };
        let m = read(deep.as_bytes(), &limits).unwrap().motion;
        assert_eq!(m.point_count(), 6_000);
        // The writer walks it without recursion too, and it parses back the same.
        let text = write(&m).unwrap();
        let again = read(&text, &limits).unwrap().motion;
        assert_eq!(again.skeleton, m.skeleton);
        // Within the default limit it simply loads.
        assert!(read(chain_bvh(400).as_bytes(), &ReadLimits::default()).is_ok());
    }

    #[test]
    fn every_prefix_fails_cleanly_or_loads() {
        for cut in 0..TOY.len() {
            let _ = read(&TOY.as_bytes()[..cut], &ReadLimits::default());
        }
    }
}
