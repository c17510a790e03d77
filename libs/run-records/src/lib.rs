//! What a run writes and its judges read, each format defined once for its writer and every
//! reader: the hub's outcome line ([`outcome`]), a run's `summary.json` ([`summary`]) and
//! latency percentiles ([`latency`]). Agents do not link it: they write only their robots'
//! logs (`robot-log`).
//!
//! ```
//! let p = run_records::latency::Percentiles::of_ns(&[1_000, 2_000, 3_000]);
//! assert_eq!(p.p50_us, 2.0);
//! ```
#![warn(missing_docs)]

pub mod latency;
pub mod outcome;
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
