//! `iwsim run` as a process that owns others: a signal to it alone stops its hub, agents and
//! viewer and leaves nothing behind; a child that fails before the run's end stops the run at
//! once; `--session` lets another process attach; and every command README shows exists.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use run_records::summary::RunSummary;

use super::common::{
    Lines, Proc, assert_no_shared_memory_left, processes_with_argument, session, shared_memory_files, text, wait_until,
};

/// A fresh directory for one test.
fn work_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-runner-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("work dir");
    dir
}

/// A scenario file in `dir`: the agents given as TOML, for a run far longer than any test.
fn scenario(dir: &Path, lab: &str, agents: &str) -> String {
    let path = dir.join("long.toml");
    std::fs::write(
        &path,
        format!(
            "name = \"long\"\ndescription = \"chairs standing still for a long time\"\nlab = \"{lab}\"\nseconds = 100000\n{agents}"
        ),
    )
    .expect("scenario written");
    path.display().to_string()
}

/// A wheelchair agent that stands still at `x`.
fn still_chair(x: f64) -> String {
    format!("[[agents]]\nkind = \"wheelchair\"\noptions = {{ pose = [{x}, 6.1, 0.0], powers = [0.0, 0.0] }}\n")
}

/// Asserts that nothing of the runner `pid`'s sessions is left: no process and no file.
fn assert_nothing_of_run_left(pid: u32) {
    let prefix = format!("run-{pid}-");
    let procs = processes_with_argument(&prefix);
    assert!(procs.is_empty(), "processes of the run left: {procs:?}");
    let files = shared_memory_files(&format!("iwsim_{prefix}"));
    assert!(files.is_empty(), "left in /dev/shm: {files:?}");
}

/// Starts a long run, waits until its agent drives (and its viewer serves, unless headless),
/// sends `signal` to the runner alone, and checks what it leaves.
fn interrupt_a_run(tag: &str, extra: &[&str], viewer: bool, signal: &str, name: &str, code: i32) {
    let dir = work_dir(tag);
    let scenario = scenario(&dir, "builtin:liacc", &still_chair(10.0));
    let out = dir.join("out");
    let mut args = vec!["run", &scenario, "--out", out.to_str().expect("utf-8")];
    args.extend(extra);
    if viewer {
        args.extend(["--http", "127.0.0.1:0"]);
    } else {
        args.push("--headless");
    }
    let mut run = Proc::spawn(&args);
    let pid = run.pid();
    let lines = run.stderr_lines();
    let mut markers = vec!["wheelchair: agent"];
    if viewer {
        markers.push("open http://");
    }
    lines.wait_for_all(&markers, Duration::from_secs(60));
    assert!(!processes_with_argument(&format!("run-{pid}-")).is_empty(), "the run's processes are found");
    run.signal(signal);
    let output = run.wait(Duration::from_secs(30));
    let stdout = text(&output.stdout);
    let stderr = lines.to_end(Duration::from_secs(10));
    assert_eq!(output.status.code(), Some(code), "{stdout}\n{}", stderr.join("\n"));
    assert!(stderr.iter().any(|l| l.contains(&format!("iwsim run: {name} received"))), "{stderr:?}");
    assert!(stdout.contains(&format!("FAIL: interrupted by {name}")), "{stdout}");
    assert!(
        stdout.contains(&format!("logs, the recording (run.mcap) and summary.json in {}", out.display())),
        "{stdout}"
    );
    let summary = RunSummary::read(&out.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
    assert!(!summary.passed, "{summary:?}");
    assert!(summary.failures.iter().any(|f| f.starts_with(&format!("interrupted by {name}"))), "{summary:?}");
    assert_nothing_of_run_left(pid);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn sigint_to_a_lock_step_run_stops_its_hub_and_agents_and_leaves_nothing() {
    interrupt_a_run("sigint-lockstep", &["--lockstep"], false, "INT", "SIGINT", 130);
}

#[test]
fn sigterm_to_a_real_time_run_stops_its_hub_agents_and_viewer_and_leaves_nothing() {
    interrupt_a_run("sigterm-realtime", &[], true, "TERM", "SIGTERM", 143);
}

#[test]
fn sigterm_to_a_lock_step_run_stops_its_hub_and_agents_and_leaves_nothing() {
    interrupt_a_run("sigterm-lockstep", &["--lockstep"], false, "TERM", "SIGTERM", 143);
}

/// `iwsim bench traffic` owns its runs like `iwsim run` owns its children: SIGTERM to it
/// alone, mid-run, stops that run (hub and navigators) and the bench, and leaves nothing.
/// (Its runs' observer is an iceoryx2 node, whose handlers once swallowed the signal: the
/// bench went on to the end.)
#[test]
fn sigterm_to_bench_traffic_stops_its_run_and_leaves_nothing() {
    let mut bench = Proc::spawn(&["bench", "traffic", "--chairs", "10", "--runs", "1", "--seconds", "600"]);
    let pid = bench.pid();
    let lines = bench.stderr_lines();
    let prefix = format!("bench-traffic-{pid}-");
    // The run is under way once its hub publishes (its shared memory is there) and its ten
    // navigators are up (each has the session among its arguments, as do the hub and the run).
    let started =
        || !shared_memory_files(&format!("iwsim_{prefix}")).is_empty() && processes_with_argument(&prefix).len() >= 12;
    wait_until("the bench's run starting", Duration::from_secs(60), Duration::from_millis(50), started);
    bench.signal("TERM");
    let output = bench.wait(Duration::from_secs(30));
    let stderr = lines.to_end(Duration::from_secs(10));
    assert!(!output.status.success(), "{stderr:?}");
    assert!(stderr.iter().any(|l| l.contains("interrupted by SIGTERM")), "{stderr:?}");
    let procs = processes_with_argument(&prefix);
    assert!(procs.is_empty(), "processes of the bench left: {procs:?}");
    let files = shared_memory_files(&format!("iwsim_{prefix}"));
    assert!(files.is_empty(), "left in /dev/shm: {files:?}");
}

#[test]
fn sighup_to_a_real_time_run_stops_its_hub_and_agents_and_leaves_nothing() {
    interrupt_a_run("sighup-realtime", &[], false, "HUP", "SIGHUP", 129);
}

/// A headless lock-step run of one chair standing still for a long time, once its agent
/// drives: its work dir, its output dir, the runner and its stderr.
fn long_lock_step_run(tag: &str) -> (PathBuf, PathBuf, Proc, Lines) {
    let dir = work_dir(tag);
    let scenario = scenario(&dir, "builtin:liacc", &still_chair(10.0));
    let out = dir.join("out");
    let mut run = Proc::spawn(&["run", &scenario, "--lockstep", "--headless", "--out", out.to_str().expect("utf-8")]);
    let lines = run.stderr_lines();
    lines.wait_for_all(&["wheelchair: agent"], Duration::from_secs(60));
    (dir, out, run, lines)
}

/// Issue 27, fault 4: a run whose hub is killed mid-run still writes its summary.json,
/// partial, saying what ended it and how far the record got (it used to write none).
#[test]
fn a_run_whose_hub_is_killed_writes_a_partial_summary_saying_so() {
    let (dir, out, run, lines) = long_lock_step_run("hub-killed");
    let pid = run.pid();
    // Chunks close every simulated second: wait for some to reach the disk.
    let grown = || std::fs::metadata(out.join("run.mcap")).map_or(0, |m| m.len()) >= 200_000;
    wait_until("the recording growing to 200 kB", Duration::from_secs(60), Duration::from_millis(20), grown);
    let hub = processes_with_argument(&format!("run-{pid}-"))
        .into_iter()
        .find(|p| p.contains(" hub "))
        .and_then(|p| p.split(':').next().map(str::to_owned))
        .expect("the run's hub");
    assert!(Command::new("kill").args(["-KILL", &hub]).status().expect("kill runs").success());
    let output = run.wait(Duration::from_secs(60));
    let stdout = text(&output.stdout);
    let stderr = lines.to_end(Duration::from_secs(10)).join("\n");
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    let summary = RunSummary::read(&out.join("summary.json")).unwrap_or_else(|e| panic!("{e}\n{stdout}\n{stderr}"));
    assert!(!summary.passed, "{summary:?}");
    assert!(summary.ticks >= 10, "how far the record got: {summary:?}");
    let ended = summary.failures.iter().find(|f| f.starts_with("ended at tick")).expect("what ended it");
    assert!(ended.contains("hub"), "{ended}");
    assert!(stdout.contains("FAIL: ended at tick"), "{stdout}");
    assert_nothing_of_run_left(pid);
    let _ = std::fs::remove_dir_all(dir);
}

/// Issue 27, fault 2: `iwsim run` killed with SIGKILL (it can forward nothing) used to
/// orphan its hub and agents, which ran to the end. Each child now gets SIGTERM when the
/// runner dies, and stops and cleans up as on Ctrl-C.
#[test]
fn a_runner_killed_outright_takes_its_hub_and_agents_with_it() {
    let (dir, _, mut run, _lines) = long_lock_step_run("runner-killed");
    let pid = run.pid();
    let prefix = format!("run-{pid}-");
    assert!(processes_with_argument(&prefix).len() >= 2, "the hub and the agent run");
    run.kill9();
    // The children stop on their own (SIGTERM from the kernel): poll until none is left.
    let gone = || processes_with_argument(&prefix).is_empty();
    wait_until("the killed runner's children stopping", Duration::from_secs(30), Duration::from_millis(50), gone);
    assert_nothing_of_run_left(pid);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_agent_that_fails_at_start_up_stops_the_run_at_once() {
    let dir = work_dir("agent-fails");
    let bad = "[[agents]]\nkind = \"wheelchair\"\noptions = { pose = [12.0, 6.1, 0.0], powerz = [0.5, 0.5] }\n";
    let scenario = scenario(&dir, "builtin:liacc", &format!("{}{bad}", still_chair(10.0)));
    let out = dir.join("out");
    let run = Proc::spawn(&["run", &scenario, "--headless", "--out", out.to_str().expect("utf-8")]);
    let pid = run.pid();
    // Without the fix the hub waits for its second agent for ever.
    let output = run.wait(Duration::from_secs(60));
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("the agent 2 (wheelchair) exited with exit status: 2 before the run ended"), "{stderr}");
    assert!(stderr.contains("--powerz"), "the agent's own message is shown: {stderr}");
    assert_nothing_of_run_left(pid);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_faulty_lab_is_reported_before_any_agent_starts() {
    let dir = work_dir("faulty-lab");
    std::fs::write(dir.join("bad.xml"), "<Lab Name=\"bad\" Width=\"10\" Height=\"10\"><Wall").expect("lab");
    let scenario = scenario(&dir, "bad.xml", &still_chair(1.0));
    let out = dir.join("out");
    let run = Proc::spawn(&["run", &scenario, "--headless", "--out", out.to_str().expect("utf-8")]);
    let pid = run.pid();
    // Without the fix the runner waited 20 s for each agent (which waits 30 s for a hub) before
    // saying anything; with it the hub's failure ends the run as it happens.
    let output = run.wait(Duration::from_secs(15));
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("the hub exited with exit status: 1"), "{stderr}");
    assert!(stderr.contains("bad.xml"), "the hub's message names the lab: {stderr}");
    // No agent was started, so none was waited for (it would wait 30 s for the hub) or
    // killed: the runner never said it started agents, no agent said anything and no log was
    // written.
    assert!(!stderr.contains("starting 1 agent(s)"), "{stderr}");
    assert!(!stderr.contains("wheelchair"), "{stderr}");
    assert!(!out.join("chair1.csv").exists());
    assert_nothing_of_run_left(pid);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_run_with_a_session_name_can_be_watched_from_another_process() {
    let dir = work_dir("session");
    let scenario = scenario(&dir, "builtin:liacc", &still_chair(10.0));
    let out = dir.join("out");
    let name = session("runner-session");
    let mut run =
        Proc::spawn(&["run", &scenario, "--headless", "--session", &name, "--out", out.to_str().expect("utf-8")]);
    let lines = run.stderr_lines();
    // The runner says when it starts the agents (what a_faulty_lab… looks for in vain).
    lines.wait_for_all(&["starting 1 agent(s)", "wheelchair: agent"], Duration::from_secs(60));
    let mut observer = observer::Observer::connect_within(&name, "e2e-runner-watch", Duration::from_secs(10))
        .expect("an observer joins the run's session");
    let start = Instant::now();
    let robots = loop {
        if let Some((_, robots)) = observer.try_world().expect("world") {
            break robots;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "no world snapshot");
        std::thread::sleep(Duration::from_millis(5));
    };
    assert_eq!(robots.len(), 1, "the run's chair is in the session's world");
    observer.close();
    run.signal("INT");
    let output = run.wait(Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(130), "{}", text(&output.stdout));
    assert_no_shared_memory_left(&name);
    let _ = std::fs::remove_dir_all(dir);
}

/// The command lines README's code blocks show, as `iwsim` arguments: lines that start with
/// `iwsim ` or `cargo run --release -- `, without their shell comments.
fn readme_commands(readme: &str) -> Vec<(usize, Vec<String>)> {
    let mut commands = Vec::new();
    let mut in_block = false;
    for (n, line) in readme.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if !in_block {
            continue;
        }
        let line = line.trim().trim_start_matches("$ ");
        let line = line.split(" #").next().unwrap_or_default();
        let Some(rest) = line.strip_prefix("iwsim ").or_else(|| line.strip_prefix("cargo run --release -- ")) else {
            continue;
        };
        commands.push((n + 1, rest.split_whitespace().map(str::to_owned).collect()));
    }
    commands
}

#[test]
fn readme_commands_are_split_from_their_comments() {
    let readme = "text iwsim no\n```\niwsim run builtin:door --session d1   # then: iwsim view --session d1\n# a comment\ncargo run --release -- hub --session lab1\n```\niwsim outside\n";
    let got = readme_commands(readme);
    let want = [(3, vec!["run", "builtin:door", "--session", "d1"]), (5, vec!["hub", "--session", "lab1"])];
    assert_eq!(got, want.map(|(n, a)| (n, a.into_iter().map(String::from).collect::<Vec<_>>())));
}

#[test]
fn every_iwsim_command_in_the_readme_and_the_docs_takes_the_options_it_shows() {
    let mut commands = Vec::new();
    for (name, text) in crate::docs::user_docs() {
        commands.extend(readme_commands(&text).into_iter().map(|(line, args)| (format!("{name}:{line}"), args)));
    }
    assert!(commands.len() >= 20, "README and docs show {} commands: {commands:?}", commands.len());
    let mut refused = Vec::new();
    for (place, args) in &commands {
        let mut args: Vec<&str> = args.iter().map(String::as_str).collect();
        args.push("--help");
        let output = Proc::spawn(&args).wait(Duration::from_secs(30));
        if !output.status.success() {
            refused.push(format!("{place}: iwsim {}\n{}", args.join(" "), text(&output.stderr)));
        }
    }
    assert!(refused.is_empty(), "{}", refused.join("\n"));
}

#[test]
fn every_option_in_the_command_table_is_one_the_command_takes() {
    let page = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/cli.md")).expect("docs/cli.md");
    let (_, table) = page.split_once("## Command line").expect("docs/cli.md's command line section");
    let mut rows = 0;
    let mut stale = Vec::new();
    for row in table.lines().take_while(|l| !l.starts_with("## ")).filter(|l| l.starts_with("| `iwsim ")) {
        let shown = row.split('`').nth(1).unwrap_or_default();
        // The subcommand's words, then its options as `--name`.
        let words: Vec<&str> = shown
            .split_whitespace()
            .skip(1)
            .take_while(|w| w.chars().next().is_some_and(|c| c.is_ascii_lowercase()))
            .collect();
        let flags: Vec<&str> = shown
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
            .filter(|t| t.starts_with("--") && t.len() > 2)
            .collect();
        let mut args = words.clone();
        args.push("--help");
        let help = text(&Proc::spawn(&args).wait(Duration::from_secs(30)).stdout);
        for flag in flags {
            if !help.contains(&format!("{flag} "))
                && !help.contains(&format!("{flag}\n"))
                && !help.contains(&format!("{flag},"))
            {
                stale.push(format!("iwsim {}: {flag}", words.join(" ")));
            }
        }
        rows += 1;
    }
    assert!(rows >= 25, "README's command table has {rows} rows");
    assert!(
        stale.is_empty(),
        "options README's command table shows that the command does not take:\n{}",
        stale.join("\n")
    );
}

/// The first ```toml block of README's section `heading` (up to the next heading of that level).
fn readme_toml(readme: &str, heading: &str) -> String {
    let section = readme.split(heading).nth(1).unwrap_or_else(|| panic!("README has {heading:?}"));
    let block = section.split("```toml\n").nth(1).unwrap_or_else(|| panic!("{heading:?} shows a TOML file"));
    block.split("```").next().unwrap_or_default().to_owned()
}

#[test]
fn the_documented_scenario_file_runs_as_copied_and_passes() {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/scenarios.md"))
        .expect("docs/scenarios.md");
    let dir = work_dir("readme-scenario");
    let file = dir.join("slalom.toml");
    std::fs::write(&file, readme_toml(&readme, "### The scenario file")).expect("scenario written");
    let out = dir.join("out");
    let args =
        ["run", file.to_str().expect("utf-8"), "--lockstep", "--headless", "--out", out.to_str().expect("utf-8")];
    let output = Proc::spawn(&args).wait(Duration::from_secs(120));
    assert_eq!(output.status.code(), Some(0), "{}\n{}", text(&output.stdout), text(&output.stderr));
    let summary = RunSummary::read(&out.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
    assert!(summary.passed, "{:?}", summary.failures);
    let _ = std::fs::remove_dir_all(dir);
}

/// README's test command, from "The two commands": the `cargo test` line of its first code
/// block that has one.
fn readme_test_command(readme: &str) -> String {
    let section = readme.split("## The two commands").nth(1).expect("README has \"The two commands\"");
    let line = section.lines().find(|l| l.trim_start().starts_with("cargo test")).expect("a cargo test line");
    line.split(" #").next().unwrap_or_default().trim().to_owned()
}

#[test]
fn ci_runs_the_readme_test_command_and_a_failure_hides_no_other_test_binary() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README");
    let ci = std::fs::read_to_string(root.join(".ci/run")).expect(".ci/run");
    let command = readme_test_command(&readme);
    // cargo stops at the first failing test binary unless told otherwise.
    assert!(command.split_whitespace().any(|w| w == "--no-fail-fast"), "README's test command: {command}");
    // CI runs the same command, only with the lock file enforced.
    let ci_line = ci.lines().rfind(|l| l.trim_start().starts_with("cargo test")).expect("CI runs cargo test");
    let mut ci_words: Vec<&str> = ci_line.split_whitespace().filter(|w| *w != "--locked").collect();
    let mut words: Vec<&str> = command.split_whitespace().collect();
    ci_words.sort_unstable();
    words.sort_unstable();
    assert_eq!(ci_words, words, ".ci/run's `{ci_line}` is README's `{command}`");
}
