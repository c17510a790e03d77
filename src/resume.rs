//! `iwsim resume NAME`: the operator's word that lifts a physical chair's latched stop. The
//! chair's adapter drives it again only on this word (or with `--auto-resume`), and only once
//! every cause of the stop has cleared; a word given while a cause holds is refused, and the
//! adapter says why.

use std::process::ExitCode;

use agent_sdk::cli::SessionArgs;
use anyhow::{Context as _, bail};
use ipc_types::Command;

/// Options of `iwsim resume`.
#[derive(Debug, clap::Args)]
pub struct ResumeArgs {
    /// The chair: its name in the hub (`iwsim serial --robot NAME`) or its robot id.
    #[arg(value_name = "CHAIR")]
    pub chair: String,
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
}

/// Finds the chair by name (or id) in the session's world and asks the hub to resume it.
pub fn resume(args: &ResumeArgs) -> anyhow::Result<ExitCode> {
    let session = &args.hub.session;
    let name = format!("iwsim-resume-{}", std::process::id());
    let mut observer = observer::Observer::connect_within(session, &name, args.hub.timeout())
        .with_context(|| format!("connecting to the hub of session {session:?}"))?;
    // Names come with the robots' info, published beside the world.
    let robots = observer
        .world()
        .and_then(|(_, robots)| Ok(observer.robot_infos_covering(&robots)?.to_vec()))
        .with_context(|| format!("reading the world of session {session:?}"));
    observer.close();
    let robots = robots?;
    let by_name = robots.iter().find(|r| r.name.as_str() == Some(args.chair.as_str()));
    let Some(robot) = by_name.or_else(|| {
        let id: u32 = args.chair.parse().ok()?;
        robots.iter().find(|r| r.robot_id == id)
    }) else {
        let names: Vec<&str> = robots.iter().filter_map(|r| r.name.as_str()).collect();
        bail!("no robot {:?} in session {session:?} (its robots: {})", args.chair, names.join(", "));
    };
    let (label, robot_id) = (robot.name.as_str().unwrap_or("?").to_owned(), robot.robot_id);
    let answer = agent_sdk::control_within(session, Command::ResumeChair, robot_id, args.hub.timeout())
        .with_context(|| format!("asking the hub of session {session:?} to resume {label}"))?;
    match answer.status {
        0 => {
            println!(
                "iwsim resume: asked to resume {label} (robot {}); its adapter drives it again once every cause of \
                 its stop has cleared, and says so",
                robot_id
            );
            Ok(ExitCode::SUCCESS)
        }
        3 => bail!("{label} (robot {}) is not a physical chair: it has no stop to resume", robot_id),
        2 => bail!("{label} (robot {}) left the world before the hub got the word", robot_id),
        s => bail!("the hub refused to resume {label} (status {s})"),
    }
}
