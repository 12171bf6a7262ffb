//! Several ranges, of one take or many, in one answer (`GET /v1/ranges`): what a training
//! loader reads. A shuffled batch of one-second windows touches as many takes as it has
//! windows, and one request per window costs the client more than the server's decode of
//! it (the Python client measured 1.6 ms of its own CPU per request against 0.6 ms of the
//! server's); one request per batch pays that once.
//!
//! Each part is the answer `GET /v1/takes/{id}/frames` gives for its range with the
//! request's points, format and transforms, opened one after the other: the answer holds
//! one part's reservation at a time (two while the last pieces of one are written), never
//! the batch's. Everything a part could be refused for is checked before the first is
//! opened, by the check its answer opens with ([`answer::check`]: the take exists, the
//! range lies in it, the points are in it, the transforms suit it, the answer fits the
//! limit), with the caller's access to each take and the batch's total against one
//! answer's limit — so a batch is refused whole with a 4xx, not cut off part way; only a
//! take deleted meanwhile, a fault, or a budget still full after [`PART_WAIT`] cuts it
//! short.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;

use super::access::{self, Grant};
use super::answer::{self, Answer, RangeRequest};
use super::budget::{Budget, Holder};
use super::fetch::TimeRange;
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
    /// The skeleton every part is put on (its joints' places), as `skeleton=` on a range.
    pub onto: Option<Arc<super::retarget::Target>>,
    pub feet: super::retarget::Feet,
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
    let mut reachable: HashSet<&str> = HashSet::new();
    let mut samples = 0u64;
    for part in &request.parts {
        if part.end <= part.start {
            return Err(Error::InvalidRequest(format!(
                "range {}:{}-{} holds no frames (END is the frame after the last)",
                part.id, part.start, part.end
            )));
        }
        if reachable.insert(&part.id) {
            access::check_take(store, grant, &part.id).await?;
        }
        // The part's own request, checked as its answer will open it.
        let one = part_request(&request, part, transform);
        samples += answer::check(store, caches, limits, &part.id, &one).await?;
    }
    // One request may not ask for more than one answer may hold: the parts are decoded in
    // turn, so memory is bounded anyway, but the time one request holds a decoder is not.
    limits::check(
        "the batch's samples (frames × points)",
        samples,
        limits.answer_samples,
    )
    .map_err(|why| Error::InvalidRequest(format!("{why}: ask for fewer or shorter ranges")))?;
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

/// A part's request: its range, with the batch's points, format and transforms.
fn part_request(batch: &RangesRequest, part: &Part, transform: Options) -> RangeRequest {
    RangeRequest {
        range: TimeRange::Frames {
            start: part.start,
            end: Some(part.end),
        },
        points: batch.points.clone(),
        format: batch.format,
        transform,
        onto: batch.onto.clone(),
        feet: batch.feet,
    }
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
        let request = part_request(&self.request, part, self.transform);
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
