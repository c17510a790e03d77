//! The formats iwsim writes and reads as text, each defined once for its writer and every
//! reader: per-robot CSV logs ([`log`]), comma-separated option values ([`args`]), a scenario's
//! obstacles and checkpoints ([`places`]), the hub's outcome line ([`outcome`]), a run's
//! `summary.json` ([`summary`]) and latency percentiles ([`latency`]), plus the one capped
//! reader of the text files users write ([`files`]).
//!
//! ```
//! let pose = records::args::pose("10,6.1,-90").expect("a pose");
//! assert_eq!(pose, [10.0, 6.1, -90.0]);
//! ```
#![warn(missing_docs)]

pub mod args;
pub mod files;
pub mod latency;
pub mod log;
pub mod outcome;
pub mod places;
pub mod summary;

/// `value` to `places` decimals, rounded exactly as `format!("{:.places$}")` prints it, so that
/// JSON written through serde keeps the figures the hand-written formats had.
fn round_to(value: f64, places: usize) -> f64 {
    format!("{value:.places$}").parse().unwrap_or(value)
}

/// One line of JSON for a value of one of this crate's types.
fn to_json<T: serde::Serialize>(value: &T) -> String {
    // Only a map with non-string keys or a failing `Serialize` impl can make serde_json fail;
    // the types here have neither, so an error is a bug in this crate.
    serde_json::to_string(value).expect("records' types always serialise to JSON")
}

/// The last line of `text` that is a JSON object (starts with `{`) and passes `wanted`.
fn last_json_line(text: &str, wanted: impl Fn(&str) -> bool) -> Option<&str> {
    text.lines().map(str::trim).rev().find(|l| l.starts_with('{') && wanted(l))
}
