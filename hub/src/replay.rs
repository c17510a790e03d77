//! `iwsim replay`: rebuilds a recorded run's world from its MCAP file and re-applies the
//! recorded changes (robots added, removed, frozen; every step's actions as the hub applied
//! them), optionally checking every tick's state hash against the recording. A real-time run
//! replays as exactly as a lock-step one, because the actions are recorded as applied, after
//! deadlines: nothing in the replay depends on timing.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use recorder::Recording;
use recorder::journal::Event;

use crate::HubOutcome;
use crate::serve::ServeOptions;
use crate::stage::{Stage, StageApplyError};

/// Options of `iwsim replay`.
#[derive(Debug, clap::Args, Clone)]
pub struct ReplayArgs {
    /// The recording (`iwsim hub --record FILE.mcap`, or `run.mcap` in a run's output folder).
    pub file: PathBuf,
    /// Compare every tick's state hash with the recording's; exit 1 naming the first tick
    /// that differs.
    #[arg(long)]
    pub check: bool,
    /// Stop after the step that reaches this tick.
    #[arg(long, value_name = "TICK")]
    pub until: Option<u64>,
    /// Print the end of the replay as one JSON object (the shape of `iwsim hub --json`).
    #[arg(long)]
    pub json: bool,
    /// Play the recording as a live session: `iwsim view`, `iwsim udp` and other observers
    /// attach to it as to a hub. Pause, Start, Step and Stop work; robots are refused.
    #[arg(long)]
    pub serve: bool,
    /// With --serve: the session to serve.
    #[arg(long, default_value = "replay", requires = "serve")]
    pub session: String,
    /// With --serve: playback rate (1 = a tick per recorded cycle, 2 = twice as fast).
    #[arg(long, value_name = "X", default_value_t = 1.0, value_parser = parse_speed, requires = "serve")]
    pub speed: f64,
    /// With --serve: start over from tick 0 at the end instead of finishing.
    #[arg(long = "loop", requires = "serve")]
    pub looped: bool,
    /// With --serve: wait for a Start (or Step) command before the first tick.
    #[arg(long, requires = "serve")]
    pub start_on_command: bool,
}

/// `--speed`: a finite number above 0.
fn parse_speed(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x > 0.0 && x.is_finite() => Ok(x),
        _ => Err("the speed must be a number above 0 (1 = the recorded cycle)".to_owned()),
    }
}

/// What a replay found.
#[derive(Debug, Clone, PartialEq)]
pub struct Replayed {
    /// The world at the end, as `iwsim hub --json` reports it.
    pub outcome: HubOutcome,
    /// Steps re-applied.
    pub steps: u64,
    /// The first step whose hash differs (with `check`).
    pub mismatch: Option<StageApplyError>,
    /// Where a cut-short file ends and what was lost.
    pub truncated: Option<String>,
}

/// Replays `recording` up to `until`, checking hashes when `check` is set.
pub fn replay(recording: &Recording, check: bool, until: Option<u64>) -> anyhow::Result<Replayed> {
    replay_observed(recording, check, until, |_| {})
}

/// Like [`replay`], calling `observe` with the world as it stands before the first step and
/// after every step: how the runner judges a run from its record.
pub fn replay_observed(
    recording: &Recording,
    check: bool,
    until: Option<u64>,
    mut observe: impl FnMut(&Stage),
) -> anyhow::Result<Replayed> {
    let start = &recording.start;
    let mut stage = Stage::new(&start.lab, start.params.clone(), start.seed, start.tick_limit)
        .context("rebuilding the recorded world")?;
    anyhow::ensure!(
        stage.dt_s() == start.dt_s,
        "the recording steps {} s a tick but its parameters give {} s",
        start.dt_s,
        stage.dt_s()
    );
    let mut steps = 0;
    let mut mismatch = None;
    for event in &recording.events {
        if let Event::Step { tick, .. } = event
            && until.is_some_and(|u| *tick >= u)
        {
            break;
        }
        if steps == 0 && matches!(event, Event::Step { .. }) {
            observe(&stage);
        }
        match stage.apply(event, check) {
            Ok(Some(_)) => {
                steps += 1;
                observe(&stage);
            }
            Ok(None) => {}
            Err(e @ StageApplyError::HashDiffers { .. }) => {
                mismatch = Some(e);
                break;
            }
            Err(e) => return Err(e.into()),
        }
    }
    let outcome = stage.outcome();
    Ok(Replayed { outcome, steps, mismatch, truncated: recording.truncated.clone() })
}

/// `iwsim replay`.
pub fn run(args: &ReplayArgs) -> anyhow::Result<ExitCode> {
    let recording = Recording::open(&args.file).with_context(|| format!("reading {}", args.file.display()))?;
    if let Some(from) = recording.metadata.get(recorder::OBSERVED_METADATA_NAME) {
        anyhow::bail!(
            "{} was recorded by an observer ({}), not by the hub: it holds the world as seen, but no replay journal \
             (actions, seed, noise) to replay. Plot it (`iwsim plot`) or open it in Foxglove; for a replayable \
             file, record on the hub's machine (`iwsim hub --record`).",
            args.file.display(),
            from.get("source").map_or("iwsim record", String::as_str)
        );
    }
    if let Some(lost) = &recording.truncated {
        ipc_services::report!("iwsim replay: {}: {lost}", args.file.display());
    }
    if args.serve {
        return serve(args, &recording);
    }
    let r = replay(&recording, args.check, args.until)?;
    if args.json {
        println!("{}", r.outcome.json_line());
    } else {
        let s = &recording.start;
        println!(
            "replayed {} ticks of {} (lab {:?}, seed {}, {}): tick {} state hash {}",
            r.steps,
            args.file.display(),
            s.lab.name,
            s.seed,
            if s.lockstep { "lock-step" } else { "real time" },
            r.outcome.ticks,
            r.outcome.state_hash
        );
        for robot in &r.outcome.robots {
            println!(
                "robot {}: x {:.4} m, y {:.4} m, heading {:.2} deg, flags {}",
                robot.id, robot.x_m, robot.y_m, robot.heading_deg, robot.flags
            );
        }
    }
    match r.mismatch {
        Some(e) => {
            ipc_services::report!("iwsim replay: {}: {e}", args.file.display());
            Ok(ExitCode::FAILURE)
        }
        None => match (&recording.truncated, args.check) {
            // What a cut-short file holds may match, but the run it recorded cannot be checked
            // to its end: a check that passed would say more than it knows.
            (Some(lost), true) => {
                ipc_services::report!(
                    "iwsim replay: the {} ticks the recording holds match, but it is cut short ({lost}): the run \
                     cannot be checked to its end",
                    r.steps
                );
                Ok(ExitCode::FAILURE)
            }
            (None, true) => {
                ipc_services::report!("iwsim replay: every one of the {} ticks matches the recording", r.steps);
                Ok(ExitCode::SUCCESS)
            }
            (_, false) => Ok(ExitCode::SUCCESS),
        },
    }
}

/// `iwsim replay FILE --serve`.
fn serve(args: &ReplayArgs, recording: &Recording) -> anyhow::Result<ExitCode> {
    let options = ServeOptions {
        session: args.session.clone(),
        speed: args.speed,
        looped: args.looped,
        start_on_command: args.start_on_command,
        check: args.check,
        until: args.until,
    };
    ipc_services::report!(
        "iwsim replay: serving {} as session {:?} at {}x{}",
        args.file.display(),
        options.session,
        options.speed,
        if options.looped { ", looping" } else { "" }
    );
    let served = crate::serve::serve(recording, &options).context("serving the replay")?;
    if args.json {
        // The world at the end, whichever way it ended (the last tick, --until, Stop).
        println!("{}", served.outcome.json_line());
    } else {
        println!(
            "served {} ticks of {} as session {:?}: ended at tick {}{}",
            served.steps,
            args.file.display(),
            options.session,
            served.outcome.ticks,
            if served.outcome.interrupted { " (stopped by a termination signal)" } else { "" }
        );
    }
    match served.mismatch {
        Some(e) => {
            ipc_services::report!("iwsim replay: {}: {e}", args.file.display());
            Ok(ExitCode::FAILURE)
        }
        None => Ok(ExitCode::SUCCESS),
    }
}
