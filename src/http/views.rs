//! What the API shows of the service's records: a view per record, so that the stored
//! record, the domain type and the body a client reads can each change on their own.

use serde::Serialize;

use crate::service::library::Listing;
use crate::service::take::Take;

/// A take as `GET /v1/sequences/{id}` and listings show it: the take's record (its header
/// bytes and lease stay inside) and whether a live stream is still recording it.
#[derive(Serialize)]
pub struct TakeView<'a> {
    #[serde(flatten)]
    take: &'a Take,
    live: bool,
    /// What the take costs on disk (container, metadata row and keys), beside
    /// `stored_bytes` (the container alone).
    disk_bytes: u64,
}

impl<'a> From<&'a Take> for TakeView<'a> {
    fn from(take: &'a Take) -> Self {
        TakeView {
            take,
            live: take.is_live(),
            disk_bytes: take.disk_bytes().unwrap_or(take.stored_bytes),
        }
    }
}

/// One page of a listing.
#[derive(Serialize)]
pub struct ListingView<'a> {
    items: Vec<TakeView<'a>>,
    next_cursor: Option<&'a str>,
}

impl<'a> From<&'a Listing> for ListingView<'a> {
    fn from(l: &'a Listing) -> Self {
        ListingView {
            items: l.items.iter().map(TakeView::from).collect(),
            next_cursor: l.next_cursor.as_deref(),
        }
    }
}
