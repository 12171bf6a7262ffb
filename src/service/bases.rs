//! Shared bases as stored objects: loading the one a take names, finding the newest for a
//! layout, listing and deleting them. Training new ones is [`super::training`].

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::access::Grant;
use super::{blocking, Error, Result};
use crate::codec::{Basis, BasisKind};
use crate::store::{BasisRow, Deletion, Store};

/// How a shared basis was made: stored with it (JSON) and shown by `/v1/bases`. One
/// definition for what training writes, what the API shows and what a token limited to
/// some libraries may see of it ([`Provenance::settings_only`]). Fields a basis was not
/// made with are absent.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// How it was trained, or, for a stream's untrained basis, how it was made.
    pub algorithm: String,
    // How it was trained: settings, shown to every caller that may see the basis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sparsity: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rank: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bound_mm: Option<f64>,
    // What it was trained on and measured there.
    /// The takes it was trained on (ids), and their frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub takes: Option<Vec<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<u64>,
    /// Training time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
    /// LSDT: the samples trained on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<usize>,
    /// MDTT set: the clips trained on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clips: Option<usize>,
    /// MDTT set: the sizes each basis count tried came to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_candidates: Option<Vec<SetSize>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub objective: Option<Objective>,
}

/// What an MDTT basis set of `k` bases cost on its training takes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetSize {
    pub k: usize,
    pub takes_bytes: u64,
    pub basis_bytes: u64,
}

/// The training objective, iteration by iteration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Objective {
    /// LSDT trains one basis per coordinate.
    PerAxis {
        x: Vec<f64>,
        y: Vec<f64>,
        z: Vec<f64>,
    },
    /// MDTT's annealing distortion.
    Series(Vec<f64>),
}

impl Provenance {
    /// How the basis was trained, not what it measured on its takes: what a token limited
    /// to some of those takes' libraries is shown, beside the takes it may see.
    pub fn settings_only(&self) -> Provenance {
        Provenance {
            algorithm: self.algorithm.clone(),
            sparsity: self.sparsity,
            max_iterations: self.max_iterations,
            tolerance: self.tolerance,
            rank: self.rank,
            k: self.k,
            bound_mm: self.bound_mm,
            ..Provenance::default()
        }
    }

    /// As the store keeps it. A training whose objective is not finite (it diverged) is
    /// refused: JSON would store null, which no reader could take for a number.
    pub fn to_value(&self) -> Result<serde_json::Value> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let objective_finite = match &self.objective {
            None => true,
            Some(Objective::Series(s)) => finite(s),
            Some(Objective::PerAxis { x, y, z }) => finite(x) && finite(y) && finite(z),
        };
        if !objective_finite {
            return Err(Error::Internal(
                "training diverged: its objective is not finite".into(),
            ));
        }
        serde_json::to_value(self).map_err(|e| Error::Internal(format!("basis provenance: {e}")))
    }
}

/// A stored basis's record (not its payload), parsed.
#[derive(Debug, Clone, PartialEq)]
pub struct BasisInfo {
    /// BLAKE3 of the payload, hex.
    pub id: String,
    pub kind: BasisKind,
    pub layout: String,
    pub points: usize,
    /// Shape, e.g. `3×31×31` (matrices × rows × columns).
    pub dims: String,
    pub provenance: Provenance,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// How many takes reference it (that the caller may see).
    pub used_by: u64,
}

impl BasisInfo {
    /// A stored record whose kind or provenance does not parse is corrupt, not a default.
    fn parse(row: BasisRow) -> Result<BasisInfo> {
        let corrupt = |what: &str, e: &dyn std::fmt::Display| {
            Error::Corrupt(format!("basis {}: {what}: {e}", row.id))
        };
        let kind = row.kind.parse().map_err(|e| corrupt("kind", &e))?;
        let provenance =
            Provenance::deserialize(&row.provenance).map_err(|e| corrupt("provenance", &e))?;
        Ok(BasisInfo {
            kind,
            points: usize::try_from(row.points).map_err(|e| corrupt("points", &e))?,
            provenance,
            used_by: row.used_by.max(0) as u64,
            id: row.id,
            layout: row.layout,
            dims: row.dims,
            created_at: row.created_at,
        })
    }
}

/// Parse a stored basis, checking that its bytes still hash to its id.
pub(super) fn parse(row: &BasisRow) -> Result<Basis> {
    let b = Basis::parse(&row.payload)
        .map_err(|e| Error::Internal(format!("stored basis {}: {e}", row.id)))?;
    if b.id() != row.id {
        return Err(Error::Internal(format!(
            "stored basis {} hashes to {}",
            row.id,
            b.id()
        )));
    }
    Ok(b)
}

/// The basis with this id (a take's header names it by hash).
pub async fn load(store: &Store, id: &str) -> Result<Arc<Basis>> {
    let row = store
        .basis(id)
        .await?
        .ok_or_else(|| Error::NotFound(format!("basis {id}")))?;
    Ok(Arc::new(blocking(move || parse(&row)).await??))
}

/// The newest basis of each kind trained for `layout`: what ingest codes takes of that
/// layout with.
pub async fn latest_for(store: &Store, layout: &str) -> Result<Vec<Arc<Basis>>> {
    let mut out = Vec::new();
    for kind in BasisKind::ALL {
        if let Some(row) = store.latest_basis(layout, kind.name()).await? {
            out.push(Arc::new(blocking(move || parse(&row)).await??));
        }
    }
    Ok(out)
}

/// Stored bases, newest first, optionally of one layout and/or kind (payloads not read).
/// A grant limited to libraries sees those its libraries' takes use or were trained from
/// ([`scoped`]).
pub async fn list(
    store: &Store,
    layout: Option<&str>,
    kind: Option<BasisKind>,
    grant: &Grant,
) -> Result<Vec<BasisInfo>> {
    let rows = store.bases(layout, kind.map(BasisKind::name)).await?;
    scoped(store, rows, grant).await
}

/// One stored basis; to a grant limited to libraries, only one of theirs ([`scoped`]; any
/// other is `NotFound`, as if it did not exist).
pub async fn get(store: &Store, id: &str, grant: &Grant) -> Result<BasisInfo> {
    let row = store.basis(id).await?;
    scoped(store, row.into_iter().collect(), grant)
        .await?
        .pop()
        .ok_or_else(|| Error::NotFound(format!("basis {id}")))
}

/// Delete a basis no take references.
pub async fn delete(store: &Store, id: &str) -> Result<()> {
    match store.delete_basis(id).await? {
        Deletion::Deleted => Ok(()),
        Deletion::NotFound => Err(Error::NotFound(format!("basis {id}"))),
        Deletion::InUse(n) => Err(Error::Conflict(format!(
            "basis {id} codes {n} stored take(s); delete them first"
        ))),
    }
}

/// The bases of `rows` a grant reaches, as it may see them. Over every library: all, as
/// stored. Limited to libraries: those that takes of its libraries use or were trained
/// from, with `used_by` counting only those takes, and a provenance that says nothing of
/// another library: its takes (and their frame total) only those in the grant's libraries,
/// and of the rest only how it was trained ([`Provenance::settings_only`]), not what it measured on the
/// whole selection (samples, clips, sizes, objective).
async fn scoped(store: &Store, rows: Vec<BasisRow>, grant: &Grant) -> Result<Vec<BasisInfo>> {
    let Some(within) = grant.within() else {
        return rows.into_iter().map(BasisInfo::parse).collect();
    };
    // Which rows the grant reaches is read from the stored takes list alone, so that a
    // record it does not reach cannot fail its listing; those it reaches are parsed whole.
    let trained = |row: &BasisRow| -> Vec<String> {
        row.provenance["takes"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|v| v.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default()
    };
    let uses = store.basis_use_within(&within).await?;
    // One lookup for every basis's takes, not one per basis.
    let mut all: Vec<String> = rows.iter().flat_map(trained).collect();
    all.sort();
    all.dedup();
    let visible = store.take_frames_within(&all, &within).await?;
    let mut out = Vec::with_capacity(rows.len());
    for row in rows {
        let takes: Vec<String> = trained(&row)
            .into_iter()
            .filter(|t| visible.contains_key(t))
            .collect();
        let used = uses.get(&row.id).copied().unwrap_or(0);
        if used == 0 && takes.is_empty() {
            continue;
        }
        let mut b = BasisInfo::parse(row)?;
        b.used_by = used.max(0) as u64;
        let mut shown = b.provenance.settings_only();
        if b.provenance.takes.is_some() {
            shown.frames = Some(takes.iter().map(|t| visible[t].max(0) as u64).sum());
            shown.takes = Some(takes);
        }
        b.provenance = shown;
        out.push(b);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Provenances as training and streams wrote them before they were typed read back
    /// and are shown field for field as stored.
    #[test]
    fn stored_provenances_read_and_show_as_written() {
        for stored in [
            json!({
                "samples": 1200, "algorithm": "LSDT (Hou et al. 2016, Algorithm 1)",
                "sparsity": 8, "max_iterations": 30, "tolerance": 1e-4,
                "objective": {"x": [3.0, 2.5], "y": [1.0], "z": [0.5]},
                "takes": ["a", "b"], "frames": 900, "seconds": 1.5,
            }),
            json!({
                "algorithm": "MDTT database mode", "clips": 40, "rank": 12,
                "k_candidates": [{"k": 1, "takes_bytes": 900, "basis_bytes": 300}],
                "k": 1, "bound_mm": 1.0, "objective": [9.0, 4.0, 3.5],
                "takes": ["a"], "frames": 300, "seconds": 0.2,
            }),
            json!({ "algorithm": "DCT-II (untrained)" }),
        ] {
            let p = Provenance::deserialize(&stored).unwrap();
            assert_eq!(p.to_value().unwrap(), stored);
        }
    }

    #[test]
    fn what_a_library_limited_token_sees_is_how_it_was_trained() {
        let p = Provenance::deserialize(&json!({
            "algorithm": "MDTT", "rank": 12, "k": 2, "bound_mm": 1.0, "clips": 40,
            "objective": [1.0], "takes": ["a"], "frames": 3, "seconds": 1.0,
        }))
        .unwrap();
        assert_eq!(
            p.settings_only().to_value().unwrap(),
            json!({"algorithm": "MDTT", "rank": 12, "k": 2, "bound_mm": 1.0})
        );
    }

    #[test]
    fn a_basis_record_that_does_not_parse_is_corrupt() {
        let row = |kind: &str, provenance: serde_json::Value| BasisRow {
            id: "b".into(),
            kind: kind.into(),
            layout: "l".into(),
            points: 3,
            dims: "1×3×3".into(),
            payload: Vec::new(),
            provenance,
            created_at: 0,
            used_by: 0,
        };
        let ok = json!({"algorithm": "x"});
        assert!(BasisInfo::parse(row("lsdt", ok.clone())).is_ok());
        for bad in [
            row("zip", ok),
            row("lsdt", json!({"rank": 3})),
            row("lsdt", json!({"algorithm": "x", "objective": "low"})),
        ] {
            assert!(matches!(BasisInfo::parse(bad), Err(Error::Corrupt(_))));
        }
        let diverged = Provenance {
            objective: Some(Objective::Series(vec![1.0, f64::NAN])),
            ..Provenance::default()
        };
        assert!(diverged.to_value().is_err());
    }
}
