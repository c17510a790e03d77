//! The scenario runner behind `iwsim run` and `iwsim demo`: a scenario file ([`scenario`])
//! becomes a run of real processes — the hub, every agent and (unless headless) the viewer —
//! whose outcome is a summary ([`run`]) written as `summary.json` and judged against the
//! scenario's expectations. A signal to the runner ([`signals`]) stops every process of the
//! run, and a process that fails before the run's end stops the rest. A scenario with a
//! `[chair]` adds a physical chair — the chair emulator behind the serial adapter ([`chair`])
//! — and its contacts in the emulator's room to the summary.
//!
//! ```
//! let slalom = runner::scenario::Scenario::load("builtin:slalom").expect("built in");
//! assert_eq!(slalom.checkpoints.len(), 2);
//! ```
#![warn(missing_docs)]

pub mod args;
pub mod chair;
pub mod crowd;
pub mod demo;
pub mod metrics;
pub mod run;
pub mod scenario;
pub mod signals;

pub use args::{DemoArgs, RunArgs};
