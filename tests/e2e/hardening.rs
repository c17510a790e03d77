//! Hardening (issue 16): values a process cannot honour are refused up front, a closed stderr
//! is not an error, an idle lock-step hub sleeps, a viewer leaves with its hub, and no way out
//! of a process leaves files of its session in /dev/shm.

use std::process::{Command, Stdio};
use std::time::Duration;

use super::common::{Proc, assert_no_dev_shm_left, assert_no_shared_memory_left, session, text, wait_for_tick};

/// Runs `iwsim ARGS` to its end (failing the test if it runs 10 s, as a value that was not
/// refused would) and returns its exit code and stderr.
fn iwsim(args: &[&str]) -> (Option<i32>, String) {
    let out = Proc::spawn(args).wait(Duration::from_secs(10));
    (out.status.code(), text(&out.stderr))
}

#[test]
fn values_that_cannot_be_honoured_are_refused_with_the_option_and_its_range() {
    for (args, option, range) in [
        (&["hub", "--deadline-ms", "0"][..], "--deadline-ms", "1..=86400000"),
        (&["hub", "--wait-agents", "1000"][..], "--wait-agents", "0..=128"),
        (&["hub", "--max-robots", "0"][..], "--max-robots", "1..=10000"),
        (&["hub", "--max-robots", "20000"][..], "--max-robots", "1..=10000"),
        (&["hub", "--cycle-ms", "0"][..], "--cycle-ms", "1..="),
        (&["agent", "wheelchair", "--robots", "0"][..], "--robots", "1..=10000"),
        (&["udp", "--client-timeout", "1e30"][..], "--client-timeout", "0.1..=86400"),
        (&["udp", "--wait-robots", "0"][..], "--wait-robots", "1..=1000000"),
        (&["run", "builtin:slalom", "--deadline-ms", "0"][..], "--deadline-ms", "1..=86400000"),
    ] {
        // A session of its own, so a value that is not refused starts nothing a user runs.
        let s = session("refused");
        let args: Vec<&str> = args.iter().copied().chain(["--session", &s]).collect();
        let (code, stderr) = iwsim(&args);
        assert_eq!(code, Some(2), "{args:?} must be refused before anything starts: {stderr}");
        let first = stderr.lines().next().unwrap_or_default();
        assert!(first.contains(option) && first.contains(range), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

/// Issue 27, fault 11: `iwsim plot /dev/zero` read until memory ran out, and a FIFO with no
/// writer given as a lab blocked for ever. Every reader of a user's file now refuses what is
/// not a regular file, at once and saying what it is (10 s is this test's own bound).
#[test]
fn a_device_or_a_pipe_given_as_a_file_is_refused_at_once() {
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-fifo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let fifo = dir.join("lab.xml");
    assert!(Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs").success());
    let fifo = fifo.to_str().expect("utf-8");
    let s = session("fifo-lab");
    for (args, said) in [
        (&["plot", "/dev/zero"][..], "/dev/zero: cannot read the log: not a regular file but a device"),
        (&["plot", fifo][..], "not a regular file but a pipe (FIFO)"),
        (&["map", "check", fifo][..], "not a regular file but a pipe (FIFO)"),
        (&["hub", "--session", &s, "--lab", fifo][..], "not a regular file but a pipe (FIFO)"),
        (&["replay", fifo, "--check"][..], "not a regular file but a pipe (FIFO)"),
    ] {
        let (code, stderr) = iwsim(args);
        assert_ne!(code, Some(0), "{args:?}: {stderr}");
        assert!(stderr.contains(said), "{args:?}: {stderr}");
        // Each cause is said once.
        assert_eq!(stderr.matches("not a regular file").count(), 1, "{args:?}: {stderr}");
    }
    std::fs::remove_dir_all(&dir).expect("clean up");
    assert_no_shared_memory_left(&s);
}

/// Issue 27, fault 10: a hub given a session name it cannot use printed its banner (as if the
/// session were coming up) before the error.
#[test]
fn a_hub_with_an_unusable_session_name_says_only_that() {
    let (code, stderr) = iwsim(&["hub", "--session", "bad/name", "--ticks", "1"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "the error alone: {stderr}");
    assert!(stderr.contains("session name \"bad/name\" is invalid"), "{stderr}");
}

#[test]
fn an_agent_whose_stderr_is_closed_finishes_its_run() {
    let s = session("closed-stderr");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--ticks", "30", "--wait-agents", "1", "--json"]);
    let mut agent = Command::new(env!("CARGO_BIN_EXE_iwsim"))
        .args(["agent", "wheelchair", "--session", &s, "--connect-timeout", "20"])
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the agent starts");
    // The reader goes away before the agent has written anything: every line it reports
    // meets a broken pipe.
    drop(agent.stderr.take());
    let status = Proc(Some(agent)).wait(Duration::from_secs(30)).status;
    assert_eq!(status.code(), Some(0), "the agent must finish its run as if its stderr were there");
    let h = hub.wait(Duration::from_secs(10));
    assert!(h.status.success(), "{}", text(&h.stderr));
    assert!(text(&h.stdout).contains("\"ticks\":30"), "the hub ran all its ticks: {}", text(&h.stdout));
    assert_no_shared_memory_left(&s);
}

/// User plus system CPU time of process `pid` so far, in clock ticks.
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("the hub runs");
    // Fields after the command name (which is in parentheses): state is the 1st, utime the
    // 12th, stime the 13th.
    let rest = stat.rsplit_once(')').expect("a stat line").1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    fields[11].parse::<u64>().expect("utime") + fields[12].parse::<u64>().expect("stime")
}

/// The unit of /proc's CPU times (`getconf CLK_TCK`; 100 on every Linux we know).
fn clock_ticks_per_second() -> u64 {
    let out = Command::new("getconf").arg("CLK_TCK").output().ok();
    out.and_then(|o| text(&o.stdout).trim().parse().ok()).unwrap_or(100)
}

/// CPU time (clock ticks) process `pid` uses over one second of wall time.
fn cpu_over_a_second(pid: u32) -> u64 {
    let before = cpu_ticks(pid);
    // A measuring interval, not a synchronisation: nothing is waited for.
    std::thread::sleep(Duration::from_secs(1));
    cpu_ticks(pid) - before
}

#[test]
fn a_lock_step_hub_with_no_ready_agent_sleeps() {
    let hz = clock_ticks_per_second();
    let s = session("idle-lockstep");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--deadline-ms", "20"]);
    // Serving: an observer saw tick 0 and left again; the 20 ms deadline is long past below.
    wait_for_tick(&s, 0, Duration::from_secs(20)).close();
    let idle = cpu_over_a_second(hub.pid());
    assert!(idle < hz / 5, "a lock-step hub with no agent used {idle} of {hz} clock ticks in a second");

    // Its last ready agent leaves: the hub is back to no ready agent.
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--ticks", "5"]);
    let a = agent.wait(Duration::from_secs(20));
    assert!(a.status.success(), "{}", text(&a.stderr));
    let idle = cpu_over_a_second(hub.pid());
    assert!(idle < hz / 5, "a lock-step hub whose agent left used {idle} of {hz} clock ticks in a second");

    // SIGTERM to a lock-step hub alone leaves nothing behind.
    hub.signal("TERM");
    let h = hub.wait(Duration::from_secs(10));
    assert!(h.status.success(), "{}", text(&h.stderr));
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_lock_step_hub_whose_only_agent_dies_steps_on_at_the_deadlines_pace() {
    // The agent is killed mid-run: its robot stays, frozen, for a restarted agent to take back,
    // and the hub steps it at the deadline's pace (so a run with a tick limit reaches its end)
    // instead of waiting for ever at 0 % CPU (issue 27, fault 1).
    let s = session("orphan-lockstep");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--deadline-ms", "100", "--json"]);
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s]);
    wait_for_tick(&s, 5, Duration::from_secs(20)).close();
    agent.signal("KILL");
    agent.wait(Duration::from_secs(10));
    let mut observer = wait_for_tick(&s, 0, Duration::from_secs(20));
    let (h, _) = observer.world().expect("the world");
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    let mut now = h.tick;
    while now < h.tick + 5 && std::time::Instant::now() < deadline {
        now = observer.with_world(|w, _| w.tick).expect("the world");
        // Polling the newest tick until the deadline; a short pause keeps a loaded CPU free.
        std::thread::sleep(Duration::from_millis(5));
    }
    observer.close();
    assert!(now >= h.tick + 5, "the hub stalled at tick {now} after its only agent died");
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    let out = hub.wait(Duration::from_secs(20));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_viewer_leaves_when_its_hub_is_killed_and_a_restarted_hub_serves_the_session() {
    let s = session("view-hub-killed");
    let mut hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20"]);
    let mut viewer = Proc::spawn(&["view", "--session", &s, "--http", "127.0.0.1:0", "--connect-timeout", "20"]);
    viewer.announced("open http://", Duration::from_secs(20));
    hub.kill9();
    let v = viewer.wait(Duration::from_secs(5));
    assert!(!v.status.success(), "a viewer whose hub died must say so in its exit status");
    // The viewer, last of the session, cleaned up after the dead hub's shared memory too.
    assert_no_dev_shm_left(&s);

    let hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20"]);
    wait_for_tick(&s, 2, Duration::from_secs(20)).close();
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the new hub answers").status, 0);
    let h = hub.wait(Duration::from_secs(10));
    assert!(h.status.success(), "the restarted hub: {}", text(&h.stderr));
    // Not /tmp/iceoryx2: after a SIGKILL iceoryx2 may leave a dead node's monitor files and a
    // port tag there that no later process of the session removes (see ARCHITECTURE.md).
    assert_no_dev_shm_left(&s);
}

#[test]
fn clients_that_find_no_hub_leave_nothing_behind() {
    let s = session("no-hub");
    for args in [
        &["agent", "wheelchair", "--session", &s, "--connect-timeout", "0.2"][..],
        &["view", "--session", &s, "--http", "127.0.0.1:0", "--connect-timeout", "0.2"][..],
        &["udp", "--session", &s, "--port", "0", "--connect-timeout", "0.2"][..],
    ] {
        let (code, stderr) = iwsim(args);
        assert_eq!(code, Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains("no hub is serving session"), "{args:?}: {stderr}");
        assert_no_shared_memory_left(&s);
    }
}

#[test]
fn sigterm_to_a_lock_step_hub_and_its_bridge_leaves_nothing_behind() {
    let s = session("term-hub-bridge");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep"]);
    let mut bridge = Proc::spawn(&["udp", "--session", &s, "--port", "0", "--connect-timeout", "20"]);
    bridge.announced("registrations on ", Duration::from_secs(20));
    hub.signal("TERM");
    bridge.signal("TERM");
    hub.wait(Duration::from_secs(10));
    bridge.wait(Duration::from_secs(10));
    assert_no_shared_memory_left(&s);
}

#[test]
fn sighup_ends_a_hub_and_its_bridge_as_sigterm_does() {
    // A closed terminal or ssh session sends SIGHUP: the hub and the bridge stop cleanly, the
    // recording is whole, and nothing is left in /dev/shm (SIGHUP's default killed them
    // where they stood).
    let s = session("hup-hub-bridge");
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-hup-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let rec = dir.join("hup.mcap");
    let rec = rec.to_str().expect("utf-8");
    let hub = Proc::spawn_hangup_default(&["hub", "--session", &s, "--cycle-ms", "20", "--record", rec]);
    let mut bridge = Proc::spawn_hangup_default(&["udp", "--session", &s, "--port", "0", "--connect-timeout", "20"]);
    bridge.announced("registrations on ", Duration::from_secs(20));
    wait_for_tick(&s, 5, Duration::from_secs(20)).close();
    hub.signal("HUP");
    let h = hub.wait(Duration::from_secs(10));
    assert!(h.status.success(), "the hub ends as on SIGTERM: {:?} {}", h.status, text(&h.stderr));
    bridge.signal("HUP");
    let b = bridge.wait(Duration::from_secs(10));
    assert!(b.status.code().is_some(), "the bridge exits rather than dying of the signal: {:?}", b.status);
    assert_no_shared_memory_left(&s);
    let (code, stderr) = iwsim(&["replay", rec, "--check"]);
    assert_eq!(code, Some(0), "the recording is whole: {stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The peak resident set (`VmHWM`) of process `pid`, KiB.
fn peak_rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("the process is alive");
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:")).expect("VmHWM");
    line.trim().trim_end_matches("kB").trim().parse().expect("a number of kB")
}

#[test]
fn a_navigator_on_a_10_km_lab_plans_within_64_mib() {
    // The largest lab a hub accepts, with one wall across the chair's way: the navigator's
    // grids cover where the chair may go (its start and checkpoints and a reach round them),
    // not 10 km × 10 km, which would take tens of gigabytes at 5 cm a cell.
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-10km-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let lab = dir.join("lab.xml");
    std::fs::write(
        &lab,
        r#"<Lab Name="ten km" Width="10000" Height="10000">
<Wall Height="1"><Corner X="5004" Y="4999.5"/><Corner X="5004.5" Y="4999.5"/><Corner X="5004.5" Y="5000.2"/><Corner X="5004" Y="5000.2"/></Wall>
</Lab>
"#,
    )
    .expect("lab written");
    let s = session("nav-10km");
    let lab = lab.to_str().expect("utf-8");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lab", lab, "--lockstep", "--wait-agents", "1", "--no-noise"]);
    let mut nav = Proc::spawn(&[
        "agent",
        "navigator",
        "--session",
        &s,
        "--connect-timeout",
        "20",
        "--pose",
        "5000,5000,0",
        "--checkpoint",
        "5000,5000",
        "--checkpoint",
        "5008,5000",
        "--checkpoint",
        "5012,5003,0.3",
    ]);
    let said = nav.stderr_lines();
    // Past the wall and on to the last leg: every grid it plans on has been built.
    said.said("reached checkpoint 2", Duration::from_secs(60));
    said.said("to checkpoint 3", Duration::from_secs(20));
    let kib = peak_rss_kib(nav.pid());
    assert!(kib < 64 * 1024, "the navigator's peak resident set is {kib} KiB");
    said.said("reached checkpoint 3", Duration::from_secs(60));
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    assert!(hub.wait(Duration::from_secs(20)).status.success());
    assert!(
        nav.wait(Duration::from_secs(20)).status.success(),
        "all checkpoints reached: {:?}",
        said.to_end(Duration::from_secs(5))
    );
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}
