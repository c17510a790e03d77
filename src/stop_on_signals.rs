//! SIGINT, SIGTERM and SIGHUP as a flag, for commands that own no iceoryx2 node (whose handlers would
//! otherwise catch them) and poll for the end of their work, such as the chair emulator.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    // Only an atomic store: the one thing a signal handler may safely do here.
    STOP.store(true, Ordering::SeqCst);
}

/// Installs the handlers and returns the flag they set. SA_RESTART keeps interrupted reads
/// from failing; the command's own polls see the flag.
pub fn install() -> std::io::Result<&'static AtomicBool> {
    os::signals::on_signals(&[libc::SIGINT, libc::SIGTERM, libc::SIGHUP], on_signal, true)?;
    Ok(&STOP)
}
