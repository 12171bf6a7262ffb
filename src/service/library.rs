//! The library as a whole: listings with filters and cursors, statistics, edits.

use std::collections::BTreeMap;

use serde::Serialize;

use super::prepared::ReadCaches;
use super::take::Take;
use super::{Error, Result};
use crate::store::{Cursor, Filter, SortKey, Store, TakeRow, Totals};

pub const MAX_PAGE: usize = 500;

/// One page of takes and the cursor of the next.
#[derive(Debug, Clone, Serialize)]
pub struct Listing {
    pub items: Vec<Take>,
    pub next_cursor: Option<String>,
}

pub async fn list(
    store: &Store,
    filter: &Filter,
    sort: SortKey,
    descending: bool,
    limit: Option<usize>,
    cursor: Option<&str>,
) -> Result<Listing> {
    let limit = limit.unwrap_or(50);
    if limit == 0 || limit > MAX_PAGE {
        return Err(Error::InvalidRequest(format!(
            "limit must be 1..={MAX_PAGE}, got {limit}"
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
        .list(filter, sort, descending, limit, cursor.as_ref())
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
            .list(filter, SortKey::Created, false, MAX_PAGE, cursor.as_ref())
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
}

pub async fn stats(store: &Store, filter: &Filter) -> Result<Stats> {
    let rows = store.stat_rows(filter).await?;
    let mut codecs: Vec<&str> = rows.iter().map(|r| r.codec.as_str()).collect();
    codecs.sort();
    codecs.dedup();
    let mut libraries: Vec<&str> = rows.iter().map(|r| r.library.as_str()).collect();
    libraries.sort();
    libraries.dedup();
    Ok(Stats {
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

/// Delete a take (its chunks and tags with it) and forget what this server kept of it. A
/// take a live stream is still recording is not deleted (409): finish the stream first.
pub async fn delete(store: &Store, caches: &ReadCaches, id: &str) -> Result<()> {
    if let Some(row) = store.get(id).await? {
        // Read as stored: a take whose record does not parse can still be deleted.
        if row.live_until.is_some() {
            return Err(Error::Conflict(format!(
                "take {id} is being recorded by a live stream; finish the stream first"
            )));
        }
    }
    let deleted = store.delete(id).await?;
    caches.forget(id);
    if deleted {
        Ok(())
    } else {
        Err(Error::NotFound(format!("sequence {id}")))
    }
}

/// Rename, move to another library and/or replace the tags of a take.
pub async fn update(
    store: &Store,
    id: &str,
    name: Option<&str>,
    library: Option<&str>,
    tags: Option<&[String]>,
) -> Result<Take> {
    if name.is_some_and(|n| n.trim().is_empty()) {
        return Err(Error::InvalidRequest("name must not be empty".into()));
    }
    let tags = tags.map(super::normalise_tags);
    if !store.update(id, name, library, tags.as_deref()).await? {
        return Err(Error::NotFound(format!("sequence {id}")));
    }
    super::fetch::take(store, id).await
}
