//! Small generated motions for tests and benchmarks: smooth, deterministic, human-sized.

use super::model::Motion;
use super::units::Unit;
pub use crate::rng::Rng;

/// `points` markers in mm on a figure walking forward: a shared root drift, limb-like
/// oscillations at gait frequencies, a little per-marker jitter, and optionally gaps (runs
/// of missing samples) on a fraction of markers.
pub fn walker(frames: usize, points: usize, fps: f64, seed: u64, gap_fraction: f64) -> Motion {
    let mut rng = Rng::new(seed);
    let speed = 800.0 + 800.0 * rng.unit(); // mm/s
    let params: Vec<[f64; 6]> = (0..points)
        .map(|_| {
            [
                rng.unit() * 600.0 - 300.0, // x offset
                rng.unit() * 1700.0,        // height
                rng.unit() * 300.0 - 150.0, // z offset
                20.0 + rng.unit() * 250.0,  // swing amplitude
                rng.unit() * std::f64::consts::TAU,
                0.8 + rng.unit() * 1.4, // gait frequency (Hz)
            ]
        })
        .collect();
    let mut data = Vec::with_capacity(frames * points * 3);
    for f in 0..frames {
        let t = f as f64 / fps;
        for p in &params {
            let phase = std::f64::consts::TAU * p[5] * t + p[4];
            data.push((p[0] + speed * t + p[3] * phase.sin()) as f32);
            data.push((p[1] + 0.2 * p[3] * (2.0 * phase).cos() + 2.0 * rng.unit()) as f32);
            data.push((p[2] + 0.3 * p[3] * phase.cos()) as f32);
        }
    }
    if gap_fraction > 0.0 && frames > 2 {
        for p in 0..points {
            if rng.unit() >= gap_fraction {
                continue;
            }
            let start = rng.below(frames);
            let len = 1 + rng.below(frames / 4 + 1);
            for f in start..(start + len).min(frames) {
                data[(f * points + p) * 3..(f * points + p) * 3 + 3].fill(f32::NAN);
            }
        }
    }
    let names = (0..points).map(|i| format!("M{i}")).collect();
    Motion::new(fps, Unit::millimetres(), names, data, None).expect("consistent shape")
}

/// A BVH file whose hierarchy is a chain `depth` joints deep, with one frame: what a parser
/// that recursed on depth could not survive (tests, and `scripts/hostile`'s case).
pub fn chain_bvh(depth: usize) -> String {
    let mut s = String::from(
        "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n",
    );
    for i in 1..depth {
        s.push_str(&format!(
            "JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\n"
        ));
    }
    s.push_str(&"}\n".repeat(depth));
    s.push_str("MOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0");
    s.push_str(&" 1".repeat(depth.saturating_sub(1)));
    s.push('\n');
    s
}

/// A BVH take of a humanoid (19 joints, 5 End Sites, centimetres) dancing in place for
/// `frames` frames: root translation and Z-X-Y rotations as CMU prints them, every joint
/// rotating smoothly in all three axes with a little jitter, values printed with `decimals`
/// decimals. For tests and benchmarks of the codecs that keep channels.
pub fn dancer_bvh(frames: usize, fps: f64, seed: u64, decimals: usize) -> String {
    // (name, parent, offset); parents first. End Sites are named "End".
    const BONES: [(&str, usize, [f64; 3]); 24] = [
        ("Hips", usize::MAX, [0.0, 0.0, 0.0]),
        ("LeftUpLeg", 0, [9.0, -4.0, 0.0]),
        ("LeftLeg", 1, [0.0, -42.0, 0.0]),
        ("LeftFoot", 2, [0.0, -40.0, 0.0]),
        ("End", 3, [0.0, -4.0, 14.0]),
        ("RightUpLeg", 0, [-9.0, -4.0, 0.0]),
        ("RightLeg", 5, [0.0, -42.0, 0.0]),
        ("RightFoot", 6, [0.0, -40.0, 0.0]),
        ("End", 7, [0.0, -4.0, 14.0]),
        ("Spine", 0, [0.0, 10.0, 0.0]),
        ("Chest", 9, [0.0, 18.0, 0.0]),
        ("Neck", 10, [0.0, 20.0, 0.0]),
        ("Head", 11, [0.0, 9.0, 0.0]),
        ("End", 12, [0.0, 18.0, 0.0]),
        ("LeftShoulder", 10, [4.0, 16.0, 0.0]),
        ("LeftArm", 14, [14.0, 0.0, 0.0]),
        ("LeftForeArm", 15, [28.0, 0.0, 0.0]),
        ("LeftHand", 16, [25.0, 0.0, 0.0]),
        ("End", 17, [12.0, 0.0, 0.0]),
        ("RightShoulder", 10, [-4.0, 16.0, 0.0]),
        ("RightArm", 19, [-14.0, 0.0, 0.0]),
        ("RightForeArm", 20, [-28.0, 0.0, 0.0]),
        ("RightHand", 21, [-25.0, 0.0, 0.0]),
        ("End", 22, [-12.0, 0.0, 0.0]),
    ];
    let mut children = vec![Vec::new(); BONES.len()];
    for (i, b) in BONES.iter().enumerate().skip(1) {
        children[b.1].push(i);
    }
    let mut s = String::from("HIERARCHY\n");
    // (bone, depth, closing)
    let mut stack = vec![(0usize, 0usize, false)];
    let mut order = Vec::new();
    while let Some((i, d, closing)) = stack.pop() {
        let ind = "  ".repeat(d);
        if closing {
            s.push_str(&format!("{ind}}}\n"));
            continue;
        }
        let (name, parent, o) = BONES[i];
        let head = match (parent, name) {
            (usize::MAX, _) => format!("ROOT {name}"),
            (_, "End") => "End Site".to_string(),
            _ => format!("JOINT {name}"),
        };
        s.push_str(&format!(
            "{ind}{head}\n{ind}{{\n{ind}  OFFSET {:.5} {:.5} {:.5}\n",
            o[0], o[1], o[2]
        ));
        if parent == usize::MAX {
            s.push_str(&format!(
                "{ind}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
            ));
            order.push(6);
        } else if name != "End" {
            s.push_str(&format!(
                "{ind}  CHANNELS 3 Zrotation Xrotation Yrotation\n"
            ));
            order.push(3);
        }
        stack.push((i, d, true));
        stack.extend(children[i].iter().rev().map(|&k| (k, d + 1, false)));
    }
    let channels: usize = order.iter().sum();
    s.push_str(&format!(
        "MOTION\nFrames: {frames}\nFrame Time: {:.6}\n",
        1.0 / fps
    ));
    let mut rng = Rng::new(seed);
    let waves: Vec<[f64; 3]> = (0..channels)
        .map(|_| {
            [
                5.0 + 40.0 * rng.unit(),
                0.3 + 1.5 * rng.unit(),
                std::f64::consts::TAU * rng.unit(),
            ]
        })
        .collect();
    for f in 0..frames {
        let t = f as f64 / fps;
        for (c, w) in waves.iter().enumerate() {
            let mut v = w[0] * (std::f64::consts::TAU * w[1] * t + w[2]).sin() + 0.05 * rng.unit();
            match c {
                0 => v += 60.0 * t,
                1 => v = 90.0 + v * 0.1,
                _ => {}
            }
            if c > 0 {
                s.push(' ');
            }
            s.push_str(&format!("{v:.decimals$}"));
        }
        s.push('\n');
    }
    s
}

/// [`dancer_bvh`] (4 decimals) read as a take, as ingest reads it.
pub fn dancer(frames: usize, fps: f64, seed: u64) -> Motion {
    let text = dancer_bvh(frames, fps, seed, 4);
    super::formats::read_as(
        super::format::Format::Bvh,
        text.as_bytes(),
        &Default::default(),
    )
    .expect("a generated BVH reads")
    .motion
}

/// The [`dancer`] with two joints held near gimbal lock, LeftLeg at +90° and RightFoot
/// at −90° on their middle (X) angle, 0.05° to 0.25° off, while their first and last angles
/// swing; the positions are the new channels' FK. Where a rotation within any bound leaves
/// Euler angles ill-conditioned (the codecs' twists, issue 49).
pub fn dancer_near_lock(frames: usize, fps: f64, seed: u64) -> Motion {
    let m = dancer(frames, fps, seed);
    let mut sk = m.skeleton.clone().expect("a dancer has a skeleton");
    // The values change: what the generated text printed no longer holds.
    sk.printed = None;
    let cc: usize = sk.joints.iter().map(|j| j.channels.len()).sum();
    let first = |name: &str| {
        let j = sk.joints.iter().position(|j| j.name == name).expect(name);
        sk.joints[..j]
            .iter()
            .map(|j| j.channels.len())
            .sum::<usize>()
    };
    // Both joints' channels are Zrotation Xrotation Yrotation.
    let held = [first("LeftLeg"), first("RightFoot")];
    for (f, row) in sk.values.chunks_exact_mut(cc).enumerate() {
        let x = f as f64 / fps;
        for (n, &c) in held.iter().enumerate() {
            let sign = if n == 0 { 1.0 } else { -1.0 };
            row[c] = 60.0 * (1.3 * x + n as f64).sin();
            row[c + 1] = sign * (89.85 + 0.1 * (3.0 * x).sin());
            row[c + 2] = -50.0 * (0.9 * x).cos();
        }
    }
    let mut fk = super::skeleton::Fk::new(&sk.joints);
    let mut frame = vec![0f64; sk.joints.len() * 3];
    let mut positions = Vec::with_capacity(m.positions().len());
    for row in sk.values.chunks_exact(cc) {
        fk.frame(&sk.joints, row, &mut frame);
        positions.extend(frame.iter().map(|&v| v as f32));
    }
    Motion::new(m.fps, m.unit, m.point_names.clone(), positions, Some(sk))
        .expect("the dancer's own shape")
}

/// Two behaviours: a dancer's first second, played over and over for 800 frames, with
/// its forearms and hands also swinging fast and wide from frame 400 on (positions only; the
/// skeleton is dropped). PPCA segmentation cuts it near frame 400.
pub fn two_behaviours() -> Motion {
    let m = dancer(120, 120.0, 3);
    let n = m.point_count();
    let arm: Vec<usize> = (0..n)
        .filter(|&p| {
            let k = m.point_names[p].to_ascii_lowercase();
            ["leftforearm", "lefthand", "rightforearm", "righthand"]
                .iter()
                .any(|a| k.starts_with(a))
        })
        .collect();
    assert!(!arm.is_empty());
    let w = n * 3;
    let mut x = Vec::with_capacity(800 * w);
    for f in 0..800 {
        let g = f % 120;
        x.extend_from_slice(&m.positions()[g * w..(g + 1) * w]);
        if f >= 400 {
            let t = (f - 400) as f32;
            for &p in &arm {
                x[f * w + p * 3] += (t * 0.13).sin() * 60.0;
                x[f * w + p * 3 + 2] += (t * 0.21).cos() * 80.0;
            }
        }
    }
    Motion::new(m.fps, m.unit, m.point_names.clone(), x, None).unwrap()
}

/// Analog channels as a lab records them, `frames × per_frame` rows: a force plate's six
/// channels (a vertical force of steps on ADC noise, shears and moments following it) and
/// two EMG channels (bursts of noise). `storage`: `"int"` (signed 16-bit ADC values),
/// `"float"` (floats on an ADC grid, as float-format files store them, the EMG computed:
/// on no grid). Deterministic in `seed`.
pub fn force_and_emg(
    frames: usize,
    per_frame: usize,
    seed: u64,
    storage: &str,
) -> crate::motion::analog::Analog {
    use crate::motion::analog::{Analog, Channel, Samples};
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let rate = 100.0 * per_frame as f64;
    let labels = ["Fx1", "Fy1", "Fz1", "Mx1", "My1", "Mz1", "EMG1", "EMG2"];
    let units = ["N", "N", "N", "Nmm", "Nmm", "Nmm", "V", "V"];
    let rows = frames * per_frame;
    let mut adc = Vec::with_capacity(rows * labels.len());
    for r in 0..rows {
        let t = r as f64 / rate;
        let stance = ((t * 0.9).fract() < 0.6) as u8 as f64;
        let fz = stance * 2400.0 * (std::f64::consts::PI * (t * 0.9).fract() / 0.6).sin();
        let burst = 1.0 + 4.0 * ((t * 0.9).fract() < 0.2) as u8 as f64;
        let row = [
            0.08 * fz + 3.0 * noise(),
            -0.05 * fz + 3.0 * noise(),
            fz + 3.0 * noise(),
            12.0 * fz.sqrt() + 5.0 * noise(),
            -9.0 * fz.sqrt() + 5.0 * noise(),
            4.0 * noise(),
            300.0 * burst * noise(),
            200.0 * burst * noise(),
        ];
        adc.extend(row.iter().map(|v| v.round().clamp(-32768.0, 32767.0)));
    }
    let channels: Vec<Channel> = labels
        .iter()
        .zip(units)
        .map(|(l, u)| Channel {
            label: l.to_string(),
            description: String::new(),
            unit: u.to_string(),
            scale: if u == "V" { 1.0e-4 } else { 0.5 },
            offset: 0,
        })
        .collect();
    let samples = if storage == "float" {
        let q = 10.0 / 32768.0;
        Samples::Float(
            adc.iter()
                .enumerate()
                .map(|(i, &v)| {
                    if i % labels.len() >= 6 {
                        // EMG as filtered floats: on no grid.
                        (v * 1.0e-6 * (1.0 + 0.1 * (i as f64).sin())) as f32
                    } else {
                        (v * q) as f32
                    }
                })
                .collect(),
        )
    } else {
        Samples::Int {
            values: adc.iter().map(|&v| v as i32).collect(),
            unsigned: false,
        }
    };
    Analog::new(per_frame, 1.0, channels, samples).expect("a whole number of frames")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_shaped() {
        let a = walker(50, 4, 120.0, 7, 0.5);
        let b = walker(50, 4, 120.0, 7, 0.5);
        assert_eq!(a.positions().len(), 600);
        assert_eq!(
            a.positions()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            b.positions()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        );
    }
}
