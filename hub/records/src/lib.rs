//! The formats iwsim writes and reads as text, each defined once for its writer and every
//! reader: per-robot CSV logs ([`log`]), comma-separated option values ([`args`]).
//!
//! ```
//! let pose = records::args::pose("10,6.1,-90").expect("a pose");
//! assert_eq!(pose, [10.0, 6.1, -90.0]);
//! ```
#![warn(missing_docs)]

pub mod args;
pub mod latency;
pub mod log;
