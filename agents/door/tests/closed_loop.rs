//! The door agent against a hub in this process, as `iwsim run` pairs them: what a user finds
//! in the `--log` directory after the run.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use agent_sdk::log::LogTable;
use clap::Parser as _;

#[derive(clap::Parser)]
struct Cli {
    #[command(flatten)]
    args: door::DoorArgs,
}

/// A lock-step hub on the LIACC lab that waits for one agent and stops after `ticks`.
fn hub_config(session: &str, ticks: u64) -> hub::HubConfig {
    let map = world::map::builtin::map("liacc").expect("built in");
    hub::HubConfig {
        session: session.into(),
        obstacle_from: map.lab.walls.len(),
        lab: map.lab,
        grid: map.grid,
        params: world::map::Params::default(),
        seed: 1,
        mode: hub::core::Mode::LockStep,
        deadline: Duration::from_secs(5),
        wait_agents: 1,
        start_on_command: false,
        tick_limit: ticks,
        max_robots: 8,
        checkpoints: Vec::new(),
    }
}

fn out_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-door-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn the_doors_log_ends_with_the_runs_final_tick() {
    let session = format!("door-final-{}", std::process::id());
    let dir = out_dir("final");
    let hub = std::thread::spawn({
        let cfg = hub_config(&session, 4);
        move || hub::run(cfg).map(|out| out.ticks)
    });
    let cli = Cli::parse_from([
        "door",
        "--session",
        &session,
        "--connect-timeout",
        "30",
        "--name",
        "front door",
        "--pose",
        "12,6,0",
        "--log",
        dir.to_str().expect("utf-8"),
    ]);
    let code = door::run(&cli.args).expect("the agent ran");
    assert_eq!(hub.join().expect("the hub thread").expect("the hub ran"), 4);
    assert_eq!(code, ExitCode::SUCCESS);
    // The name's space is escaped, not turned into a `_` another door's name may have.
    let log = LogTable::read(&dir.join("front%20door.csv")).expect("the door's log");
    let tick = log.column("tick").expect("a tick column");
    let ticks: Vec<f64> = log.rows.iter().map(|r| r[tick]).collect();
    assert_eq!(ticks, [0.0, 1.0, 2.0, 3.0, 4.0], "ticks 0 to 3 answered, then 4, the run's end");
    let _ = std::fs::remove_dir_all(dir);
}
