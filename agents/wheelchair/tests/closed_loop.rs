//! The wheelchair agent against a hub in this process, as `iwsim run` pairs them: what a user
//! finds in the `--log` directory after the run.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use agent_sdk::log::LogTable;
use clap::Parser as _;

#[derive(clap::Parser)]
struct Cli {
    #[command(flatten)]
    args: wheelchair::WheelchairArgs,
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
    let dir = std::env::temp_dir().join(format!("iwsim-wheelchair-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn every_chairs_log_ends_with_the_runs_final_tick() {
    let session = format!("wheelchair-final-{}", std::process::id());
    let dir = out_dir("final");
    let hub = std::thread::spawn({
        let cfg = hub_config(&session, 5);
        move || hub::run(cfg).map(|out| out.ticks)
    });
    let cli = Cli::parse_from([
        "wheelchair",
        "--session",
        &session,
        "--connect-timeout",
        "30",
        "--robots",
        "2",
        "--log",
        dir.to_str().expect("utf-8"),
    ]);
    let code = wheelchair::run(&cli.args).expect("the agent ran");
    assert_eq!(hub.join().expect("the hub thread").expect("the hub ran"), 5);
    assert_eq!(code, ExitCode::SUCCESS);
    for name in ["chair1", "chair2"] {
        let log = LogTable::read(&dir.join(format!("{name}.csv"))).expect("a log per chair");
        let col = |c: &str| log.column(c).expect("a column");
        let ticks: Vec<f64> = log.rows.iter().map(|r| r[col("tick")]).collect();
        // Ticks 0 to 4 answered with the script's powers, then tick 5, the run's end, unanswered.
        assert_eq!(ticks, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0], "{name}");
        let powers = |r: &Vec<f64>| [r[col("power_left")], r[col("power_right")]];
        assert_eq!(powers(&log.rows[4]), [0.5, 0.5], "{name}");
        assert_eq!(powers(&log.rows[5]), [0.0, 0.0], "{name}");
        assert!((log.rows[5][col("time_s")] - 0.5).abs() < 1e-9, "{name}: the final tick's own time");
    }
    let _ = std::fs::remove_dir_all(dir);
}
