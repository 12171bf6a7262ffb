//! Several ranges, of one take or many, in one answer (`GET /v1/ranges`): what a training
//! loader reads. A shuffled batch of one-second windows touches as many takes as it has
//! windows, and one request per window costs the client more than the server's decode of
//! it (the Python client measured 1.6 ms of its own CPU per request against 0.6 ms of the
//! server's); one request per batch pays that once.
//!
//! Each part is the answer `GET /v1/sequences/{id}/frames` gives for its range with the
//! request's points, format and transforms, opened one after the other: the answer holds
//! one part's reservation at a time (two while the last pieces of one are written), never
//! the batch's. Everything a part could be refused for is checked before the first is
//! opened — each take exists and the caller may read it, each range lies in its take,
//! each point is in each take, each part fits the answer limit — so a batch is refused
//! whole with a 4xx, not cut off part way; only a take deleted meanwhile, a fault, or a
//! budget still full after [`PART_WAIT`] cuts it short.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use super::access::{self, Grant};
use super::answer::{self, Answer, RangeRequest};
use super::budget::{Budget, Holder};
use super::fetch::{prepare, TimeRange};
use super::prepared::ReadCaches;
use super::{Error, Result};
use crate::limits::{self, Limits};
use crate::motion::formats::Format;
use crate::motion::transform::Options;
use crate::store::Store;

/// How long a part after the first waits for room in the answer budget: the first part's
/// refusal is the request's 503, but a batch half sent can only be cut off.
pub const PART_WAIT: Duration = Duration::from_secs(10);

/// One range of one take: frames `start..end` of its own frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Part {
    pub id: String,
    pub start: usize,
    pub end: usize,
}

/// A batch of ranges, parsed: every part answered with the same points, format and
/// transforms.
#[derive(Debug, Clone, PartialEq)]
pub struct RangesRequest {
    pub parts: Vec<Part>,
    pub points: Option<Vec<String>>,
    pub format: Format,
    pub transform: Options,
}

/// A batch, checked: its parts' answers, opened one at a time by [`Ranges::next_part`].
pub struct Ranges {
    store: Store,
    caches: Arc<ReadCaches>,
    budget: Arc<Budget>,
    holder: Holder,
    limits: Limits,
    request: RangesRequest,
    transform: Options,
    at: usize,
}

/// Check a batch (see the module doc) and ready its answer; nothing is decoded yet.
pub async fn open(
    store: &Store,
    caches: &Arc<ReadCaches>,
    budget: &Arc<Budget>,
    holder: Holder,
    limits: &Limits,
    grant: &Grant,
    request: RangesRequest,
) -> Result<Ranges> {
    if !matches!(request.format, Format::F32 | Format::Npy) {
        return Err(Error::InvalidRequest(format!(
            "a batch of ranges is answered as f32 or npy (parts of known length), not {}",
            request.format
        )));
    }
    if request.parts.is_empty() {
        return Err(Error::InvalidRequest(
            "ranges names no range: ranges=ID:START-END,…".into(),
        ));
    }
    limits::check(
        "ranges",
        request.parts.len() as u64,
        limits::MAX_RANGES as u64,
    )
    .map_err(Error::InvalidRequest)?;
    let transform = answer::transform_for(request.format, request.transform)?;
    let mut checked: HashMap<&str, usize> = HashMap::new();
    for part in &request.parts {
        if !checked.contains_key(part.id.as_str()) {
            access::check_take(store, grant, &part.id).await?;
        }
        let range = TimeRange::Frames {
            start: part.start,
            end: Some(part.end),
        };
        let (prepared, (start, end)) = prepare(store, caches, &part.id, range).await?;
        let points = match checked.get(part.id.as_str()) {
            Some(&points) => points,
            None => {
                let points = match &request.points {
                    Some(names) => answer::point_indices(&prepared, names)?.len(),
                    None => prepared.point_names.len(),
                };
                checked.insert(&part.id, points);
                points
            }
        };
        let frames = super::shape::frames_out(&prepared, &transform, end - start);
        answer::check_size(frames, points, limits)?;
    }
    Ok(Ranges {
        store: store.clone(),
        caches: caches.clone(),
        budget: budget.clone(),
        holder,
        limits: *limits,
        transform,
        request,
        at: 0,
    })
}

impl Ranges {
    /// The parts in the batch.
    pub fn len(&self) -> usize {
        self.request.parts.len()
    }

    /// Whether the batch has no parts (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.request.parts.is_empty()
    }

    /// The next part's answer, opened; `None` after the last. The first is refused at once
    /// when the budget is full (the request's 503); later ones wait up to [`PART_WAIT`].
    pub async fn next_part(&mut self) -> Result<Option<Answer>> {
        let Some(part) = self.request.parts.get(self.at) else {
            return Ok(None);
        };
        let request = RangeRequest {
            range: TimeRange::Frames {
                start: part.start,
                end: Some(part.end),
            },
            points: self.request.points.clone(),
            format: self.request.format,
            transform: self.transform,
        };
        let wait = if self.at == 0 {
            Duration::ZERO
        } else {
            PART_WAIT
        };
        let holder = self.holder.clone();
        let budget = self.budget.clone();
        let a = answer::open_waiting(
            &self.store,
            &self.caches,
            || budget.reservation(holder.clone()),
            &self.limits,
            &part.id,
            request,
            wait,
        )
        .await?;
        self.at += 1;
        Ok(Some(a))
    }
}
