//! `iwsim view`: the live viewer.

use std::process::ExitCode;
use std::time::Duration;

use viewer::{Viewer, ViewerConfig};

use crate::cli::ViewArgs;

/// Serves the viewer until the hub ends the run.
pub fn run(args: &ViewArgs) -> anyhow::Result<ExitCode> {
    let v = Viewer::start(ViewerConfig {
        session: args.session.clone(),
        http: args.http,
        allow_control: args.allow_control,
        connect_timeout: Duration::from_secs_f64(args.connect_timeout.max(0.0)),
    })?;
    let addr = v.local_addr().unwrap_or(args.http);
    eprintln!("iwsim view: session {:?}, open http://{addr}/", args.session);
    v.run()?;
    Ok(ExitCode::SUCCESS)
}
