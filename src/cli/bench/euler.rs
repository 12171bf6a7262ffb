//! `mocapstore bench --euler`: how the skeleton codecs give Euler channels back, file by
//! file (issue 49): frame-to-frame jumps over 90° in the source and in the decoded
//! channels, and the largest difference between a decoded rotation channel and the
//! source's. Equivalent rotations can differ by 180° or 360° in their angles while every
//! position stays within the bound; an animator's curve editor shows each as a flip.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use mocapstore::codec::{self, branches, CodecId, ErrorBound, Reader, Shared, Stored};
use mocapstore::motion::formats::{self, Format};

/// A jump between frames larger than this is a flip on a curve (degrees).
const JUMP: f64 = 90.0;

const CODECS: [CodecId; 2] = [CodecId::Rot, CodecId::Pga];

struct Row {
    file: String,
    codec: CodecId,
    source_jumps: usize,
    decoded_jumps: usize,
    /// Largest |decoded − source| of a rotation channel, degrees.
    largest: f64,
    /// Channel values more than [`JUMP`] from the source's.
    flipped: usize,
}

/// Frame-to-frame jumps over [`JUMP`] of the rotation channels `rot` in `values`.
fn jumps(values: &[f64], channels: usize, rot: &[usize]) -> usize {
    values
        .chunks_exact(channels)
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| {
            rot.iter()
                .filter(|&&c| (w[1][c] - w[0][c]).abs() > JUMP)
                .count()
        })
        .sum()
}

/// A decoded jump over [`JUMP`] where the source's is not: (frame, channel, the source's
/// triple at the frame before and at the frame, the decoded triple at both).
type Extra = (usize, usize, [[f64; 3]; 2], [[f64; 3]; 2]);

/// Every [`Extra`] jump of `decoded` against `source` (`frames × channels` each), on the
/// Euler triples of `turnings`.
fn extra_jumps(
    source: &[f64],
    decoded: &[f64],
    channels: usize,
    turnings: &[branches::Turning],
) -> Vec<Extra> {
    let mut out = Vec::new();
    let frames = source.len() / channels.max(1);
    let triple = |v: &[f64], f: usize, t: &branches::Turning| t.idx.map(|i| v[f * channels + i]);
    for f in 1..frames {
        for t in turnings {
            for c in t.idx {
                let step = |v: &[f64]| (v[f * channels + c] - v[(f - 1) * channels + c]).abs();
                if step(decoded) > JUMP && step(source) <= JUMP {
                    out.push((
                        f,
                        c,
                        [triple(source, f - 1, t), triple(source, f, t)],
                        [triple(decoded, f - 1, t), triple(decoded, f, t)],
                    ));
                }
            }
        }
    }
    out
}

pub fn run(files: &[PathBuf], bound_mm: f64, out: &Path) -> ExitCode {
    let mut rows = Vec::new();
    // Where a decoded curve jumps over 90° and the source's does not.
    let mut extra = Vec::new();
    for path in files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
    {
        let Ok(loaded) = std::fs::read(path)
            .map_err(|e| e.to_string())
            .and_then(|b| {
                formats::read_as(Format::Bvh, &b, &Default::default()).map_err(|e| e.to_string())
            })
        else {
            eprintln!("{}: not readable, left out", path.display());
            continue;
        };
        let m = loaded.motion;
        let Some(s) = m.skeleton.as_ref() else {
            continue;
        };
        let channels: Vec<_> = s
            .joints
            .iter()
            .flat_map(|j| j.channels.iter().copied())
            .collect();
        let rot: Vec<usize> = (0..channels.len())
            .filter(|&c| channels[c].rotation_axis().is_some())
            .collect();
        let rig = match codec::Skeleton::new(s.joints.clone()) {
            Ok(r) => Arc::new(r),
            Err(e) => {
                eprintln!("{}: {e}", path.display());
                continue;
            }
        };
        let turnings = branches::turnings(&rig);
        for codec in CODECS {
            let enc = match codec::encode(&m, codec, ErrorBound::max(bound_mm), Default::default())
            {
                Ok(e) => e,
                Err(e) => {
                    eprintln!("{} {codec}: {e}", path.display());
                    continue;
                }
            };
            let shared = Shared {
                basis: None,
                rig: Some(rig.clone()),
            };
            let decoded = Reader::new(enc.container.header.clone(), shared).and_then(|r| {
                let source = Stored::new(0, enc.container.chunks.iter().map(Vec::as_slice));
                r.read_channels(0..m.frame_count(), channels.len(), &source)
            });
            let decoded = match decoded {
                Ok(d) => d.values,
                Err(e) => {
                    eprintln!("{} {codec}: does not decode: {e}", path.display());
                    return ExitCode::FAILURE;
                }
            };
            extra.extend(extra_jumps(&s.values, &decoded, channels.len(), &turnings).into_iter().map(
                |(f, c, src, dec)| {
                    format!(
                        "- {} {codec} frame {f} channel {c}: the source {:.2?} → {:.2?}, decoded {:.2?} → {:.2?}",
                        super::short_name(path),
                        src[0], src[1], dec[0], dec[1]
                    )
                },
            ));
            let (mut largest, mut flipped) = (0.0f64, 0);
            for (d, v) in decoded
                .chunks_exact(channels.len())
                .zip(s.values.chunks_exact(channels.len()))
            {
                for &c in &rot {
                    let diff = (d[c] - v[c]).abs();
                    largest = largest.max(diff);
                    flipped += usize::from(diff > JUMP);
                }
            }
            rows.push(Row {
                file: super::short_name(path),
                codec,
                source_jumps: jumps(&s.values, channels.len(), &rot),
                decoded_jumps: jumps(&decoded, channels.len(), &rot),
                largest,
                flipped,
            });
        }
    }
    if rows.is_empty() {
        eprintln!("mocapstore bench --euler: no readable BVH files");
        return ExitCode::FAILURE;
    }
    let mut table = String::from(
        "| file | codec | jumps > 90° in the source | decoded | largest channel difference ° | values > 90° off |\n|---|---|---:|---:|---:|---:|\n",
    );
    for r in &rows {
        table += &format!(
            "| {} | {} | {} | {} | {:.2} | {} |\n",
            r.file, r.codec, r.source_jumps, r.decoded_jumps, r.largest, r.flipped
        );
    }
    for codec in CODECS {
        let of: Vec<&Row> = rows.iter().filter(|r| r.codec == codec).collect();
        let more = of
            .iter()
            .filter(|r| r.decoded_jumps > r.source_jumps)
            .count();
        let largest = of.iter().map(|r| r.largest).fold(0.0, f64::max);
        table += &format!(
            "| **{} files** | {codec} | {} | {} | {largest:.2} | {} |\n",
            of.len(),
            of.iter().map(|r| r.source_jumps).sum::<usize>(),
            of.iter().map(|r| r.decoded_jumps).sum::<usize>(),
            of.iter().map(|r| r.flipped).sum::<usize>(),
        );
        println!("{codec}: {more} of {} files decode with more jumps over 90° than their source; largest channel difference {largest:.2}°", of.len());
    }
    if !extra.is_empty() {
        table += "\nJumps over 90° that the source does not make (first, middle, last angle):\n\n";
        for e in &extra {
            table += e;
            table.push('\n');
        }
    }
    print!("{table}");
    if let Err(e) =
        std::fs::create_dir_all(out).and_then(|_| std::fs::write(out.join("euler.md"), &table))
    {
        eprintln!("mocapstore bench --euler: {}: {e}", out.display());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    /// Jumps are counted on rotation channels only, between neighbouring frames.
    #[test]
    fn jumps_over_ninety_degrees_are_counted_per_rotation_channel() {
        // Two channels (a position, a rotation), four frames.
        let v = [0.0, 10.0, 500.0, 170.0, 0.0, -170.0, 0.0, -160.0];
        assert_eq!(super::jumps(&v, 2, &[1]), 2);
        assert_eq!(super::jumps(&v, 2, &[]), 0);
    }

    /// A decoded jump is listed only where the source's step is not over 90° too.
    #[test]
    fn jumps_the_source_does_not_make_are_listed() {
        use mocapstore::codec::branches::Turning;
        let t = Turning {
            idx: [0, 1, 2],
            order: [2, 0, 1],
        };
        // Frame 1: both jump (source 100°); frame 2: only the decoded curve (89° → 91°).
        let source = [0.0, 0.0, 0.0, 100.0, 0.0, 0.0, 11.0, 0.0, 0.0];
        let decoded = [0.0, 0.0, 0.0, 100.0, 0.0, 0.0, 9.0, 0.0, 0.0];
        let extra = super::extra_jumps(&source, &decoded, 3, &[t]);
        assert_eq!(extra.len(), 1);
        assert_eq!((extra[0].0, extra[0].1), (2, 0));
    }
}
