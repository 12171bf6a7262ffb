//! A take's labels: a small map of key → value that says what the take is of (its content,
//! style, subject, trial …), beside its free-form tags. Datasets publish them in sidecar
//! files (Bandai Namco's `{"content": 7, "style": 0}` beside each BVH) or in their file
//! names (`dataset-1_walk_happy_001`); a library filters on them (`label.content=walk`).
//!
//! A value is text or a number. Both are compared by their canonical text
//! ([`Label::canonical`]): `label.style=0` finds a style of `0` given as a number or as
//! text, and `7`, `7.0` and `7e0` are one number. Keys and values are checked here against
//! the limits in [`crate::limits`] before anything is stored: keys are short words
//! (`[A-Za-z0-9_.-]`, so that `label.<key>=` and `key:value` read them unambiguously).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::limits::{MAX_LABELS, MAX_LABEL_KEY_CHARS, MAX_LABEL_VALUE_CHARS};

/// A label's value. A whole number is written as one (`7`, not `7.0`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Label {
    Number(f64),
    Text(String),
}

impl Serialize for Label {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            // Exactly representable: below 2^53 every whole f64 is an integer.
            Label::Number(n) if n.fract() == 0.0 && n.abs() < 9.0e15 => s.serialize_i64(*n as i64),
            Label::Number(n) => s.serialize_f64(*n),
            Label::Text(t) => s.serialize_str(t),
        }
    }
}

impl Label {
    /// A value written as text (a query, a file name): a number when it is one written
    /// plainly (`7`, `-0.5`, `1e3`), else text.
    pub fn from_text(s: &str) -> Label {
        let plain = !s.is_empty()
            && s.bytes()
                .all(|b| b.is_ascii_digit() || matches!(b, b'-' | b'+' | b'.' | b'e' | b'E'))
            && s.bytes().any(|b| b.is_ascii_digit());
        match s.parse::<f64>() {
            Ok(n) if plain && n.is_finite() => Label::Number(n),
            _ => Label::Text(s.to_string()),
        }
    }

    /// The text it is stored, compared and filtered by: a whole number without a point
    /// (`7`), another number in Rust's shortest round-trip form (`0.5`), text as it is.
    pub fn canonical(&self) -> String {
        match self {
            Label::Number(n) if n.fract() == 0.0 && n.abs() < 9.0e15 => format!("{}", *n as i64),
            Label::Number(n) => format!("{n}"),
            Label::Text(t) => t.clone(),
        }
    }

    /// The value a stored row holds: `number` says which it was.
    pub fn from_stored(value: &str, number: bool) -> Result<Label, String> {
        if !number {
            return Ok(Label::Text(value.to_string()));
        }
        match value.parse::<f64>() {
            Ok(n) if n.is_finite() => Ok(Label::Number(n)),
            _ => Err(format!("a number label holds {value:?}")),
        }
    }

    pub fn is_number(&self) -> bool {
        matches!(self, Label::Number(_))
    }

    fn check(&self, key: &str) -> Result<(), String> {
        match self {
            Label::Number(n) if !n.is_finite() => Err(format!("label {key}: {n} is not a number")),
            Label::Number(_) => Ok(()),
            Label::Text(t) => {
                let n = t.chars().count();
                if n == 0 || n > MAX_LABEL_VALUE_CHARS {
                    Err(format!(
                        "label {key}: a value has 1 to {MAX_LABEL_VALUE_CHARS} characters, not {n}"
                    ))
                } else if t.chars().any(char::is_control) {
                    Err(format!("label {key}: its value holds a control character"))
                } else {
                    Ok(())
                }
            }
        }
    }
}

/// A key a label may have: 1 to [`MAX_LABEL_KEY_CHARS`] of `A-Z a-z 0-9 _ . -`, starting
/// with a letter or digit.
pub fn check_key(key: &str) -> Result<(), String> {
    let ok = !key.is_empty()
        && key.len() <= MAX_LABEL_KEY_CHARS
        && key
            .bytes()
            .next()
            .is_some_and(|b| b.is_ascii_alphanumeric())
        && key
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'-'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "label key {key:?}: a key is 1 to {MAX_LABEL_KEY_CHARS} letters, digits, '_', '.' \
             or '-', starting with a letter or digit"
        ))
    }
}

/// A take's labels, by key.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Labels(BTreeMap<String, Label>);

impl Labels {
    pub fn new() -> Labels {
        Labels::default()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn get(&self, key: &str) -> Option<&Label> {
        self.0.get(key)
    }

    pub fn iter(&self) -> impl Iterator<Item = (&String, &Label)> {
        self.0.iter()
    }

    /// Set one label, checked.
    pub fn insert(&mut self, key: &str, value: Label) -> Result<(), String> {
        check_key(key)?;
        value.check(key)?;
        self.0.insert(key.to_string(), value);
        self.check_count()
    }

    /// `other`'s labels over these (its value wins for a key both have).
    pub fn merge(&mut self, other: &Labels) -> Result<(), String> {
        for (k, v) in &other.0 {
            self.0.insert(k.clone(), v.clone());
        }
        self.check_count()
    }

    /// Every key and value checked, and their number (a stored record, a deserialised one).
    pub fn check(&self) -> Result<(), String> {
        for (k, v) in &self.0 {
            check_key(k)?;
            v.check(k)?;
        }
        self.check_count()
    }

    fn check_count(&self) -> Result<(), String> {
        if self.0.len() > MAX_LABELS {
            return Err(format!(
                "a take has at most {MAX_LABELS} labels, these are {}",
                self.0.len()
            ));
        }
        Ok(())
    }

    /// Labels as a query or a header gives them: `content:walk,style:happy` (values read by
    /// [`Label::from_text`]), or a JSON object (`{"content": "walk", "style": 0}`).
    pub fn parse(s: &str) -> Result<Labels, String> {
        let s = s.trim();
        if s.starts_with(['{', '[']) {
            let v: serde_json::Value =
                serde_json::from_str(s).map_err(|e| format!("labels: not a JSON object: {e}"))?;
            return Labels::from_json(&v);
        }
        let mut out = Labels::new();
        for pair in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = pair
                .split_once(':')
                .ok_or_else(|| format!("labels: {pair:?} is not key:value"))?;
            out.insert(k.trim(), Label::from_text(v.trim()))?;
        }
        Ok(out)
    }

    /// Labels from a JSON object (a sidecar file, a request body): strings and numbers as
    /// they are, true/false as text, a nested object's fields under `outer.inner`. A list
    /// or a null is refused, naming the key.
    pub fn from_json(v: &serde_json::Value) -> Result<Labels, String> {
        let serde_json::Value::Object(map) = v else {
            return Err("labels: not a JSON object of key → value".into());
        };
        let mut out = Labels::new();
        out.add_json("", map)?;
        Ok(out)
    }

    fn add_json(
        &mut self,
        prefix: &str,
        map: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<(), String> {
        use serde_json::Value as J;
        for (k, v) in map {
            let key = format!("{prefix}{k}");
            match v {
                J::String(s) => self.insert(&key, Label::Text(s.clone()))?,
                J::Number(n) => {
                    let n = n
                        .as_f64()
                        .ok_or_else(|| format!("label {key}: {n} is not a number we keep"))?;
                    self.insert(&key, Label::Number(n))?
                }
                J::Bool(b) => self.insert(&key, Label::Text(b.to_string()))?,
                J::Object(inner) => self.add_json(&format!("{key}."), inner)?,
                J::Array(_) | J::Null => {
                    return Err(format!(
                        "label {key}: a value is text or a number, not {}",
                        if v.is_null() { "null" } else { "a list" }
                    ))
                }
            }
        }
        Ok(())
    }
}

/// A change of a take's labels (a `PATCH`'s `labels`): each key set to its value, or
/// removed (JSON `null`); the take's other labels kept.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LabelChanges(Vec<(String, Option<Label>)>);

impl LabelChanges {
    /// From a JSON object: key → text, number, true/false, or null (remove).
    pub fn from_json(v: &serde_json::Value) -> Result<LabelChanges, String> {
        let serde_json::Value::Object(map) = v else {
            return Err("labels: not a JSON object of key → value (null removes)".into());
        };
        let mut out = Vec::with_capacity(map.len());
        for (k, v) in map {
            check_key(k)?;
            if v.is_null() {
                out.push((k.clone(), None));
                continue;
            }
            let one = serde_json::Value::Object([(k.clone(), v.clone())].into_iter().collect());
            let parsed = Labels::from_json(&one)?;
            match parsed.get(k) {
                Some(l) if parsed.len() == 1 => out.push((k.clone(), Some(l.clone()))),
                _ => return Err(format!("label {k}: a value is text or a number")),
            }
        }
        if out.len() > MAX_LABELS {
            return Err(format!(
                "a take has at most {MAX_LABELS} labels, this changes {}",
                out.len()
            ));
        }
        Ok(LabelChanges(out))
    }

    /// `labels` with these changes made, checked.
    pub fn apply(&self, labels: &Labels) -> Result<Labels, String> {
        let mut out = labels.clone();
        for (k, v) in &self.0 {
            match v {
                Some(v) => {
                    check_key(k)?;
                    v.check(k)?;
                    out.0.insert(k.clone(), v.clone());
                }
                None => {
                    out.0.remove(k);
                }
            }
        }
        out.check_count()?;
        Ok(out)
    }
}

/// A file-name pattern that labels takes by their names: `{dataset}_{content}_{style}_{n}`
/// reads `dataset-1_walk_happy_001` as dataset `dataset-1`, content `walk`, style `happy`,
/// n 1. Each `{key}` takes the shortest text up to the literal that follows it (the last
/// one takes the rest); `{}` matches without labelling. Two fields with nothing between
/// them could split anywhere: refused.
#[derive(Debug, Clone, PartialEq)]
pub struct NamePattern {
    parts: Vec<Part>,
}

#[derive(Debug, Clone, PartialEq)]
enum Part {
    Literal(String),
    /// A field and its key (`None`: matched, not kept).
    Field(Option<String>),
}

impl NamePattern {
    pub fn parse(pattern: &str) -> Result<NamePattern, String> {
        let mut parts = Vec::new();
        let mut rest = pattern;
        while !rest.is_empty() {
            match rest.find('{') {
                Some(0) => {
                    let end = rest
                        .find('}')
                        .ok_or_else(|| format!("name pattern {pattern:?}: a '{{' is not closed"))?;
                    let key = &rest[1..end];
                    if matches!(parts.last(), Some(Part::Field(_))) {
                        return Err(format!(
                            "name pattern {pattern:?}: two fields with nothing between them"
                        ));
                    }
                    let key = match key {
                        "" | "_" => None,
                        k => {
                            check_key(k).map_err(|e| format!("name pattern {pattern:?}: {e}"))?;
                            Some(k.to_string())
                        }
                    };
                    parts.push(Part::Field(key));
                    rest = &rest[end + 1..];
                }
                Some(i) => {
                    parts.push(Part::Literal(rest[..i].to_string()));
                    rest = &rest[i..];
                }
                None => {
                    parts.push(Part::Literal(rest.to_string()));
                    rest = "";
                }
            }
        }
        if parts
            .iter()
            .any(|p| matches!(p, Part::Literal(l) if l.contains('}')))
        {
            return Err(format!("name pattern {pattern:?}: a '}}' opens nothing"));
        }
        if !parts.iter().any(|p| matches!(p, Part::Field(Some(_)))) {
            return Err(format!("name pattern {pattern:?} names no field ({{key}})"));
        }
        Ok(NamePattern { parts })
    }

    /// The labels `name` (a file's stem) gives, or `None` if it does not match.
    pub fn labels(&self, name: &str) -> Option<Labels> {
        let mut out = Labels::new();
        let mut rest = name;
        let mut i = 0;
        while i < self.parts.len() {
            match &self.parts[i] {
                Part::Literal(l) => rest = rest.strip_prefix(l.as_str())?,
                Part::Field(key) => {
                    let value = match self.parts.get(i + 1) {
                        Some(Part::Literal(next)) => {
                            let at = rest.find(next.as_str())?;
                            let (v, after) = rest.split_at(at);
                            rest = after;
                            v
                        }
                        _ => std::mem::take(&mut rest),
                    };
                    if value.is_empty() {
                        return None;
                    }
                    if let Some(k) = key {
                        out.insert(k, Label::from_text(value)).ok()?;
                    }
                }
            }
            i += 1;
        }
        rest.is_empty().then_some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_read_as_numbers_only_when_written_as_numbers() {
        assert_eq!(Label::from_text("7"), Label::Number(7.0));
        assert_eq!(Label::from_text("-0.5"), Label::Number(-0.5));
        assert_eq!(Label::from_text("001"), Label::Number(1.0));
        for text in ["walk", "inf", "NaN", "1e999", "7a", "-", "e"] {
            assert_eq!(Label::from_text(text), Label::Text(text.into()), "{text}");
        }
        assert_eq!(Label::Number(7.0).canonical(), "7");
        assert_eq!(Label::from_text("7e0").canonical(), "7");
        assert_eq!(Label::Number(0.25).canonical(), "0.25");
        let l = Labels::parse("n:7,x:0.5,t:walk").unwrap();
        assert_eq!(
            serde_json::to_string(&l).unwrap(),
            r#"{"n":7,"t":"walk","x":0.5}"#
        );
        assert_eq!(Label::from_stored("7", true), Ok(Label::Number(7.0)));
        assert!(Label::from_stored("seven", true).is_err());
    }

    #[test]
    fn labels_parse_from_a_query_or_json() {
        let l = Labels::parse("content:walk, style:happy,n:3").unwrap();
        assert_eq!(l.get("content"), Some(&Label::Text("walk".into())));
        assert_eq!(l.get("n"), Some(&Label::Number(3.0)));
        let j = Labels::parse(r#"{"content": 7, "style": 0, "ok": true, "subject": {"id": "s1"}}"#)
            .unwrap();
        assert_eq!(j.get("content"), Some(&Label::Number(7.0)));
        assert_eq!(j.get("ok"), Some(&Label::Text("true".into())));
        assert_eq!(j.get("subject.id"), Some(&Label::Text("s1".into())));
        // What cannot be a label is named.
        for (bad, names) in [
            ("content", "key:value"),
            ("a b:c", "a b"),
            (":x", "\"\""),
            (r#"{"a": [1]}"#, "list"),
            (r#"{"a": null}"#, "null"),
            (r#"{"a": ""}"#, "1 to"),
            ("[1]", "JSON"),
        ] {
            let e = Labels::parse(bad).unwrap_err();
            assert!(e.contains(names), "{bad}: {e}");
        }
        let many: Vec<String> = (0..=MAX_LABELS).map(|i| format!("k{i}:v")).collect();
        assert!(Labels::parse(&many.join(","))
            .unwrap_err()
            .contains("at most"));
        let long = format!("k:{}", "x".repeat(MAX_LABEL_VALUE_CHARS + 1));
        assert!(Labels::parse(&long).is_err());
        assert!(Labels::parse("k:a\u{7}b").is_err());
    }

    #[test]
    fn changes_set_and_remove_labels() {
        let had = Labels::parse("content:walk,style:happy").unwrap();
        let c = LabelChanges::from_json(&serde_json::json!({"style": null, "n": 2})).unwrap();
        let now = c.apply(&had).unwrap();
        assert_eq!(now, Labels::parse("content:walk,n:2").unwrap());
        assert!(LabelChanges::from_json(&serde_json::json!({"n": {"a": 1}})).is_err());
        assert!(LabelChanges::from_json(&serde_json::json!({"a b": 1})).is_err());
        assert!(LabelChanges::from_json(&serde_json::json!([1])).is_err());
    }

    #[test]
    fn a_name_pattern_labels_dataset_names() {
        let p = NamePattern::parse("{dataset}_{content}_{style}_{n}").unwrap();
        let l = p.labels("dataset-1_walk_happy_001").unwrap();
        assert_eq!(l.get("dataset"), Some(&Label::Text("dataset-1".into())));
        assert_eq!(l.get("content"), Some(&Label::Text("walk".into())));
        assert_eq!(l.get("style"), Some(&Label::Text("happy".into())));
        assert_eq!(l.get("n"), Some(&Label::Number(1.0)));
        // The last field takes the rest; a name that does not fit gives none.
        assert_eq!(
            p.labels("d_c_s_1_2").unwrap().get("n"),
            Some(&Label::Text("1_2".into()))
        );
        assert!(p.labels("dataset-1_walk").is_none());
        assert!(p.labels("a__b_c").is_none(), "an empty field");
        let p = NamePattern::parse("{subject}-{}-trial{trial}").unwrap();
        let l = p.labels("S01-walk-trial12").unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l.get("trial"), Some(&Label::Number(12.0)));
        assert!(p.labels("S01-walk-take12").is_none());
        for bad in ["{a}{b}", "{a", "plain", "{a b}", "a}b{c}"] {
            assert!(NamePattern::parse(bad).is_err(), "{bad}");
        }
    }
}
