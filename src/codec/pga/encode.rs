//! The `pga` encoder: fit the take's principal geodesics, keep the fewest directions whose
//! truncation leaves room in the bound, then code each chunk at the largest step whose
//! decoded FK positions meet it (the decoder's own reconstruction, IK included, is what is
//! measured).

use nalgebra::UnitQuaternion;

use super::chunk::Trajectories;
use super::coder::Coder;
use super::frames;
use super::layout::Layout;
use super::model::Geodesics;
use super::params::{Params, MAX_ITERATIONS, MAX_STRIDE_LOG2};
use super::scale;
use crate::codec::container::estimated_bytes;
use crate::codec::entropy::io::Dry;
use crate::codec::entropy::rangecoder::Encoder;
use crate::codec::error::{Error, Result};
use crate::codec::measure::max_mean;
use crate::codec::rate::{narrow, ChunkSteps, Smallest};
use crate::codec::skeleton::{printed, Skeleton};
use crate::codec::twists::Around;
use crate::codec::{default_chunk_frames, ChunkOut, CodecOutput, Input, Target};
use crate::motion::Animation;

/// How a take is coded and decoded, beyond its model and steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// IK steps per decoded frame (0: no IK, no end points coded).
    pub iterations: u8,
    /// Coordinate steps relative to position steps ([`Scale::steps`](super::scale::Scale::steps)).
    pub rho: f64,
    /// IK weight of the coordinates ([`Scale::weights`](super::scale::Scale::weights)).
    pub lambda: f64,
    /// log₂ of the lifting's coarsest stride.
    pub stride_log2: u8,
    /// Details within `½ + dead_zone` steps of zero are dropped ([`Steps::dead_zone`](super::chunk::Steps::dead_zone)).
    pub dead_zone: f64,
}

impl Options {
    /// Poses from their coordinates alone: no end points to send, and the fastest decoder
    /// (about 100 k frames/s on CMU). Smallest at tight bounds, where coordinates must be
    /// fine anyway.
    pub const PLAIN: Options = Options {
        iterations: 0,
        rho: 1.0,
        lambda: 1.0,
        stride_log2: 5,
        dead_zone: 0.0,
    };
    /// The paper's decoder: end points sent, coordinates 4× coarser, one Gauss–Newton step
    /// of IK per frame pulls the pose onto the end points (more steps changed no size on
    /// CMU, Bandai and misc takes; `rho` 8, `lambda` 0.003 or stride 64 did worse). Smaller
    /// than [`Options::PLAIN`] at loose bounds (CMU at max 12.5 mm: 7 % with the canonical
    /// model, 16–25 % with the principal one), larger at tight ones; decoding at 15–33 k
    /// frames/s. Its dead zone saved 7 % on CMU at 12.5 mm (0.4 did worse; without IK it
    /// made no difference).
    pub const IK: Options = Options {
        iterations: 1,
        rho: 4.0,
        lambda: 0.01,
        stride_log2: 5,
        dead_zone: 0.2,
    };
}

/// The share of the bound the dropped directions may take (from 0.3 to 0.9 changed sizes by
/// under 1 % on CMU: coordinates coded finely make up for the directions dropped).
const TRUNCATION_SHARE: f64 = 0.5;

/// A take being encoded.
pub struct Take<'a> {
    rig: &'a Skeleton,
    input: &'a Input<'a>,
    layout: Layout,
    values: &'a [f64],
    /// Each frame's inner-joint rotations (`frames × n`).
    poses: Vec<UnitQuaternion<f64>>,
    /// Every direction, fitted to the take.
    full: Geodesics,
    /// Per direction, the largest coordinate along it.
    extent: Vec<f64>,
    /// The skeleton's reach ([`scale::reach`]).
    reach: f64,
}

/// The share of the bound a stored direction's rounding may take at the farthest point.
const MODEL_SHARE: f64 = 0.05;

impl<'a> Take<'a> {
    pub fn new(
        rig: &'a Skeleton,
        skeleton: &'a Animation,
        input: &'a Input<'a>,
    ) -> Result<Take<'a>> {
        let frames = skeleton.frame_count();
        let values = &skeleton.values[..];
        let layout = Layout::new(rig, values, frames).map_err(Error::Invalid)?;
        let n = layout.inner_count();
        let cc = layout.channels();
        let mut poses = vec![UnitQuaternion::identity(); frames * n];
        for (f, pose) in poses.chunks_exact_mut(n).enumerate() {
            layout.split(&values[f * cc..(f + 1) * cc], pose);
        }
        let full = Geodesics::fit(&poses, n, 3 * n)
            .ok_or_else(|| Error::Invalid("pga found no mean pose".into()))?;
        let mut extent = vec![0f64; full.dims()];
        for pose in poses.chunks_exact(n) {
            for (e, x) in extent.iter_mut().zip(full.coordinates(pose)) {
                *e = e.max(x.abs());
            }
        }
        let reach = scale::reach(layout.chain());
        Ok(Take {
            rig,
            input,
            layout,
            values,
            poses,
            full,
            extent,
            reach,
        })
    }

    /// The first `k` directions as stored for bound `t` (each to the precision at which its
    /// rounding moves the farthest point by [`MODEL_SHARE`] of `t` at most), and as parsed.
    fn stored(&self, k: usize, t: f64) -> Result<(Vec<u8>, Geodesics)> {
        let n = self.layout.inner_count();
        let precision: Vec<f64> = self.extent[..k]
            .iter()
            .map(|x| MODEL_SHARE * t / (x.max(1e-9) * self.reach.max(1e-9)))
            .collect();
        let bytes = self.full.truncated(k).to_bytes(&precision);
        let model = Geodesics::parse(&bytes, n, 3 * n)?;
        Ok((bytes, model))
    }

    /// Max and mean error (take units) of every frame posed from its coordinates along
    /// `g`'s directions alone (the root as given).
    fn truncation_error(&self, g: &Geodesics) -> (f64, f64) {
        let n = self.layout.inner_count();
        let cc = self.layout.channels();
        let frames = self.poses.len() / n;
        let mut values = vec![0.0; frames * cc];
        let mut inner = vec![UnitQuaternion::identity(); n];
        let mut scratch = vec![UnitQuaternion::identity(); n];
        for f in 0..frames {
            let root = self
                .layout
                .split(&self.values[f * cc..(f + 1) * cc], &mut scratch);
            g.pose(&g.coordinates(&self.poses[f * n..(f + 1) * n]), &mut inner);
            let (done, rest) = values.split_at_mut(f * cc);
            let previous = (f > 0).then(|| &done[(f - 1) * cc..]);
            self.layout.join(root, &inner, previous, &mut rest[..cc]);
        }
        for v in &mut values {
            *v = printed(*v);
        }
        let mut positions = vec![0f32; self.input.data.len()];
        self.rig.positions(&values, &mut positions);
        max_mean(self.input.data, &positions, self.input.valid)
    }

    /// The fewest directions whose truncation error, as stored, meets `share` of `target`.
    fn directions_for(&self, target: Target, t: f64, share: f64) -> Result<usize> {
        let within = target.scaled(share);
        let meets = |k: usize| -> Result<bool> {
            let (max, mean) = self.truncation_error(&self.stored(k, t)?.1);
            Ok(within.holds(max, mean))
        };
        // `hi` meets (or is every direction), `lo` does not.
        let (_, hi) = narrow(0, self.full.dims(), |k| Ok(!meets(k)?))?;
        Ok(hi)
    }

    /// The smallest bitstream for `target`: each model of `models` coded with `options[0]`,
    /// the one that codes smaller then with each other option; the first error if none
    /// meets the bound.
    pub fn encode(
        &self,
        target: Target,
        models: &[Directions],
        options: &[Options],
    ) -> Result<CodecOutput> {
        let t = target.tightest();
        if !(t.is_finite() && t > 0.0) {
            return Err(Error::Invalid(format!(
                "pga needs a positive bound, got {t}"
            )));
        }
        let (Some(first), Some(_)) = (options.first(), models.first()) else {
            return Err(Error::Fault("pga was given no options".into()));
        };
        // The smallest success, with the model it came from; the first error if none.
        let mut best = Smallest::new();
        let mut error = None;
        let mut offer = |best: &mut Smallest<_>, coded: Result<CodecOutput>, m: usize| match coded {
            Ok(out) => {
                best.offer(estimated_bytes(out.params.len(), &out.chunks), (out, m));
            }
            Err(e) => {
                error.get_or_insert(e);
            }
        };
        let mut candidates = Vec::with_capacity(models.len());
        for (m, directions) in models.iter().enumerate() {
            let candidate = self.model(*directions, target, t)?;
            offer(&mut best, self.code(&candidate, *first, target), m);
            candidates.push(candidate);
        }
        let winner = best.best().map_or(0, |b| b.1);
        for o in &options[1..] {
            offer(
                &mut best,
                self.code(&candidates[winner], *o, target),
                winner,
            );
        }
        match (best.into_best(), error) {
            (Some((out, _)), _) => Ok(out),
            (None, Some(e)) => Err(e),
            (None, None) => Err(Error::Fault("pga was given no models".into())),
        }
    }

    /// A model for `target` and each chunk's trajectories along it.
    fn model(&self, directions: Directions, target: Target, t: f64) -> Result<Model> {
        let n = self.layout.inner_count();
        let (bytes, model) = match directions {
            Directions::Principal => {
                let k = self.directions_for(target, t, TRUNCATION_SHARE)?;
                self.stored(k, t)?
            }
            Directions::Canonical => {
                let bytes = Geodesics::canonical(self.full.mean.clone()).to_bytes(&[]);
                let model = Geodesics::parse(&bytes, n, 3 * n)?;
                (bytes, model)
            }
        };
        let cc = self.layout.channels();
        let per = default_chunk_frames(self.input.fps);
        let frames = self.poses.len() / n;
        let given = (0..frames)
            .step_by(per)
            .map(|f0| {
                let len = per.min(frames - f0);
                let values = &self.values[f0 * cc..(f0 + len) * cc];
                (f0, frames::analyse(&self.layout, &model, values, len))
            })
            .collect();
        Ok(Model {
            bytes,
            model,
            given,
        })
    }

    /// The take coded with `model` and options `o`.
    fn code(&self, model: &Model, o: Options, target: Target) -> Result<CodecOutput> {
        let params = Params {
            version: super::params::VERSION,
            iterations: o.iterations.min(MAX_ITERATIONS),
            stride_log2: o.stride_log2.min(MAX_STRIDE_LOG2),
            base: target.tightest(),
            rho: f64::from(o.rho as f32),
            lambda: f64::from(o.lambda as f32),
            root: self.layout.root(),
            constants: self.layout.constants().to_vec(),
            model: model.model.clone(),
            model_bytes: model.bytes.clone(),
        };
        let coder = Coder::new(&self.layout, params).with_dead_zone(o.dead_zone);
        self.code_chunks(&coder, &model.given, target)
    }

    /// Every chunk of `given` coded by `coder` at the largest step that meets `target`,
    /// twisting near lock ([`twists`](crate::codec::twists)) unless that cannot meet it (a
    /// twist moves a rotation a little, and what hangs below it).
    fn code_chunks(
        &self,
        coder: &Coder,
        given: &[(usize, Trajectories)],
        target: Target,
    ) -> Result<CodecOutput> {
        let k = coder.params.model.dims();
        let w = self.input.points * 3;
        let mut chunks = Vec::with_capacity(given.len());
        // The step search with twists and without: each chunk's starts where the last
        // one's ended.
        let mut steps = [ChunkSteps::default(); 2];
        for (i, (f0, given)) in given.iter().enumerate() {
            let (f0, len) = (*f0, given.root_position.len());
            let original = &self.input.data[f0 * w..(f0 + len) * w];
            let valid = self.input.valid.map(|v| &v[f0 * w / 3..(f0 + len) * w / 3]);
            let cc = self.layout.channels();
            let source = Around::new(self.values, cc, f0, len);
            let meets = |twists: bool, s: u32| -> Result<bool> {
                let decoded = coder.code(&mut Dry, s, twists, len, Some((given, source)))?;
                let mut positions = vec![0f32; len * w];
                self.rig.positions(&decoded, &mut positions);
                let (max, mean) = max_mean(original, &positions, valid);
                Ok(target.holds(max, mean))
            };
            let mut found = None;
            for twists in [true, false] {
                if let Some(s) = steps[usize::from(twists)].largest(|s| meets(twists, s))? {
                    found = Some((s, twists));
                    break;
                }
            }
            let (s, twists) = found.ok_or_else(|| Error::BoundMissed {
                codec: "pga".into(),
                detail: format!(
                    "chunk {i} misses the bound even at the finest step with {k} directions"
                ),
            })?;
            let mut enc = Encoder::new();
            coder.code(&mut enc, s, twists, len, Some((given, source)))?;
            chunks.push(ChunkOut {
                frames: len,
                bytes: enc.finish(),
            });
        }
        Ok(CodecOutput {
            params: coder.params.to_bytes(),
            chunks,
        })
    }
}

/// Which directions a take's model has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Directions {
    /// The fewest principal geodesics that leave room in the bound (the paper's).
    Principal,
    /// Every joint's own axes ([`Geodesics::canonical`]): nothing to store but the means,
    /// and each coordinate's error stays with its joint. Without IK it coded 8–34 % smaller
    /// than the principal directions on Bandai's 6 s takes and 6–26 % on CMU's (max 1 and
    /// 12.5 mm): under a max bound, a principal direction spreads its coordinate's error
    /// over every joint it moves, and its storage costs more than it saves.
    Canonical,
}

/// A model as stored and parsed, and every chunk's trajectories along it.
struct Model {
    bytes: Vec<u8>,
    model: Geodesics,
    given: Vec<(usize, Trajectories)>,
}
