//! Analog channels: force plates, EMG, accelerometers — sampled signals recorded beside the
//! points, at a whole multiple of the point rate.
//!
//! Values are kept exactly as the file holds them: 16-bit ADC integers with the file's
//! scale and offset, or the floats a float-format file stores. A value in the channel's
//! unit is `(stored − offset) × scale × gen_scale`, the rule of the C3D standard and of
//! every reader of it (py-c3d, ezc3d, BTK); computing it is the reader's job, never the
//! archive's, so nothing is rounded on the way in.

use serde::Serialize;

use super::error::{Error, Result};

/// One channel: its label and what turns a stored value into its unit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Channel {
    pub label: String,
    pub description: String,
    /// The unit its values are in once scaled (`N`, `V`, `Nmm`…), as the file names it.
    pub unit: String,
    /// `ANALOG:SCALE` of the channel.
    pub scale: f32,
    /// `ANALOG:OFFSET` of the channel, in stored units.
    pub offset: i32,
}

/// Stored values, `rows × channels`, a row (one analog sample time) contiguous.
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// ADC integers: signed 16-bit, or unsigned when the file says `ANALOG:FORMAT
    /// UNSIGNED`.
    Int {
        values: Vec<i32>,
        unsigned: bool,
    },
    Float(Vec<f32>),
}

impl Samples {
    pub fn len(&self) -> usize {
        match self {
            Samples::Int { values, .. } => values.len(),
            Samples::Float(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes a value takes where it came from: 2 for 16-bit integers, 4 for floats. What
    /// a take's raw size counts, so that its ratio is against what was uploaded.
    pub fn stored_width(&self) -> usize {
        match self {
            Samples::Int { .. } => 2,
            Samples::Float(_) => 4,
        }
    }

    /// Stored value `i` as a number.
    pub fn get(&self, i: usize) -> f64 {
        match self {
            Samples::Int { values, .. } => f64::from(values[i]),
            Samples::Float(v) => f64::from(v[i]),
        }
    }

    /// Rows `start..end` of `width` values each.
    pub fn rows(&self, width: usize, start: usize, end: usize) -> Samples {
        let r = start * width..end * width;
        match self {
            Samples::Int { values, unsigned } => Samples::Int {
                values: values[r].to_vec(),
                unsigned: *unsigned,
            },
            Samples::Float(v) => Samples::Float(v[r].to_vec()),
        }
    }
}

/// Analog rows in a frame at `fps` of channels sampled `per_frame` times a frame at
/// `take_fps`: the analog rate over `fps`, which C3D needs whole; why not, when it is not.
pub fn per_frame_at(per_frame: usize, take_fps: f64, fps: f64) -> Result<usize, String> {
    if fps == take_fps {
        return Ok(per_frame);
    }
    let rate = per_frame as f64 * take_fps;
    let k = rate / fps;
    if (k - k.round()).abs() < 1e-6 && k.round() >= 1.0 {
        Ok(k.round() as usize)
    } else {
        Err(format!(
            "the analog channels run at {rate} Hz, which is not a whole number of samples a \
             frame at {fps} fps; ask for a rate that divides it"
        ))
    }
}

/// A take's analog channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Analog {
    /// Analog samples per point frame (`ANALOG:RATE / POINT:RATE`).
    pub per_frame: usize,
    /// `ANALOG:GEN_SCALE`: one factor for every channel.
    pub gen_scale: f32,
    pub channels: Vec<Channel>,
    pub samples: Samples,
}

impl Analog {
    pub fn new(
        per_frame: usize,
        gen_scale: f32,
        channels: Vec<Channel>,
        samples: Samples,
    ) -> Result<Analog> {
        let n = channels.len();
        if per_frame == 0 || n == 0 {
            return Err(Error::Invalid(format!(
                "analog data needs channels and samples per frame ({n} channels, {per_frame} per frame)"
            )));
        }
        if !samples.len().is_multiple_of(n * per_frame) {
            return Err(Error::Invalid(format!(
                "{} analog values do not fill whole frames of {n} channels × {per_frame} samples",
                samples.len()
            )));
        }
        if let Samples::Int { values, unsigned } = &samples {
            let range = if *unsigned {
                0..=i32::from(u16::MAX)
            } else {
                i32::from(i16::MIN)..=i32::from(i16::MAX)
            };
            if values.iter().any(|v| !range.contains(v)) {
                return Err(Error::Invalid("analog integers outside 16 bits".into()));
            }
        }
        Ok(Analog {
            per_frame,
            gen_scale,
            channels,
            samples,
        })
    }

    pub fn channel_count(&self) -> usize {
        self.channels.len()
    }

    /// Analog rows (sample times) in all.
    pub fn rows(&self) -> usize {
        self.samples.len() / self.channels.len()
    }

    /// Point frames the rows make.
    pub fn frames(&self) -> usize {
        self.rows() / self.per_frame
    }

    /// Samples per second, given the point rate.
    pub fn rate(&self, fps: f64) -> f64 {
        fps * self.per_frame as f64
    }

    /// The factor and offset that turn channel `c`'s stored values into its unit.
    pub fn transform(&self, c: usize) -> (f64, f64) {
        let ch = &self.channels[c];
        (
            f64::from(ch.scale) * f64::from(self.gen_scale),
            f64::from(ch.offset),
        )
    }

    /// Value `(row, c)` in the channel's unit.
    pub fn value(&self, row: usize, c: usize) -> f64 {
        let (k, off) = self.transform(c);
        (self.samples.get(row * self.channels.len() + c) - off) * k
    }

    /// The analog of point frames `start..end`.
    pub fn slice_frames(&self, start: usize, end: usize) -> Analog {
        Analog {
            per_frame: self.per_frame,
            gen_scale: self.gen_scale,
            channels: self.channels.clone(),
            samples: self.samples.rows(
                self.channels.len(),
                start * self.per_frame,
                end * self.per_frame,
            ),
        }
    }

    /// The same rows as `frames` frames of `per_frame` rows each: the channels of a take
    /// resampled to another frame rate, at their own rate. Rows past the frames are left
    /// out; a last frame that reaches past the rows holds the last row (a resampled take's
    /// last frame may end after its source's last sample).
    pub fn with_per_frame(&self, per_frame: usize, frames: usize) -> Analog {
        let want = per_frame * frames;
        let have = want.min(self.rows());
        let n = self.channels.len();
        let mut samples = self.samples.rows(n, 0, have);
        if have < want && have > 0 {
            fn pad<T: Copy>(v: &mut Vec<T>, n: usize, have: usize, want: usize) {
                let last = v[(have - 1) * n..have * n].to_vec();
                for _ in have..want {
                    v.extend_from_slice(&last);
                }
            }
            match &mut samples {
                Samples::Int { values, .. } => pad(values, n, have, want),
                Samples::Float(v) => pad(v, n, have, want),
            }
        }
        Analog {
            per_frame,
            gen_scale: self.gen_scale,
            channels: self.channels.clone(),
            samples,
        }
    }

    /// Bytes the values took where they came from ([`Samples::stored_width`]).
    pub fn raw_bytes(&self) -> usize {
        self.samples.len() * self.samples.stored_width()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_of_other_rates_hold_the_same_rows() {
        let a = Analog {
            per_frame: 2,
            gen_scale: 1.0,
            channels: vec![Channel {
                label: "a".into(),
                description: String::new(),
                unit: "V".into(),
                scale: 1.0,
                offset: 0,
            }],
            samples: Samples::Int {
                values: (0..10).collect(),
                unsigned: false,
            },
        };
        let b = a.with_per_frame(4, 2);
        assert_eq!(b.samples.len(), 8);
        assert_eq!(b.frames(), 2);
        let c = a.with_per_frame(4, 3);
        let want: Vec<i32> = (0..10).chain([9, 9]).collect();
        assert_eq!(
            c.samples,
            Samples::Int {
                values: want,
                unsigned: false
            }
        );
    }

    fn ch(label: &str, scale: f32, offset: i32) -> Channel {
        Channel {
            label: label.into(),
            description: String::new(),
            unit: "N".into(),
            scale,
            offset,
        }
    }

    #[test]
    fn values_follow_the_c3d_rule() {
        let a = Analog::new(
            2,
            0.5,
            vec![ch("Fx", 2.0, 10), ch("Fy", -1.0, 0)],
            Samples::Int {
                values: vec![10, 4, 20, -4, 30, 0, 40, 2],
                unsigned: false,
            },
        )
        .unwrap();
        assert_eq!((a.rows(), a.frames()), (4, 2));
        assert_eq!(a.value(1, 0), 10.0); // (20 - 10) × 2 × 0.5
        assert_eq!(a.value(1, 1), 2.0); // (-4 - 0) × -1 × 0.5
        assert_eq!(a.slice_frames(1, 2).value(0, 0), 20.0);
        assert_eq!(a.raw_bytes(), 16);
    }

    #[test]
    fn shapes_and_ranges_are_checked() {
        let int = |values: Vec<i32>, unsigned| Samples::Int { values, unsigned };
        assert!(Analog::new(2, 1.0, vec![ch("a", 1.0, 0)], int(vec![1, 2, 3], false)).is_err());
        assert!(Analog::new(1, 1.0, vec![ch("a", 1.0, 0)], int(vec![40_000], false)).is_err());
        assert!(Analog::new(1, 1.0, vec![ch("a", 1.0, 0)], int(vec![40_000], true)).is_ok());
        assert!(Analog::new(0, 1.0, vec![ch("a", 1.0, 0)], int(vec![], true)).is_err());
    }
}
