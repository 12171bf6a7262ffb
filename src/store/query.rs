//! Library queries: filters, sorting, keyset (cursor) pagination, and aggregate statistics.
//! SQL is assembled with numbered placeholders and the values bound in order, so one text
//! serves both backends.

use serde::{Deserialize, Serialize};

/// Filters on takes; every field is optional and they combine with AND.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
pub struct Filter {
    pub library: Option<String>,
    pub tag: Option<String>,
    /// Labels every take has: (key, canonical value) pairs.
    #[serde(default)]
    pub labels: Vec<(String, String)>,
    pub name_prefix: Option<String>,
    pub fps: Option<f64>,
    pub points: Option<i64>,
    pub layout: Option<String>,
    pub codec: Option<String>,
    /// Takes of this stored skeleton (its id).
    pub skeleton: Option<String>,
    pub min_duration_s: Option<f64>,
    pub max_duration_s: Option<f64>,
    pub min_frames: Option<i64>,
    pub max_frames: Option<i64>,
    pub min_ratio: Option<f64>,
    /// Milliseconds since the Unix epoch.
    pub created_after: Option<i64>,
    pub created_before: Option<i64>,
    /// Only takes in these libraries (an access limit, not a user's filter); an empty list
    /// matches nothing.
    pub within: Option<Vec<String>>,
}

/// Sort keys; every sort ends with the id, so pages are stable.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SortKey {
    #[default]
    Created,
    Name,
    Duration,
    Frames,
    Ratio,
}

impl SortKey {
    fn column(self) -> &'static str {
        match self {
            SortKey::Created => "created_at",
            SortKey::Name => "name",
            SortKey::Duration => "duration_s",
            SortKey::Frames => "frames",
            SortKey::Ratio => "ratio",
        }
    }
}

/// A value to bind, in placeholder order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Value {
    Int(i64),
    Real(f64),
    Text(String),
}

/// Where the previous page ended: the sort value and key of its last take (the store's
/// integer key: takes of equal values come in the order they were stored, and the
/// library's indexes end with it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cursor {
    pub sort: SortKey,
    pub descending: bool,
    pub value: Value,
    pub key: i64,
}

impl Cursor {
    /// Opaque to clients: hex of its JSON.
    pub fn encode(&self) -> String {
        serde_json::to_string(self)
            .expect("serialisable")
            .bytes()
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    pub fn decode(s: &str) -> Option<Cursor> {
        if !s.len().is_multiple_of(2) || s.len() > 4096 {
            return None;
        }
        let bytes: Option<Vec<u8>> = (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
            .collect();
        serde_json::from_slice(&bytes?).ok()
    }
}

/// A `WHERE` clause and its values, numbered from `$1`.
pub struct Sql {
    pub text: String,
    pub values: Vec<Value>,
}

impl Sql {
    fn push(&mut self, clause: &str, v: Value) {
        self.values.push(v);
        let n = self.values.len();
        self.text += &format!(" AND {}", clause.replace('?', &format!("${n}")));
    }
}

/// `WHERE …` for a filter (and, for a page, the cursor).
pub fn where_clause(f: &Filter, cursor: Option<&Cursor>) -> Sql {
    let mut s = Sql {
        text: "WHERE 1 = 1".into(),
        values: Vec::new(),
    };
    if let Some(v) = &f.library {
        s.push("library = ?", Value::Text(v.clone()));
    }
    if let Some(libraries) = &f.within {
        if libraries.is_empty() {
            s.text += " AND 1 = 0";
        }
        let mut marks = Vec::with_capacity(libraries.len());
        for l in libraries {
            s.values.push(Value::Text(l.clone()));
            marks.push(format!("${}", s.values.len()));
        }
        if !marks.is_empty() {
            s.text += &format!(" AND library IN ({})", marks.join(", "));
        }
    }
    if let Some(v) = &f.tag {
        s.push(
            "key IN (SELECT take_key FROM take_tags WHERE tag = ?)",
            Value::Text(v.clone()),
        );
    }
    for (k, v) in &f.labels {
        s.values.push(Value::Text(k.clone()));
        let key = s.values.len();
        s.push(
            &format!("key IN (SELECT take_key FROM take_labels WHERE key = ${key} AND value = ?)"),
            Value::Text(v.clone()),
        );
    }
    if let Some(v) = &f.name_prefix {
        // Range on the name rather than LIKE: no wildcard escaping, and it uses an index.
        s.push("name >= ?", Value::Text(v.clone()));
        s.push("name < ?", Value::Text(format!("{v}\u{10FFFF}")));
    }
    if let Some(v) = f.fps {
        // Frame rates like 120.00048 come from 1/frame-time; match to 0.1 %.
        s.push("fps >= ?", Value::Real(v * 0.999));
        s.push("fps <= ?", Value::Real(v * 1.001));
    }
    if let Some(v) = f.points {
        s.push("points = ?", Value::Int(v));
    }
    if let Some(v) = &f.layout {
        s.push("layout = ?", Value::Text(v.clone()));
    }
    if let Some(v) = &f.codec {
        s.push("codec = ?", Value::Text(v.clone()));
    }
    if let Some(v) = &f.skeleton {
        s.push("skeleton_id = ?", Value::Text(v.clone()));
    }
    for (v, clause) in [
        (f.min_duration_s, "duration_s >= ?"),
        (f.max_duration_s, "duration_s <= ?"),
        (f.min_ratio, "ratio >= ?"),
    ] {
        if let Some(v) = v {
            s.push(clause, Value::Real(v));
        }
    }
    for (v, clause) in [
        (f.min_frames, "frames >= ?"),
        (f.max_frames, "frames <= ?"),
        (f.created_after, "created_at > ?"),
        (f.created_before, "created_at < ?"),
    ] {
        if let Some(v) = v {
            s.push(clause, Value::Int(v));
        }
    }
    if let Some(c) = cursor {
        let col = c.sort.column();
        let op = if c.descending { "<" } else { ">" };
        s.values.push(c.value.clone());
        s.values.push(Value::Int(c.key));
        let n = s.values.len();
        s.text += &format!(" AND ({col}, key) {op} (${}, ${n})", n - 1);
    }
    s
}

/// `ORDER BY …` for a sort.
pub fn order_by(sort: SortKey, descending: bool) -> String {
    let dir = if descending { "DESC" } else { "ASC" };
    format!("ORDER BY {} {dir}, key {dir}", sort.column())
}

/// The cursor value of a row for a sort key.
pub fn sort_value(sort: SortKey, row: &super::TakeRow) -> Value {
    match sort {
        SortKey::Created => Value::Int(row.created_at),
        SortKey::Name => Value::Text(row.name.clone()),
        SortKey::Duration => Value::Real(row.totals.duration_s),
        SortKey::Frames => Value::Int(row.totals.frames),
        SortKey::Ratio => Value::Real(row.totals.ratio),
    }
}

/// Totals over a set of takes.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Totals {
    pub takes: i64,
    pub frames: i64,
    pub hours: f64,
    pub raw_bytes: i64,
    pub stored_bytes: i64,
    /// raw_bytes / stored_bytes over the set (not the mean of per-take ratios).
    pub ratio: f64,
    /// What the takes cost on disk: `stored_bytes` plus their rows' metadata and keys
    /// ([`super::rows::disk_bytes`]); shared skeletons and bases are counted apart.
    pub disk_bytes: i64,
    /// raw_bytes / disk_bytes: the ratio the disk pays.
    pub disk_ratio: f64,
    pub mean_mm: f64,
    pub max_mm: f64,
    /// Percentiles of the per-take max error.
    pub max_mm_p50: f64,
    pub max_mm_p95: f64,
    /// The takes' points alone (raw: 12 bytes a sample; stored: their containers).
    pub points: Part,
    /// Their analog channels alone (raw: the bytes the files stored them in).
    pub analog: Part,
    /// Their files' parameter sections, compressed: stored, not part of either ratio.
    pub parameters_bytes: i64,
}

/// Sizes of one part of the takes: what was uploaded, what is stored, and the ratio.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Part {
    pub raw_bytes: i64,
    pub stored_bytes: i64,
    pub ratio: f64,
}

impl Part {
    fn finish(&mut self) {
        if self.stored_bytes > 0 {
            self.ratio = self.raw_bytes as f64 / self.stored_bytes as f64;
        }
    }
}

/// One take's numbers, enough to aggregate.
#[derive(Debug, Clone, PartialEq)]
pub struct StatRow {
    pub library: String,
    pub codec: String,
    pub frames: i64,
    pub points: i64,
    pub duration_s: f64,
    pub raw_bytes: i64,
    pub stored_bytes: i64,
    pub disk_bytes: i64,
    pub mean_mm: f64,
    pub max_mm: f64,
    pub analog_raw_bytes: i64,
    pub analog_stored_bytes: i64,
    pub parameters_bytes: i64,
}

pub fn totals<'a>(rows: impl Iterator<Item = &'a StatRow>) -> Totals {
    let rows: Vec<&StatRow> = rows.collect();
    let mut t = Totals {
        takes: rows.len() as i64,
        ..Totals::default()
    };
    let mut samples = 0f64;
    let mut maxes: Vec<f64> = Vec::with_capacity(rows.len());
    for r in &rows {
        t.frames += r.frames;
        t.hours += r.duration_s / 3600.0;
        t.raw_bytes += r.raw_bytes;
        t.stored_bytes += r.stored_bytes;
        t.disk_bytes += r.disk_bytes;
        t.analog.raw_bytes += r.analog_raw_bytes;
        t.analog.stored_bytes += r.analog_stored_bytes;
        t.parameters_bytes += r.parameters_bytes;
        t.points.raw_bytes += r.raw_bytes - r.analog_raw_bytes;
        t.points.stored_bytes += r.stored_bytes - r.analog_stored_bytes - r.parameters_bytes;
        let n = (r.frames * r.points) as f64;
        t.mean_mm += r.mean_mm * n;
        samples += n;
        t.max_mm = t.max_mm.max(r.max_mm);
        maxes.push(r.max_mm);
    }
    if samples > 0.0 {
        t.mean_mm /= samples;
    }
    if t.disk_bytes > 0 {
        t.disk_ratio = t.raw_bytes as f64 / t.disk_bytes as f64;
    }
    if t.stored_bytes > 0 {
        t.ratio = t.raw_bytes as f64 / t.stored_bytes as f64;
    }
    t.points.finish();
    t.analog.finish();
    maxes.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        if maxes.is_empty() {
            0.0
        } else {
            maxes[((maxes.len() - 1) as f64 * p).round() as usize]
        }
    };
    t.max_mm_p50 = pct(0.5);
    t.max_mm_p95 = pct(0.95);
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cursors_round_trip_and_reject_garbage() {
        let c = Cursor {
            sort: SortKey::Ratio,
            descending: true,
            value: Value::Real(12.5),
            key: 7,
        };
        assert_eq!(Cursor::decode(&c.encode()), Some(c));
        assert_eq!(Cursor::decode("zz"), None);
        assert_eq!(Cursor::decode("abc"), None);
    }

    #[test]
    fn where_clause_numbers_placeholders_in_order() {
        let f = Filter {
            library: Some("cmu".into()),
            min_frames: Some(10),
            ..Filter::default()
        };
        let c = Cursor {
            sort: SortKey::Name,
            descending: false,
            value: Value::Text("m".into()),
            key: 3,
        };
        let s = where_clause(&f, Some(&c));
        assert_eq!(
            s.text,
            "WHERE 1 = 1 AND library = $1 AND frames >= $2 AND (name, key) > ($3, $4)"
        );
        assert_eq!(s.values.len(), 4);
    }

    #[test]
    fn totals_weight_errors_by_samples() {
        let row = |frames, mean, max| StatRow {
            library: "l".into(),
            codec: "quant".into(),
            frames,
            points: 10,
            duration_s: frames as f64 / 100.0,
            raw_bytes: frames * 120,
            stored_bytes: frames * 12,
            disk_bytes: frames * 15,
            mean_mm: mean,
            max_mm: max,
            analog_raw_bytes: frames * 20,
            analog_stored_bytes: frames * 2,
            parameters_bytes: 100,
        };
        let rows = [row(100, 1.0, 2.0), row(300, 2.0, 4.0)];
        let t = totals(rows.iter());
        assert_eq!((t.takes, t.frames), (2, 400));
        assert!((t.mean_mm - 1.75).abs() < 1e-12);
        assert_eq!((t.max_mm, t.ratio, t.disk_ratio), (4.0, 10.0, 8.0));
        // The split: analog, parameters, and the points as the rest.
        assert_eq!((t.analog.raw_bytes, t.analog.stored_bytes), (8000, 800));
        assert_eq!(t.parameters_bytes, 200);
        assert_eq!((t.points.raw_bytes, t.points.stored_bytes), (40_000, 3800));
        assert_eq!(t.analog.ratio, 10.0);
    }
}
