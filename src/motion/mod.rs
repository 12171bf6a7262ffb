//! The motion model and everything that reads, writes or measures it. Pure: bytes and
//! numbers in, bytes and numbers out; no files, no async, no database.

pub mod analog;
pub mod body;
pub mod decimal;
pub mod error;
pub mod events;
pub mod features;
pub mod format;
pub mod formats;
pub mod layout;
pub mod metrics;
pub mod model;
pub mod moments;
pub mod nearest;
pub mod outputs;
pub mod rate;
pub mod retarget;
pub mod retrieval;
pub mod rigs;
pub mod rotation;
pub mod similar;
pub mod skeleton;
pub mod synthetic;
pub mod transform;
pub mod units;

pub use error::{Error, Location, Result};
pub use layout::LayoutSignature;
pub use model::Motion;
pub use skeleton::{Animation, Channel, Joint};
pub use units::{Unit, UnitSource};
