//! iwsim's live viewer: a process that reads a hub's world over shared memory and serves a
//! page and a WebSocket stream of it to browsers on this machine or the LAN.
#![warn(missing_docs)]

pub mod cli;
pub mod frame;
pub mod server;

pub use server::{Viewer, ViewerConfig, ViewerError};
