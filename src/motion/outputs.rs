//! Model outputs: what a biomechanical model (Vicon's Plug-in Gait and the like) computed
//! from the markers and wrote into a C3D's POINT block as if it were points: joint angles,
//! forces, moments and powers, three numbers a frame each, listed by name in
//! `POINT:ANGLES`, `FORCES`, `MOMENTS` and `POWERS` with their units in `ANGLE_UNITS`,
//! `FORCE_UNITS`, `MOMENT_UNITS` and `POWER_UNITS`.
//!
//! They are not positions: a hip angle of 28.5° is not 28.5 mm. So they are kept apart from
//! the markers (never in positions, glTF, windows or search), exactly as the file holds them
//! (the number a reader of the file gets, in the output's own unit), each with its kind,
//! unit and place among the file's points, so that a C3D written back puts every one where
//! it was.

use serde::{Deserialize, Serialize};

use super::error::{Error, Result};

/// What an output measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    Angle,
    Force,
    Moment,
    Power,
}

impl Kind {
    pub const ALL: [Kind; 4] = [Kind::Angle, Kind::Force, Kind::Moment, Kind::Power];

    /// The `POINT` parameter that lists outputs of this kind.
    pub fn list(self) -> &'static str {
        match self {
            Kind::Angle => "ANGLES",
            Kind::Force => "FORCES",
            Kind::Moment => "MOMENTS",
            Kind::Power => "POWERS",
        }
    }

    /// The `POINT` parameter that names their unit.
    pub fn unit_parameter(self) -> &'static str {
        match self {
            Kind::Angle => "ANGLE_UNITS",
            Kind::Force => "FORCE_UNITS",
            Kind::Moment => "MOMENT_UNITS",
            Kind::Power => "POWER_UNITS",
        }
    }

    /// The unit when the file names none: Vicon's, which the C3D user guide documents.
    pub fn default_unit(self) -> &'static str {
        match self {
            Kind::Angle => "deg",
            Kind::Force => "N",
            Kind::Moment => "Nmm",
            Kind::Power => "W",
        }
    }
}

/// One output: its name (the file's point label), kind, unit, and its place among the
/// file's points (0-based, markers and outputs together).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Output {
    pub name: String,
    pub kind: Kind,
    pub unit: String,
    pub slot: usize,
}

/// A take's model outputs and their values.
#[derive(Debug, Clone, PartialEq)]
pub struct Outputs {
    pub outputs: Vec<Output>,
    /// `frames × outputs × 3`, a frame contiguous; NaN where the file marks a gap.
    pub values: Vec<f32>,
}

impl Outputs {
    /// Outputs whose values tile whole frames and whose slots are distinct.
    pub fn new(outputs: Vec<Output>, values: Vec<f32>) -> Result<Outputs> {
        let w = outputs.len() * 3;
        if w == 0 || !values.len().is_multiple_of(w) {
            return Err(Error::Invalid(format!(
                "{} model output values for {} outputs",
                values.len(),
                outputs.len()
            )));
        }
        let mut slots: Vec<usize> = outputs.iter().map(|o| o.slot).collect();
        slots.sort_unstable();
        if slots.windows(2).any(|w| w[0] == w[1]) {
            return Err(Error::Invalid("two model outputs in one point slot".into()));
        }
        Ok(Outputs { outputs, values })
    }

    pub fn frames(&self) -> usize {
        self.values.len() / (self.outputs.len() * 3)
    }

    /// Frames `start..end`.
    pub fn rows(&self, start: usize, end: usize) -> Outputs {
        let w = self.outputs.len() * 3;
        Outputs {
            outputs: self.outputs.clone(),
            values: self.values[start * w..end * w].to_vec(),
        }
    }

    /// The output named `name`.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.outputs.iter().position(|o| o.name == name)
    }

    /// Output `o`'s three values in frame `f`.
    pub fn get(&self, f: usize, o: usize) -> [f32; 3] {
        let at = (f * self.outputs.len() + o) * 3;
        [self.values[at], self.values[at + 1], self.values[at + 2]]
    }

    /// The outputs at `to` fps from `from` fps, each component as positions are resampled
    /// ([`Positions`](super::transform::resample::Positions): a cubic through the
    /// neighbouring frames, missing where a frame beside it is).
    pub fn resampled(&self, from: f64, to: f64) -> Outputs {
        use super::transform::resample::{Positions, Resampler};
        if from == to {
            return self.clone();
        }
        let points = self.outputs.len();
        let mut r = Resampler::new(Positions { points }, self.frames(), from, to);
        let source: Vec<f64> = self.values.iter().map(|&v| f64::from(v)).collect();
        let mut out = Vec::with_capacity(r.output_frames() * points * 3);
        r.push(&source, &mut out);
        Outputs {
            outputs: self.outputs.clone(),
            values: out.into_iter().map(|v| v as f32).collect(),
        }
    }

    /// Each point slot of the file, markers and outputs together, in order: `Err(m)` for
    /// the next marker (its index among `markers`), `Ok(o)` for output `o`. Outputs whose
    /// slot lies past the total (a take whose markers were cut) follow in their order.
    pub fn interleave(&self, markers: usize) -> Vec<std::result::Result<usize, usize>> {
        let total = markers + self.outputs.len();
        let mut at: Vec<Option<usize>> = vec![None; total];
        let mut late = Vec::new();
        for (o, out) in self.outputs.iter().enumerate() {
            match at.get_mut(out.slot) {
                Some(s @ None) => *s = Some(o),
                _ => late.push(o),
            }
        }
        let mut next_marker = 0;
        let mut order = Vec::with_capacity(total);
        for s in at {
            match s {
                Some(o) => order.push(Ok(o)),
                None if next_marker < markers => {
                    order.push(Err(next_marker));
                    next_marker += 1;
                }
                None => {}
            }
        }
        order.extend(late.into_iter().map(Ok));
        order
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn output(name: &str, slot: usize) -> Output {
        Output {
            name: name.into(),
            kind: Kind::Angle,
            unit: "deg".into(),
            slot,
        }
    }

    #[test]
    fn outputs_go_back_to_their_slots_among_the_markers() {
        let o = Outputs::new(vec![output("A", 1), output("B", 4)], vec![0.0; 12]).unwrap();
        assert_eq!(o.frames(), 2);
        assert_eq!(o.interleave(3), vec![Err(0), Ok(0), Err(1), Err(2), Ok(1)]);
        // Fewer markers than the file had: the late output follows.
        assert_eq!(o.interleave(1), vec![Err(0), Ok(0), Ok(1)]);
    }

    #[test]
    fn values_must_tile_frames_and_slots_be_distinct() {
        assert!(Outputs::new(vec![output("A", 1)], vec![0.0; 4]).is_err());
        assert!(Outputs::new(vec![output("A", 1), output("B", 1)], vec![0.0; 6]).is_err());
        assert!(Outputs::new(vec![], vec![]).is_err());
    }
}
