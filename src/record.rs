//! `iwsim record`: an observer that writes what it sees of a running session to an MCAP file,
//! on another machine through the session's Zenoh bridge (`--zenoh`) or on this one.
//!
//! It sees what a viewer sees: each tick's world (every robot's true pose, flags and
//! standing), the robots' info and the map. It writes them on the hub recorder's Foxglove
//! channels (`/lab`, `/robots`, `/tf`, `/proximity`), so `iwsim plot`, Foxglove and any MCAP
//! reader take the file as they take a hub's. Through the bridge it gets every lock-step tick
//! (the bridge is one of the hub's agents, and puts each tick's world before answering it); on
//! the hub's machine it reads the newest snapshot, as a viewer does, so in real time it gets
//! every tick but in lock-step only those it sees, and says how many it missed (the hub waits
//! for no observer: `iwsim hub --record` records a whole lock-step run). What it cannot see (the agents' actions, the
//! seed, the noise) is the replay journal: the file says so in an `iwsim.observed` metadata
//! record, and `iwsim replay` refuses it rather than replay nothing.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use agent_sdk::AgentError;
use agent_sdk::cli::{RemoteArgs, SessionArgs};
use anyhow::Context as _;
use ipc_types::RunState;
use recorder::journal::RunStart;
use recorder::{OBSERVED_METADATA_NAME, Recorder, RecorderOptions};

/// Options of `iwsim record`.
#[derive(Debug, clap::Args)]
#[command(mut_arg("session", |a| a.help("Session of the hub to record")))]
pub struct RecordArgs {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// `--zenoh`, `--zenoh-config`: record a hub on another machine, through its Zenoh bridge
    /// (started with `--observers world`).
    #[command(flatten)]
    pub remote: RemoteArgs,
    /// The MCAP file to write (replaced if it exists).
    #[arg(long, value_name = "FILE", default_value = "run.mcap")]
    pub out: PathBuf,
}

/// Records until the run finishes, the hub (or its bridge) goes away, or SIGINT/SIGTERM; the
/// file is whole in every case.
pub fn record(args: &RecordArgs) -> anyhow::Result<ExitCode> {
    let session = &args.hub.session;
    let remote = args.remote.remote();
    let source = match &remote {
        Some(r) => format!("the Zenoh bridge at {}", r.endpoint),
        None => "shared memory on the hub's machine".to_owned(),
    };
    let mut observer = match &remote {
        Some(r) => observer::Observer::connect_zenoh(r, session, args.hub.timeout()),
        None => {
            agent_sdk::remote::install_stop_handlers();
            let name = format!("iwsim-record-{}", std::process::id());
            observer::Observer::connect_within(session, &name, args.hub.timeout())
        }
    }
    .with_context(|| format!("observing session {session:?} through {source}"))?;
    let result = write(&mut observer, args, &source);
    observer.close();
    result
}

fn write(observer: &mut observer::Observer, args: &RecordArgs, source: &str) -> anyhow::Result<ExitCode> {
    let session = &args.hub.session;
    let (header, items) = observer.map_items()?;
    let (lab, grid, obstacle_from, checkpoints) =
        hub::core::unpack_map(&header, &items).map_err(|e| anyhow::anyhow!("the observers' map: {e}"))?;
    let p = header.params;
    // What the map says of the run; the rest of the parameters (noise seeds, sensor latencies)
    // are the hub's to know, and no replay reads them from this file.
    let params = world::map::Params {
        sim_time_ticks: p.sim_time_ticks,
        cycle_ms: header.cycle_ms,
        ..world::map::Params::default()
    };
    let start = RunStart {
        iwsim_version: env!("CARGO_PKG_VERSION").to_owned(),
        seed: 0,
        dt_s: f64::from(header.cycle_ms) / 1000.0,
        lockstep: p.lockstep != 0,
        tick_limit: p.sim_time_ticks,
        cycle_ms: header.cycle_ms,
        deadline_ms: p.deadline_ms,
        lab,
        params,
        grid,
        obstacle_from,
        checkpoints,
    };
    let options = RecorderOptions {
        // Every frame that arrives is written: the observer, not the hub, waits for the disk.
        keep_every_frame: true,
        wall_clock_start: Some(std::time::SystemTime::now()),
        ..RecorderOptions::default()
    };
    let mut rec = Recorder::create(&args.out, &start, options)?;
    rec.metadata(
        OBSERVED_METADATA_NAME,
        BTreeMap::from([
            ("source".to_owned(), source.to_owned()),
            ("session".to_owned(), session.clone()),
            ("journal".to_owned(), "none: an observer sees no actions, seed or noise".to_owned()),
        ]),
    );
    agent_sdk::report!("iwsim record: recording session {session:?} through {source} to {}", args.out.display());
    let mut last: Option<u64> = None;
    let (mut first, mut frames, mut missed) = (None, 0u64, 0u64);
    let ended = loop {
        let Some((h, robots)) = observer.next_world()? else {
            match observer.check_alive() {
                Ok(()) => {
                    // Snapshots come at most once a tick; a millisecond's nap costs none.
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                }
                Err(AgentError::Interrupted) => break "interrupted",
                Err(AgentError::HubGone { .. } | AgentError::BridgeGone(_)) => break "the hub went away",
                Err(e) => return Err(e.into()),
            }
        };
        // A tick published again (an agent joined within it) is written once.
        if last.is_some_and(|t| h.tick <= t) {
            continue;
        }
        if let Some(t) = last {
            missed += h.tick - t - 1;
        }
        last = Some(h.tick);
        first.get_or_insert(h.tick);
        let infos = observer.robot_infos_covering(&robots)?.to_vec();
        rec.world(h.tick, &robots, &infos);
        frames += 1;
        if h.run_state == RunState::Finished as u32 {
            break "the run finished";
        }
    };
    let stats = rec.finish()?;
    let ticks = match (first, last) {
        (Some(a), Some(b)) => format!("ticks {a}..={b}"),
        _ => "no tick".to_owned(),
    };
    println!(
        "iwsim record: {frames} world frames of session {session:?} ({ticks}, {missed} missed) to {} ({} bytes); \
         {ended}",
        args.out.display(),
        stats.bytes
    );
    Ok(ExitCode::SUCCESS)
}
