//! iwsim's one OS layer: the system calls its processes make beyond what `std` offers —
//! waiting on several descriptors (`poll`), terminals and serial lines (`term`), pseudo-terminals
//! (`pty`), signals (`signals`), the monotonic clock (`clock`) and process calls (`process`).
//!
//! Built on `nix`, whose calls are safe; the few `unsafe` blocks left in the workspace's
//! processes for the operating system are here, each with why it holds. The other crates deny
//! `unsafe_code` for OS calls and come here instead, so there is one poll wrapper, one termios
//! stack and one way to install a signal handler.

pub mod clock;
pub mod fd;
pub mod poll;
pub mod process;
pub mod pty;
pub mod signals;
pub mod term;

/// A nix error as the `std::io::Error` the callers already speak.
pub(crate) fn io(e: nix::errno::Errno) -> std::io::Error {
    std::io::Error::from(e)
}
