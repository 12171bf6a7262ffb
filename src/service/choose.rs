//! Per-take codec choice: the candidates that fit the request and the take, and the record
//! of what each achieved and why the winner won.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::codec::{self, Basis, BasisKind, CodecId, Latency};
use crate::motion::Motion;

/// What the user asked for: one codec, or the smallest that meets the bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CodecRequest {
    Auto,
    Only(CodecId),
}

/// What of a skeleton take must survive coding: its animation (the channel values, so that
/// it can be served as BVH and loaded into an animation tool), or only its joint positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Keep {
    /// Only codecs that keep the channel values compete (the default: for a BVH library the
    /// animation is the data).
    #[default]
    Animation,
    /// Position codecs compete too; the smallest wins, and may keep positions only.
    Positions,
}

impl std::str::FromStr for Keep {
    type Err = String;
    fn from_str(s: &str) -> Result<Keep, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "animation" => Ok(Keep::Animation),
            "positions" => Ok(Keep::Positions),
            other => Err(format!(
                "unknown keep {other:?}; use animation or positions"
            )),
        }
    }
}

/// The codecs to run, and those left out with the reason. `bases` are the kinds of shared
/// basis trained for the take's layout: codecs that need another kind sit out. For a
/// skeleton take, `keep` says whether codecs that keep positions only may compete.
pub fn candidates(
    request: CodecRequest,
    latency: Latency,
    keep: Keep,
    m: &Motion,
    bases: &[BasisKind],
) -> (Vec<CodecId>, Vec<Skipped>) {
    if let CodecRequest::Only(c) = request {
        return (vec![c], Vec::new());
    }
    let mut run = Vec::new();
    let mut skipped = Vec::new();
    let animation = keep == Keep::Animation && m.skeleton.is_some();
    // New codecs take part by being implemented in `codec`: nothing here names one.
    for c in codec::available() {
        let channels = codec::codec(c).is_ok_and(|k| k.codes_channels());
        let why = if animation && !channels {
            Some(
                "keeps joint positions only, and keep=animation (the default for skeleton takes)"
                    .into(),
            )
        } else if c.latency() > latency {
            Some(format!(
                "latency class {:?} exceeds the requested {:?}",
                c.latency(),
                latency
            ))
        } else {
            codec::codec(c).ok().and_then(|k| match k.basis_kind() {
                Some(kind) if !bases.contains(&kind) => Some(format!(
                    "no shared {kind} basis is trained for this layout (POST /v1/bases)"
                )),
                _ => k.unsuited(m),
            })
        };
        match why {
            Some(reason) => skipped.push(Skipped { codec: c, reason }),
            None => run.push(c),
        }
    }
    (run, skipped)
}

/// The shared basis `codec` codes with, among those trained for the take's layout.
pub fn basis_for(codec: CodecId, bases: &[Arc<Basis>]) -> Option<Arc<Basis>> {
    let kind = codec::codec(codec).ok()?.basis_kind()?;
    bases.iter().find(|b| b.kind() == kind).cloned()
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skipped {
    pub codec: CodecId,
    pub reason: String,
}

/// One candidate's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tried {
    pub codec: CodecId,
    /// Stored bytes, or `None` if it failed.
    pub stored_bytes: Option<usize>,
    pub max_mm: Option<f64>,
    pub mean_mm: Option<f64>,
    pub encode_ms: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Tried {
    /// A candidate's outcome, its numbers rounded to what a reader of the record can use
    /// (0.01 ms, 10⁻⁶ mm): the record is kept with every take.
    pub fn new(
        codec: CodecId,
        outcome: std::result::Result<(usize, f64, f64), String>,
        encode_ms: f64,
    ) -> Tried {
        let round = |v: f64, k: f64| (v * k).round() / k;
        let (stored_bytes, max_mm, mean_mm, error) = match outcome {
            Ok((bytes, max, mean)) => (
                Some(bytes),
                Some(round(max, 1e6)),
                Some(round(mean, 1e6)),
                None,
            ),
            Err(e) => (None, None, None, Some(e)),
        };
        Tried {
            codec,
            stored_bytes,
            max_mm,
            mean_mm,
            encode_ms: round(encode_ms, 100.0),
            error,
        }
    }
}

/// The decision kept with the take.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Decision {
    pub winner: CodecId,
    pub reason: String,
    pub tried: Vec<Tried>,
    pub skipped: Vec<Skipped>,
    /// For a skeleton take chosen automatically: which rule chose the candidates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep: Option<Keep>,
    /// Candidates not encoded because the takes before this one say they would have lost
    /// ([`super::history`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pruned: Vec<super::history::Pruned>,
}

/// The decision for a take with no points (analog channels only): its empty point
/// container is `raw` of `stored_bytes`, and nothing competed.
pub fn no_points(stored_bytes: usize) -> Decision {
    Decision {
        winner: CodecId::Raw,
        reason: "the take has no points (analog channels only): its point container is an \
                 empty raw one"
            .into(),
        tried: vec![Tried {
            codec: CodecId::Raw,
            stored_bytes: Some(stored_bytes),
            max_mm: Some(0.0),
            mean_mm: Some(0.0),
            encode_ms: 0.0,
            error: None,
        }],
        skipped: Vec::new(),
        keep: None,
        pruned: Vec::new(),
    }
}

/// Pick the smallest successful candidate; `None` if every one failed.
pub fn decide(tried: Vec<Tried>, skipped: Vec<Skipped>, bound: &str) -> Option<Decision> {
    let mut ok: Vec<&Tried> = tried.iter().filter(|t| t.stored_bytes.is_some()).collect();
    ok.sort_by_key(|t| t.stored_bytes);
    let winner = ok.first()?;
    let reason = match ok.get(1) {
        Some(next) => format!(
            "{} is the smallest that meets {bound}: {} bytes, {:.1}% of the next best ({} at {} bytes)",
            winner.codec,
            winner.stored_bytes.unwrap_or(0),
            100.0 * winner.stored_bytes.unwrap_or(0) as f64 / next.stored_bytes.unwrap_or(1).max(1) as f64,
            next.codec,
            next.stored_bytes.unwrap_or(0)
        ),
        None => format!("{} is the only candidate that met {bound}", winner.codec),
    };
    let winner = winner.codec;
    Some(Decision {
        winner,
        reason,
        tried,
        skipped,
        keep: None,
        pruned: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::synthetic::walker;

    fn tried(codec: CodecId, bytes: Option<usize>) -> Tried {
        Tried {
            codec,
            stored_bytes: bytes,
            max_mm: bytes.map(|_| 0.9),
            mean_mm: bytes.map(|_| 0.4),
            encode_ms: 1.0,
            error: bytes.is_none().then(|| "failed".into()),
        }
    }

    #[test]
    fn latency_and_length_filter_candidates() {
        let long = walker(600, 4, 120.0, 1, 0.0);
        let (run, skipped) = candidates(
            CodecRequest::Auto,
            Latency::Sequence,
            Keep::default(),
            &long,
            &[],
        );
        assert_eq!(
            run,
            vec![CodecId::Raw, CodecId::Quant, CodecId::Mdtt, CodecId::Spca]
        );
        // Without a trained basis the shared-basis codecs sit out, and say why; so do the
        // skeleton codecs on a take of points.
        let why = |c: CodecId| {
            let s = skipped.iter().find(|s| s.codec == c);
            s.unwrap_or_else(|| panic!("{c} competes")).reason.clone()
        };
        for c in [CodecId::LsdtClip, CodecId::LsdtFrame] {
            assert!(why(c).contains("no shared lsdt basis"), "{}", why(c));
        }
        assert!(
            why(CodecId::MdttShared).contains("basis"),
            "{}",
            why(CodecId::MdttShared)
        );
        for c in [CodecId::Pga, CodecId::BvhLossless, CodecId::Rot] {
            assert!(why(c).contains("no skeleton"), "{}", why(c));
        }
        let (run, skipped) = candidates(
            CodecRequest::Auto,
            Latency::Sequence,
            Keep::default(),
            &long,
            &[BasisKind::Lsdt],
        );
        assert_eq!(
            run,
            vec![
                CodecId::Raw,
                CodecId::Quant,
                CodecId::Mdtt,
                CodecId::LsdtClip,
                CodecId::LsdtFrame,
                CodecId::Spca
            ]
        );
        // pga, bvh-lossless, rot: no skeleton; mdtt-shared: no mdtt-set basis.
        for c in [
            CodecId::Pga,
            CodecId::BvhLossless,
            CodecId::Rot,
            CodecId::MdttShared,
        ] {
            assert!(skipped.iter().any(|s| s.codec == c), "{c}");
        }
        assert_eq!(run.len() + skipped.len(), crate::codec::available().len());
        let (run, skipped) = candidates(
            CodecRequest::Auto,
            Latency::Frame,
            Keep::default(),
            &long,
            &[BasisKind::Lsdt],
        );
        assert_eq!(run, vec![CodecId::Raw, CodecId::Quant, CodecId::LsdtFrame]);
        assert_eq!(skipped[0].codec, CodecId::Mdtt);
        let short = walker(60, 4, 120.0, 1, 0.0);
        let (run, _) = candidates(
            CodecRequest::Auto,
            Latency::Sequence,
            Keep::default(),
            &short,
            &[],
        );
        assert!(!run.contains(&CodecId::Mdtt));
        let (run, _) = candidates(
            CodecRequest::Only(CodecId::Mdtt),
            Latency::Frame,
            Keep::default(),
            &short,
            &[],
        );
        assert_eq!(run, vec![CodecId::Mdtt]);
    }

    #[test]
    fn skeleton_takes_keep_their_animation_unless_asked_for_positions() {
        let m = crate::motion::synthetic::dancer(300, 60.0, 1);
        let (run, skipped) = candidates(
            CodecRequest::Auto,
            Latency::Sequence,
            Keep::Animation,
            &m,
            &[],
        );
        assert_eq!(run, vec![CodecId::Pga, CodecId::BvhLossless, CodecId::Rot]);
        let raw = skipped.iter().find(|s| s.codec == CodecId::Raw).unwrap();
        assert!(raw.reason.contains("keep=animation"), "{}", raw.reason);
        let (run, _) = candidates(
            CodecRequest::Auto,
            Latency::Sequence,
            Keep::Positions,
            &m,
            &[],
        );
        assert_eq!(
            run,
            vec![
                CodecId::Raw,
                CodecId::Quant,
                CodecId::Mdtt,
                CodecId::Spca,
                CodecId::Pga,
                CodecId::BvhLossless,
                CodecId::Rot
            ]
        );
        assert_eq!("positions".parse::<Keep>(), Ok(Keep::Positions));
        assert!("bones".parse::<Keep>().is_err());
    }

    #[test]
    fn the_smallest_success_wins_and_says_why() {
        let d = decide(
            vec![
                tried(CodecId::Raw, Some(1000)),
                tried(CodecId::Quant, Some(300)),
                tried(CodecId::Mdtt, None),
            ],
            vec![],
            "max 1 mm",
        )
        .unwrap();
        assert_eq!(d.winner, CodecId::Quant);
        assert!(
            d.reason.contains("30.0% of the next best (raw"),
            "{}",
            d.reason
        );
        assert!(decide(vec![tried(CodecId::Mdtt, None)], vec![], "max 1 mm").is_none());
    }
}
