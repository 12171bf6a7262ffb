//! Where an archive's bytes go: each table of the database by what it holds (motion,
//! records, indexes) and the free pages, as the database counts them
//! ([`crate::store::DatabaseBytes`]). Part of `GET /v1/stats` and `mocapstore stats`.

use serde::Serialize;

use super::Result;
use crate::store::Store;

/// What a table holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Holds {
    /// Coded motion: chunk payloads (points, analog), model outputs, shared bases.
    Motion,
    /// What is said of takes and of the server: take rows, tags, labels, error series,
    /// skeletons, tokens, the audit log, jobs.
    Records,
    /// What finds rows and motion: every index, and the search features of takes.
    Indexes,
}

/// The tables of coded motion.
const MOTION: &[&str] = &["chunks", "analog_chunks", "take_outputs", "bases"];
/// Derived to find motion by motion (`/v1/search`): an index in all but name.
const SEARCH: &[&str] = &["take_features"];

impl Holds {
    fn of(table: &str, index: bool) -> Holds {
        if index || SEARCH.contains(&table) {
            Holds::Indexes
        } else if MOTION.contains(&table) {
            Holds::Motion
        } else {
            Holds::Records
        }
    }
}

/// One table or index and its bytes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectUse {
    pub name: String,
    pub table: String,
    pub holds: Holds,
    pub bytes: i64,
    /// Of those, bytes in its pages that no row uses (SQLite only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unused_bytes: Option<i64>,
}

/// The database's bytes by what they hold.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Storage {
    pub total_bytes: i64,
    pub motion_bytes: i64,
    pub record_bytes: i64,
    pub index_bytes: i64,
    /// Free pages kept for reuse (SQLite's free list; `null` on Postgres, which keeps free
    /// room inside each table).
    pub free_bytes: Option<i64>,
    /// Every table and index, largest first.
    pub objects: Vec<ObjectUse>,
}

/// The database's bytes now.
pub async fn storage(store: &Store) -> Result<Storage> {
    let db = store.database_bytes().await?;
    let mut objects: Vec<ObjectUse> = db
        .objects
        .into_iter()
        .map(|o| ObjectUse {
            holds: Holds::of(&o.table, o.index),
            name: o.name,
            table: o.table,
            bytes: o.bytes,
            unused_bytes: o.unused,
        })
        .collect();
    objects.sort_by(|a, b| b.bytes.cmp(&a.bytes).then_with(|| a.name.cmp(&b.name)));
    let sum = |h: Holds| {
        objects
            .iter()
            .filter(|o| o.holds == h)
            .map(|o| o.bytes)
            .sum()
    };
    Ok(Storage {
        total_bytes: db.total,
        motion_bytes: sum(Holds::Motion),
        record_bytes: sum(Holds::Records),
        index_bytes: sum(Holds::Indexes),
        free_bytes: db.free,
        objects,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_sorted_by_what_they_hold() {
        assert_eq!(Holds::of("chunks", false), Holds::Motion);
        assert_eq!(Holds::of("chunks", true), Holds::Indexes);
        assert_eq!(Holds::of("take_features", false), Holds::Indexes);
        assert_eq!(Holds::of("takes", false), Holds::Records);
        assert_eq!(Holds::of("sqlite_schema", false), Holds::Records);
    }
}
