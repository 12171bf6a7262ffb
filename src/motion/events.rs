//! Events marked on a take: a foot strike, a foot off, a trigger — a context (the side or
//! limb), a label and a time, as C3D's `EVENT` group holds them.

use serde::{Deserialize, Serialize};

/// One event. `time_s` is the time the file states (C3D's `EVENT:TIMES`, minutes × 60 +
/// seconds, on the trial's clock: frame `n` of the trial is at `(n − 1) / rate`); `frame`
/// is the take's frame it falls on (0 is the take's first; it may lie outside the take).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    pub context: String,
    pub label: String,
    pub time_s: f64,
    pub frame: i64,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub subject: String,
}
