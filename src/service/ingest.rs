//! Ingest one take: parse, encode with every candidate codec in parallel on the blocking
//! pool, keep the smallest that meets the bound, store it with its decision record.

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use super::analog::{self, AnalogBounds};
use super::choose::{self, CodecRequest, Decision, Keep, Tried};
use super::history::{self, Histories};
use super::motion_index::MotionIndex;
use super::skeletons;
use super::take::{Label, Take, TakeMeta};
use super::{blocking, Error, Result};
use crate::codec::{self, CodecId, Encoded, ErrorBound, Hints, Latency};
use crate::motion::body::{Body, Given};
use crate::motion::formats::{self, Format, ReadLimits, ReadOptions};
use crate::motion::Motion;
use crate::store::{NewTake, Store};

/// An upload and what the user asked of it.
#[derive(Debug, Clone)]
pub struct IngestRequest {
    /// The upload, received once and shared (not copied) with the parser.
    pub bytes: bytes::Bytes,
    /// Name, library, tags.
    pub label: Label,
    /// Metres per unit of the upload, overriding the file's own.
    pub unit: Option<f64>,
    pub fps: Option<f64>,
    pub codec: CodecRequest,
    pub bound: ErrorBound,
    pub latency: Latency,
    /// For skeleton takes: keep the animation (default) or let position codecs compete.
    pub keep: Keep,
    pub limits: ReadLimits,
    /// Format to assume when the content does not identify itself (from `Content-Type`).
    pub format_hint: Option<Format>,
    /// Keep a file that contradicts its own header, with a warning (see [`ReadOptions`]).
    pub lenient: bool,
    /// What the request said about the take's points (its torso, for `spca`).
    pub hints: Hints,
    /// Bounds on the analog channels, each in its own unit; none: kept exactly.
    pub analog_bounds: AnalogBounds,
    /// The take's up and forward axes as the user states them: they win over anatomy.
    pub axes: Given,
    /// Which of the file's animations to store; none: every one, each a take of its own.
    pub animation: Option<formats::Pick>,
}

/// How a take is to be coded: the codec asked for (or auto), its bound and latency, what a
/// skeleton take keeps, and what the request said about its points.
#[derive(Debug, Clone)]
pub struct Coding {
    pub codec: CodecRequest,
    pub bound: ErrorBound,
    pub latency: Latency,
    pub keep: Keep,
    pub hints: Hints,
}

/// What ingest reports back.
#[derive(Debug, Clone, Serialize)]
pub struct IngestReport {
    pub id: String,
    pub name: String,
    pub codec: CodecId,
    pub frames: usize,
    pub points: usize,
    pub fps: f64,
    pub raw_bytes: usize,
    pub stored_bytes: usize,
    pub ratio: f64,
    pub max_mm: f64,
    pub mean_mm: f64,
    pub rms_mm: f64,
    pub kg_percent: f64,
    pub decision: Decision,
    /// The analog channels' coding, if the take has any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub analog: Option<super::take::AnalogMeta>,
    pub warnings: Vec<String>,
    /// The file's other animations, each stored as a take of its own (FBX stacks, glTF
    /// animations), when none was asked for.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub more: Vec<IngestReport>,
}

/// Ingest one upload; `histories`, if given, is what choice has learnt from the takes
/// before ([`history`]). A file of several animations (FBX stacks, glTF animations) is read
/// whole first, every animation bounded together, then stored as one take each, named
/// `name/animation` and labelled `animation`, unless the request picked one. With `index`,
/// each stored take's motion features are taken before the answer, so that it is found by
/// search at once (a take whose features fail for the server's reasons is stored all the
/// same, and the index job takes them).
pub async fn ingest(
    store: &Store,
    histories: Option<&Histories>,
    index: Option<&MotionIndex>,
    req: IngestRequest,
) -> Result<IngestReport> {
    let bytes = req.bytes.clone();
    let options = ReadOptions {
        limits: req.limits,
        unit: req.unit,
        fps: req.fps,
        lenient: req.lenient,
        animation: req.animation.clone(),
    };
    let hint = req.format_hint;
    let loads = blocking(
        move || -> crate::motion::error::Result<Vec<formats::Loaded>> {
            let read = |options: &ReadOptions| match (formats::detect(&bytes), hint) {
                (Err(_), Some(f)) => formats::read_as(f, &bytes, options),
                _ => formats::read(&bytes, options),
            };
            let first = read(&options)?;
            let count = first.extras.animations.len();
            let mut loads = vec![first];
            if options.animation.is_none() {
                let mut samples = loads[0].motion.positions().len() as u64 / 3;
                for i in 1..count {
                    let next = read(&ReadOptions {
                        animation: Some(formats::Pick::Index(i)),
                        ..options.clone()
                    })?;
                    samples += next.motion.positions().len() as u64 / 3;
                    if samples > options.limits.max_samples {
                        return Err(crate::motion::error::Error::Limit {
                            what: "sample count of every animation (frames × points)",
                            actual: samples,
                            limit: options.limits.max_samples,
                        });
                    }
                    loads.push(next);
                }
            }
            Ok(loads)
        },
    )
    .await??;
    let named = loads.len() > 1 || req.animation.is_some();
    let mut reports = Vec::with_capacity(loads.len());
    for mut loaded in loads {
        let mut req = req.clone();
        if named {
            let animation = loaded
                .extras
                .animations
                .get(loaded.extras.animation)
                .cloned();
            if let Some(a) = animation {
                req.label.name = req.label.name.map(|n| format!("{n}/{a}"));
                loaded
                    .extras
                    .labels
                    .insert("animation", crate::labels::Label::Text(a))
                    .map_err(Error::InvalidRequest)?;
            }
        }
        let report = store_loaded(store, histories, &req, loaded).await?;
        if let Some(index) = index {
            if let Err(e) = index.index_now(&report.id).await {
                tracing::warn!(take = %report.id, error = %e, "taking motion features failed; the index job will");
            }
        }
        reports.push(report);
    }
    let mut reports = reports.into_iter();
    let mut first = reports.next().expect("a file read gives one take at least");
    first.more = reports.collect();
    Ok(first)
}

/// Code and store one take as read.
async fn store_loaded(
    store: &Store,
    histories: Option<&Histories>,
    req: &IngestRequest,
    loaded: formats::Loaded,
) -> Result<IngestReport> {
    let motion = Arc::new(loaded.motion);
    let extras = loaded.extras;
    // The body before any coding: a contradiction in what was given is the caller's 400.
    let given = req.axes;
    let prior = loaded.up;
    let body = {
        let m = motion.clone();
        blocking(move || Body::of(&m, given, prior.as_ref())).await?
    }
    .map_err(|e| Error::InvalidRequest(e.to_string()))?;
    // A file of analog channels or model outputs alone is a take with no point chunks.
    let analog_only =
        motion.point_count() == 0 && (extras.analog.is_some() || extras.outputs.is_some());
    if motion.frame_count() == 0
        || !analog_only && (motion.point_count() == 0 || motion.gap_fraction() >= 1.0)
    {
        return Err(Error::Unsatisfiable(format!(
            "the take has no point samples to store ({} points, {} frames), no analog \
             channels and no model outputs",
            motion.point_count(),
            motion.frame_count()
        )));
    }
    if extras.analog.is_none() && !req.analog_bounds.is_empty() {
        return Err(Error::InvalidRequest(
            "analog_bound was given but the take has no analog channels".into(),
        ));
    }
    // Points the request named must be the take's: a 400 naming the point, not a codec
    // that quietly sits out.
    req.hints
        .torso_points(&motion.point_names)
        .map_err(|e| Error::InvalidRequest(e.to_string()))?;
    let layout = motion.layout_signature().to_hex();
    let coding = Coding {
        codec: req.codec,
        bound: req.bound,
        latency: req.latency,
        keep: req.keep,
        hints: req.hints.clone(),
    };
    let (decision, enc) = if analog_only {
        let enc = codec::pipeline::encode_no_points(
            motion.frame_count(),
            motion.fps,
            motion.unit.metres_per_unit,
        )?;
        (choose::no_points(enc.stored_bytes), enc)
    } else {
        encode_best(store, motion.clone(), &layout, &coding, histories).await?
    };
    // Analog chunks cover the frames the point chunks do, so a range reads its own of both.
    let analog = match extras.analog {
        Some(a) => {
            let chunk_frames = enc
                .container
                .header
                .chunks
                .iter()
                .map(|c| c.frames as usize)
                .collect();
            Some(analog::code(Arc::new(a), motion.fps, chunk_frames, &req.analog_bounds).await?)
        }
        None => None,
    };
    // Model outputs, exactly, apart from the markers.
    let outputs = match extras.outputs {
        Some(o) => {
            let fps = motion.fps;
            let raw = o.values.len() as u64 * 4;
            let described = o.outputs.clone();
            let bytes = blocking(move || codec::outputs::encode(&o, fps)).await??;
            Some((described, raw, bytes))
        }
        None => None,
    };
    // Parameters C3D cannot hold again (an entry past an i16 offset, a name of 128 bytes)
    // are dropped with a warning rather than refuse the take.
    let mut warnings = loaded.warnings;
    let parameters = match extras.parameters.as_ref().map(analog::parameters_row) {
        Some(Ok(row)) => Some(row),
        Some(Err(e)) => {
            warnings.push(format!("{e}; the parameter section is not kept"));
            None
        }
        None => None,
    };

    let m = &motion;
    let meta = TakeMeta {
        point_names: m.point_names.clone(),
        unit: m.unit.clone(),
        warnings: warnings.clone(),
        decision: decision.clone(),
        decoded_blake3: Some(enc.decoded_digest.clone()),
        interrupted: None,
        frames_lost: 0,
        handovers: Vec::new(),
        reencoded_from: None,
        events: extras.events,
        first_frame: extras.first_frame,
        analog: analog.as_ref().map(|a| a.meta.clone()),
        axes: Some(body.axes.clone()),
        roles_given: Default::default(),
        outputs: outputs.as_ref().map(|o| o.0.clone()).unwrap_or_default(),
    };
    let format = loaded.format.name();
    // The file's labels, and over them the request's.
    let mut label = req.label.clone();
    label.labels = extras.labels.clone();
    label
        .labels
        .merge(&req.label.labels)
        .map_err(Error::InvalidRequest)?;
    let mut take = Take::new(
        &label,
        format,
        m.fps,
        layout,
        decision.winner,
        req.bound,
        meta,
    );
    take.roles = body.roles;
    take.set_frames(m.frame_count());
    take.header = enc.container.header.to_bytes();
    take.set_measured(enc.stored_bytes, &enc.stats);
    if let Some(a) = &analog {
        take.add_beside(a.meta.raw_bytes, a.meta.stored_bytes);
    }
    if let Some(p) = &parameters {
        take.add_beside(0, p.payload.len() as u64);
    }
    if let Some((_, raw, bytes)) = &outputs {
        take.add_beside(*raw, bytes.len() as u64);
    }
    let basis = enc.container.header.basis.as_ref().map(codec::basis::hex);
    // The rig the encoder built when the codec keeps channels; built here otherwise.
    let skeleton = match (&enc.rig, &m.skeleton) {
        (Some(rig), _) => Some(skeletons::row_of(rig, &take.layout, take.created_at)),
        (None, Some(s)) => Some(skeletons::of(s, &take.layout, take.created_at)?.1),
        (None, None) => None,
    };
    take.skeleton = skeleton.as_ref().map(|k| k.id.clone());
    store
        .insert(&NewTake {
            row: take.to_row()?,
            chunks: super::take::chunk_rows(&enc.container),
            basis,
            skeleton,
            errors: Some(enc.series.to_bytes()),
            analog: analog.as_ref().map(|a| analog::rows(&a.container, &a.meta)),
            parameters,
            outputs: outputs.map(|o| o.2),
            stream: None,
        })
        .await?;
    let (raw_bytes, stored_bytes, ratio) = (
        take.raw_bytes as usize,
        take.stored_bytes as usize,
        take.ratio,
    );
    Ok(IngestReport {
        id: take.id.clone(),
        name: take.name.clone(),
        codec: decision.winner,
        frames: m.frame_count(),
        points: m.point_count(),
        fps: m.fps,
        raw_bytes,
        stored_bytes,
        ratio,
        max_mm: enc.stats.max_mm,
        mean_mm: enc.stats.mean_mm,
        rms_mm: enc.stats.rms_mm,
        kg_percent: take.kg_percent,
        decision,
        analog: analog.map(|a| a.meta),
        warnings,
        more: Vec::new(),
    })
}

/// Encode `motion` with every candidate codec (shared-basis codecs with the newest basis of
/// its layout) in parallel on the blocking pool, and keep the smallest that meets `bound`.
/// With `histories`, an automatic choice leaves out the candidates that the takes of this
/// layout before it say would lose ([`history`]), and an explored take teaches it.
pub async fn encode_best(
    store: &Store,
    motion: Arc<Motion>,
    layout: &str,
    coding: &Coding,
    histories: Option<&Histories>,
) -> Result<(Decision, Encoded)> {
    let Coding {
        codec: request,
        bound,
        latency,
        keep,
        ..
    } = *coding;
    let hints = Arc::new(coding.hints.clone());
    let bases = super::bases::latest_for(store, layout).await?;
    let kinds: Vec<_> = bases.iter().map(|b| b.kind()).collect();
    let (run, skipped) = choose::candidates(request, latency, keep, &motion, &kinds);
    let rule = (request == CodecRequest::Auto && motion.skeleton.is_some()).then_some(keep);
    let mut learning = histories
        .filter(|_| request == CodecRequest::Auto)
        .map(|h| {
            let key = history::Key {
                layout: layout.to_string(),
                bound: bound.to_string(),
                rules: format!("{latency:?}, keep {keep:?}"),
                bases: bases.iter().map(|b| codec::basis::hex(&b.hash())).collect(),
            };
            let plan = h.plan(&key, &run);
            (h, key, plan)
        });
    let run = learning
        .as_ref()
        .map_or(run, |(_, _, plan)| plan.run.clone());
    let encode = |codecs: Vec<CodecId>| {
        let (motion, bases, hints) = (&motion, &bases, &hints);
        async move {
            let jobs: Vec<_> = codecs
                .into_iter()
                .map(|codec| {
                    let m = motion.clone();
                    let shared = choose::basis_for(codec, bases);
                    let hints = hints.clone();
                    tokio::task::spawn_blocking(move || {
                        let t0 = Instant::now();
                        let r = codec::encode(
                            &m,
                            codec,
                            bound,
                            codec::EncodeOptions {
                                basis: shared.as_ref(),
                                hints: (*hints).clone(),
                                ..Default::default()
                            },
                        );
                        (codec, r, t0.elapsed().as_secs_f64() * 1e3)
                    })
                })
                .collect();
            let mut tried = Vec::new();
            let mut encodings: Vec<(CodecId, Encoded)> = Vec::new();
            for job in jobs {
                let (codec, r, ms) = job
                    .await
                    .map_err(|e| Error::Internal(format!("encoder failed: {e}")))?;
                match r {
                    Ok(e) => {
                        let measured = (e.stored_bytes, e.stats.max_mm, e.stats.mean_mm);
                        tried.push(Tried::new(codec, Ok(measured), ms));
                        encodings.push((codec, e));
                    }
                    Err(e) => tried.push(Tried::new(codec, Err(e.to_string()), ms)),
                }
            }
            Ok::<_, Error>((tried, encodings))
        }
    };
    let (mut tried, mut encodings) = encode(run).await?;
    // Where every candidate kept failed on this take, the ones the history left out run
    // after all: a history says what usually loses, not what can be done without.
    if let Some((_, _, plan)) = learning.as_mut() {
        if encodings.is_empty() && !plan.pruned.is_empty() {
            let rest = plan.pruned.drain(..).map(|p| p.codec).collect();
            let (more, enc) = encode(rest).await?;
            tried.extend(more);
            encodings.extend(enc);
        }
    }
    let errors: Vec<String> = tried.iter().filter_map(|t| t.error.clone()).collect();
    let mut decision = choose::decide(tried, skipped, &bound.to_string()).ok_or_else(|| {
        if let CodecRequest::Only(c) = request {
            Error::Unsatisfiable(format!(
                "{c} cannot encode this take: {}",
                errors.join("; ")
            ))
        } else {
            Error::Internal(format!(
                "no codec could encode the take: {}",
                errors.join("; ")
            ))
        }
    })?;
    if rule == Some(Keep::Animation) {
        decision.reason += " (keep=animation: only codecs that keep the channel values competed)";
    }
    decision.keep = rule;
    if let Some((h, key, plan)) = learning {
        if plan.explore {
            let sizes = encodings
                .iter()
                .map(|(c, e)| (*c, e.stored_bytes))
                .collect();
            h.record(&key, sizes);
        }
        let best = encodings
            .iter()
            .map(|(_, e)| e.stored_bytes)
            .min()
            .unwrap_or(0);
        decision.pruned = plan
            .pruned
            .into_iter()
            .map(|p| history::Pruned {
                estimated_bytes: Some((best as f64 * p.median_ratio).round() as usize),
                ..p
            })
            .collect();
        if !decision.pruned.is_empty() {
            let names: Vec<String> = decision
                .pruned
                .iter()
                .map(|p| p.codec.to_string())
                .collect();
            decision.reason += &format!(
                "; not encoded: {} (the layout's earlier takes say they would lose; see pruned)",
                names.join(", ")
            );
        }
    }
    let (_, enc) = encodings
        .into_iter()
        .find(|(c, _)| *c == decision.winner)
        .expect("the winner was encoded");
    Ok((decision, enc))
}
