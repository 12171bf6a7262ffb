#![allow(dead_code)] // each test crate that includes it uses a part
//! `tests/bodies/up.csv`: the true up axis of every corpus file, written from each source's
//! documentation and an independent forward kinematics (`scripts/bvh-fk.py`), not from our
//! code; and the frames where a body is upside down. Shared by the tests that check
//! bodies (`tests/bodies.rs`, `tests/service/bodies.rs`).

use std::collections::BTreeMap;
use std::path::Path;

use mocapstore::motion::body::Axis;

/// One manifest row: the true up axis of a corpus file and the frames where the head is
/// not above the ankles (handstands, falls, lying down; end inclusive).
pub struct Truth {
    pub up: Axis,
    pub upside_down: Vec<(usize, usize)>,
}

pub fn manifest() -> BTreeMap<String, Truth> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bodies/up.csv");
    let text = std::fs::read_to_string(&path).expect("tests/bodies/up.csv");
    let mut rows = csv_rows(&text).into_iter();
    let head = rows.next().expect("a header");
    let col = |name: &str| head.iter().position(|h| h == name).expect(name);
    let (p, u, d) = (col("path"), col("up"), col("upside_down_frames"));
    rows.map(|r| {
        let upside_down = r[d]
            .split(';')
            .filter(|s| !s.trim().is_empty())
            .map(|s| {
                let (a, b) = s.trim().split_once('-').expect("a-b");
                (a.parse().unwrap(), b.parse().unwrap())
            })
            .collect();
        let up = r[u].parse().unwrap_or_else(|e| panic!("{}: {e}", r[p]));
        (r[p].clone(), Truth { up, upside_down })
    })
    .collect()
}

/// Rows of a CSV with quoted fields.
fn csv_rows(text: &str) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let (mut row, mut field, mut quoted) = (Vec::new(), String::new(), false);
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '"' if quoted && chars.peek() == Some(&'"') => {
                    field.push('"');
                    chars.next();
                }
                '"' => quoted = !quoted,
                ',' if !quoted => row.push(std::mem::take(&mut field)),
                _ => field.push(c),
            }
        }
        row.push(field);
        rows.push(row);
    }
    rows
}

impl Truth {
    /// Whether the body is upside down in `frame` (a handstand, a kick, a fall).
    pub fn upside_down_at(&self, frame: usize) -> bool {
        self.upside_down
            .iter()
            .any(|&(a, b)| (a..=b).contains(&frame))
    }
}
