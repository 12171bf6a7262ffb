//! The library as a whole: listings with filters and cursors, statistics, edits.

use std::collections::BTreeMap;

use serde::Serialize;

use super::access::Grant;
use super::take::Take;
use super::{Error, Result};
use crate::codec::CodecId;
use crate::limits::MAX_TAKES_PAGE;
use crate::store::{Cursor, Filter, SortKey, Store, TakeRow, Totals};

/// Which takes a listing, statistics or an export is of, as a caller asks: each field a
/// condition every take must meet, checked ([`TakeQuery::check`]) before the store sees it.
/// A listing's query string reads as one (its other fields are the page's).
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
pub struct TakeQuery {
    pub library: Option<String>,
    pub tag: Option<String>,
    /// `label.<key>=<value>` conditions, as (key, value) given: not a field of the query
    /// string's shape, so the HTTP layer reads them apart ([`TakeQuery::with_labels`]).
    #[serde(skip)]
    pub labels: Vec<(String, String)>,
    pub name_prefix: Option<String>,
    pub layout: Option<String>,
    pub codec: Option<CodecId>,
    /// Takes of this stored skeleton (its id, `/v1/skeletons`).
    pub skeleton: Option<String>,
    pub fps: Option<f64>,
    pub points: Option<u64>,
    pub min_duration_s: Option<f64>,
    pub max_duration_s: Option<f64>,
    pub min_frames: Option<u64>,
    pub max_frames: Option<u64>,
    pub min_ratio: Option<f64>,
    /// Milliseconds since the Unix epoch.
    pub created_after: Option<i64>,
    pub created_before: Option<i64>,
}

/// The takes a filter matches, oldest first, a page of rows at a time ([`MAX_TAKES_PAGE`]):
/// how a whole selection is read (an export, motion statistics) without holding it whole.
pub struct Pages<'a> {
    store: &'a Store,
    filter: Filter,
    cursor: Option<Cursor>,
    done: bool,
}

impl<'a> Pages<'a> {
    pub fn new(store: &'a Store, filter: Filter) -> Pages<'a> {
        Pages {
            store,
            filter,
            cursor: None,
            done: false,
        }
    }

    /// The next page's rows; `None` after the last.
    pub async fn next(&mut self) -> Result<Option<Vec<TakeRow>>> {
        if self.done {
            return Ok(None);
        }
        let page = self
            .store
            .list(
                &self.filter,
                SortKey::Created,
                false,
                MAX_TAKES_PAGE,
                self.cursor.as_ref(),
            )
            .await?;
        self.cursor = page.next;
        self.done = self.cursor.is_none();
        Ok(Some(page.items))
    }
}

impl TakeQuery {
    /// This query with the `label.<key>=<value>` pairs of `pairs` (a query string's, in
    /// order; others ignored).
    pub fn with_labels<'a>(mut self, pairs: impl IntoIterator<Item = (&'a str, &'a str)>) -> Self {
        self.labels = pairs
            .into_iter()
            .filter_map(|(k, v)| Some((k.strip_prefix("label.")?.to_string(), v.to_string())))
            .collect();
        self
    }

    /// A 400 for a condition no take could meet because it is not a value of its kind (a
    /// negative duration, an fps out of range), rather than an empty answer.
    pub fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidRequest(m));
        if self.labels.len() > crate::limits::MAX_LABELS {
            return bad(format!(
                "at most {} label conditions, not {}",
                crate::limits::MAX_LABELS,
                self.labels.len()
            ));
        }
        for (k, _) in &self.labels {
            crate::labels::check_key(k).map_err(Error::InvalidRequest)?;
        }
        if let Some(c) = self.codec.filter(|c| c.is_analog()) {
            return bad(format!("{c} codes analog channels, not takes"));
        }
        if let Some(f) = self.fps {
            crate::limits::fps(f).map_err(Error::InvalidRequest)?;
        }
        for (name, v) in [
            ("min_duration_s", self.min_duration_s),
            ("max_duration_s", self.max_duration_s),
            ("min_ratio", self.min_ratio),
        ] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v >= 0.0)) {
                return bad(format!("{name} must be a number ≥ 0, got {v}"));
            }
        }
        // Beyond i64 a count matches no stored take, and would not bind.
        for (name, v) in [
            ("points", self.points),
            ("min_frames", self.min_frames),
            ("max_frames", self.max_frames),
        ] {
            if let Some(v) = v.filter(|v| i64::try_from(*v).is_err()) {
                return bad(format!("{name} {v} is beyond any take"));
            }
        }
        Ok(())
    }

    /// The store's filter of these takes among those `grant` reaches.
    pub fn filter(&self, grant: &Grant) -> Filter {
        let count = |v: Option<u64>| v.map(|v| i64::try_from(v).unwrap_or(i64::MAX));
        grant.restrict(Filter {
            library: self.library.clone(),
            tag: self.tag.clone(),
            labels: self
                .labels
                .iter()
                .map(|(k, v)| (k.clone(), crate::labels::Label::from_text(v).canonical()))
                .collect(),
            name_prefix: self.name_prefix.clone(),
            fps: self.fps,
            points: count(self.points),
            layout: self.layout.clone(),
            codec: self.codec.map(|c| c.to_string()),
            skeleton: self.skeleton.clone(),
            min_duration_s: self.min_duration_s,
            max_duration_s: self.max_duration_s,
            min_frames: count(self.min_frames),
            max_frames: count(self.max_frames),
            min_ratio: self.min_ratio,
            created_after: self.created_after,
            created_before: self.created_before,
            within: None,
        })
    }
}

/// How a listing is ordered and which page of it is asked for.
#[derive(Debug, Clone, Default)]
pub struct Page {
    pub sort: SortKey,
    /// `None`: newest first for the default sort, else ascending.
    pub descending: Option<bool>,
    pub limit: Option<usize>,
    pub cursor: Option<String>,
}

/// One page of takes and the cursor of the next.
#[derive(Debug, Clone, Serialize)]
pub struct Listing {
    pub items: Vec<Take>,
    pub next_cursor: Option<String>,
}

/// One page of the takes of `query` that `grant` reaches.
pub async fn list(store: &Store, grant: &Grant, query: &TakeQuery, page: Page) -> Result<Listing> {
    query.check()?;
    let filter = query.filter(grant);
    let Page {
        sort,
        descending,
        limit,
        cursor,
    } = page;
    let descending = descending.unwrap_or(sort == SortKey::Created);
    let cursor = cursor.as_deref();
    let limit = limit.unwrap_or(50);
    if limit == 0 || limit > MAX_TAKES_PAGE {
        return Err(Error::InvalidRequest(format!(
            "limit must be 1..={MAX_TAKES_PAGE}, got {limit}"
        )));
    }
    let cursor = match cursor {
        None => None,
        Some(c) => {
            let c = Cursor::decode(c).ok_or_else(|| {
                Error::InvalidRequest("cursor is not one this server issued".into())
            })?;
            if c.sort != sort || c.descending != descending {
                return Err(Error::InvalidRequest(
                    "cursor belongs to a listing with another sort order".into(),
                ));
            }
            Some(c)
        }
    };
    let page = store
        .list(&filter, sort, descending, limit, cursor.as_ref())
        .await?;
    let mut items = Vec::with_capacity(page.items.len());
    for row in page.items {
        items.push(super::fetch::parse(store, row).await?);
    }
    Ok(Listing {
        items,
        next_cursor: page.next.map(|c| c.encode()),
    })
}

/// Every take matching `filter`, oldest first (training selections, export): an error if
/// any of their records does not parse.
pub async fn all_takes(store: &Store, filter: &Filter) -> Result<Vec<Take>> {
    let mut out = Vec::new();
    for row in all_rows(store, filter).await? {
        out.push(super::fetch::parse(store, row).await?);
    }
    Ok(out)
}

/// The stored rows of every take matching `filter`, oldest first, read a page at a time
/// (verify parses each itself, reporting those that do not parse).
pub async fn all_rows(store: &Store, filter: &Filter) -> Result<Vec<TakeRow>> {
    let mut out = Vec::new();
    let mut cursor = None;
    loop {
        let page = store
            .list(
                filter,
                SortKey::Created,
                false,
                MAX_TAKES_PAGE,
                cursor.as_ref(),
            )
            .await?;
        out.extend(page.items);
        match page.next {
            Some(c) => cursor = Some(c),
            None => return Ok(out),
        }
    }
}

/// Library-wide statistics: totals, and the same per codec and per library.
#[derive(Debug, Clone, Serialize)]
pub struct Stats {
    pub total: Totals,
    pub by_codec: BTreeMap<String, Totals>,
    pub by_library: BTreeMap<String, Totals>,
    /// The whole database's bytes by what they hold, for a caller who reaches every
    /// library (they are every library's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub storage: Option<super::storage::Storage>,
}

/// Statistics of the takes of `query` that `grant` reaches.
pub async fn stats(store: &Store, grant: &Grant, query: &TakeQuery) -> Result<Stats> {
    query.check()?;
    let rows = store.stat_rows(&query.filter(grant)).await?;
    let mut codecs: Vec<&str> = rows.iter().map(|r| r.codec.as_str()).collect();
    codecs.sort();
    codecs.dedup();
    let mut libraries: Vec<&str> = rows.iter().map(|r| r.library.as_str()).collect();
    libraries.sort();
    libraries.dedup();
    let storage = match grant.libraries {
        None => Some(super::storage::storage(store).await?),
        Some(_) => None,
    };
    Ok(Stats {
        storage,
        total: crate::store::query::totals(rows.iter()),
        by_codec: codecs
            .iter()
            .map(|c| {
                (
                    c.to_string(),
                    crate::store::query::totals(rows.iter().filter(|r| r.codec == *c)),
                )
            })
            .collect(),
        by_library: libraries
            .iter()
            .map(|l| {
                (
                    l.to_string(),
                    crate::store::query::totals(rows.iter().filter(|r| r.library == *l)),
                )
            })
            .collect(),
    })
}

/// Delete a take (its chunks and tags with it); what servers cached of it is dropped when
/// next asked for ([`super::prepared::ReadCaches::current`]). A
/// take a live stream is still recording is not deleted (409): finish the stream first.
pub async fn delete(store: &Store, id: &str) -> Result<()> {
    if let Some(row) = store.get(id).await? {
        // Read as stored: a take whose record does not parse can still be deleted.
        if row.live_until.is_some() {
            return Err(Error::Conflict(format!(
                "take {id} is being recorded by a live stream; finish the stream first"
            )));
        }
    }
    let deleted = store.delete(id).await?;
    if deleted {
        Ok(())
    } else {
        Err(Error::NotFound(format!("take {id}")))
    }
}

/// What a `PATCH` of a take changes: each field given, the rest kept.
#[derive(Debug, Clone, Default)]
pub struct Edit {
    pub name: Option<String>,
    pub library: Option<String>,
    /// Its tags, all of them.
    pub tags: Option<Vec<String>>,
    /// Labels set or removed; the others kept.
    pub labels: Option<crate::labels::LabelChanges>,
    pub body: Option<super::body::Correction>,
}

/// Rename, move to another library, replace the tags of, relabel and/or correct the body
/// of a take. Everything is checked before anything is written: a refused request changes
/// nothing. Labels are merged into the take's as read: of two edits of one take's labels
/// at the same moment, the later one's set stands (as with tags).
pub async fn update(store: &Store, id: &str, edit: Edit) -> Result<Take> {
    if edit.name.as_ref().is_some_and(|n| n.trim().is_empty()) {
        return Err(Error::InvalidRequest("name must not be empty".into()));
    }
    let labels = match &edit.labels {
        Some(changes) => {
            let take = super::fetch::take(store, id).await?;
            let labels = changes.apply(&take.labels).map_err(Error::InvalidRequest)?;
            Some(super::take::label_rows(&labels))
        }
        None => None,
    };
    if let Some(c) = edit.body {
        super::body::correct(store, id, c).await?;
    }
    let tags = edit.tags.as_deref().map(super::normalise_tags);
    let change = crate::store::TakeEdit {
        name: edit.name.as_deref(),
        library: edit.library.as_deref(),
        tags: tags.as_deref(),
        labels: labels.as_deref(),
    };
    if !store.update(id, &change).await? {
        return Err(Error::NotFound(format!("take {id}")));
    }
    super::body::take(store, id).await
}
