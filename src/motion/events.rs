//! Events marked on a take: a foot strike, a foot off, a trigger — a context (the side or
//! limb), a label and a time, as C3D's `EVENT` group holds them.

use serde::{Deserialize, Serialize};

/// One event. `time_s` is seconds from the take's first frame's clock (C3D's
/// `EVENT:TIMES` minutes × 60 + seconds, as the file states it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    pub context: String,
    pub label: String,
    pub time_s: f64,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub subject: String,
}
