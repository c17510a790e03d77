//! The UDP/XML bridge: serves the Ciber-Rato / Intellwheels protocol to remote agents and
//! viewers, and drives their robots on a hub through the agent SDK.
#![warn(missing_docs)]

pub mod cli;
pub mod codec;
pub mod noise;
pub mod server;

pub use server::{Bridge, BridgeConfig, BridgeError, Counters, Viewers};
