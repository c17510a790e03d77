//! The rules ARCHITECTURE.md states, checked against the dependency graph `cargo metadata`
//! resolves and against the source tree (in the spirit of rust-analyzer's tidy tests). Each
//! test names the "Architecture invariant" it keeps; breaking one (say, adding `hub` to an
//! agent's dependencies) fails here with the path that breaks it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace's dependency graph: package names by id, and each package's resolved
/// normal (linked) and dev dependencies.
struct Graph {
    names: BTreeMap<String, String>,
    members: BTreeSet<String>,
    normal: BTreeMap<String, Vec<String>>,
    dev: BTreeMap<String, Vec<String>>,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn graph() -> Graph {
    let cargo = option_env!("CARGO").unwrap_or("cargo");
    let out = Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--locked"])
        .current_dir(root())
        .output()
        .expect("cargo metadata runs");
    assert!(out.status.success(), "cargo metadata: {}", String::from_utf8_lossy(&out.stderr));
    let m: serde_json::Value = serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON");
    let mut g =
        Graph { names: BTreeMap::new(), members: BTreeSet::new(), normal: BTreeMap::new(), dev: BTreeMap::new() };
    for p in m["packages"].as_array().expect("packages") {
        g.names.insert(p["id"].as_str().expect("id").to_owned(), p["name"].as_str().expect("name").to_owned());
    }
    for id in m["workspace_members"].as_array().expect("members") {
        g.members.insert(id.as_str().expect("member id").to_owned());
    }
    for node in m["resolve"]["nodes"].as_array().expect("resolve") {
        let id = node["id"].as_str().expect("node id").to_owned();
        for dep in node["deps"].as_array().expect("deps") {
            let pkg = dep["pkg"].as_str().expect("dep pkg").to_owned();
            for k in dep["dep_kinds"].as_array().expect("dep kinds") {
                match k["kind"].as_str() {
                    None => g.normal.entry(id.clone()).or_default().push(pkg.clone()),
                    Some("dev") => g.dev.entry(id.clone()).or_default().push(pkg.clone()),
                    // Build dependencies run at build time; they link nothing into the crate.
                    Some(_) => {}
                }
            }
        }
    }
    g
}

impl Graph {
    /// The id of the package `name`: the workspace's own, else the first of that name.
    fn id(&self, name: &str) -> String {
        let named = |id: &&String| self.names.get(*id).is_some_and(|n| n == name);
        let members: Vec<&String> = self.members.iter().filter(named).collect();
        match members.as_slice() {
            [one] => (*one).clone(),
            [] => self.names.keys().find(named).unwrap_or_else(|| panic!("no package {name:?}")).clone(),
            _ => panic!("two workspace packages named {name:?}"),
        }
    }

    /// Every package `name` links, with the chain that brings each in.
    fn linked(&self, name: &str) -> BTreeMap<String, Vec<String>> {
        let start = self.id(name);
        let mut seen: BTreeMap<String, Vec<String>> = BTreeMap::new();
        let mut todo = vec![(start.clone(), vec![name.to_owned()])];
        while let Some((id, chain)) = todo.pop() {
            for dep in self.normal.get(&id).into_iter().flatten() {
                let dep_name = self.names[dep].clone();
                if seen.contains_key(&dep_name) {
                    continue;
                }
                let mut c = chain.clone();
                c.push(dep_name.clone());
                seen.insert(dep_name, c.clone());
                todo.push((dep.clone(), c));
            }
        }
        seen
    }

    fn direct(&self, name: &str, kinds: &BTreeMap<String, Vec<String>>) -> Vec<String> {
        kinds.get(&self.id(name)).into_iter().flatten().map(|d| self.names[d].clone()).collect()
    }

    fn member_names(&self) -> Vec<String> {
        self.members.iter().map(|id| self.names[id].clone()).collect()
    }
}

/// Fails with every forbidden package `name` links and the chain that links it.
fn assert_links_none(g: &Graph, name: &str, forbidden: impl Fn(&str) -> bool, rule: &str) {
    let bad: Vec<String> =
        g.linked(name).into_iter().filter(|(dep, _)| forbidden(dep)).map(|(_, chain)| chain.join(" -> ")).collect();
    assert!(bad.is_empty(), "{rule}, but:\n  {}", bad.join("\n  "));
}

#[test]
fn the_world_model_links_no_iceoryx2_and_nothing_of_the_hub_server() {
    // Architecture invariant: the world crate depends on no iceoryx2 crate (and no IPC crate).
    let g = graph();
    assert_links_none(
        &g,
        "world",
        |d| d.starts_with("iceoryx2") || ["ipc-types", "ipc-services", "hub", "agent-sdk", "libc"].contains(&d),
        "the world model is pure: no iceoryx2, no IPC, no libc",
    );
}

#[test]
fn agents_adapters_and_the_viewer_never_link_the_hub_or_the_world() {
    // Architecture invariant: agents, adapters and the viewer know the world only through the
    // hub's services; only the closed-loop tests listed here may use the model in-process.
    let g = graph();
    let clients = [
        "agent-sdk",
        "navigator",
        "door",
        "teleop",
        "wheelchair",
        "udp-bridge",
        "zenoh-bridge",
        "ros2-bridge",
        "serial-bridge",
        "viewer",
        "iwsim-python",
    ];
    let allowed_dev: BTreeMap<&str, &[&str]> = BTreeMap::from([("navigator", &["world", "hub"][..])]);
    for c in clients {
        assert_links_none(&g, c, |d| d == "hub" || d == "world", &format!("{c} must not link hub or world"));
        for dev in g.direct(c, &g.dev) {
            let brings: Vec<String> = std::iter::once(dev.clone())
                .chain(g.linked(&dev).into_keys())
                .filter(|d| d == "hub" || d == "world")
                .collect();
            let allowed = allowed_dev.get(c).is_some_and(|ok| ok.contains(&dev.as_str()));
            assert!(
                brings.is_empty() || allowed,
                "{c} has the dev-dependency {dev}, which brings {brings:?}: only listed closed-loop tests may"
            );
        }
    }
    // Every client crate of the workspace is in the list above: a new agent or adapter is
    // checked from its first commit.
    for m in g.member_names() {
        let is_client = clients.contains(&m.as_str());
        let known_other = [
            "iwsim",
            "ipc-types",
            "ipc-services",
            "hub",
            "world",
            "sim-model",
            "places",
            "robot-log",
            "run-records",
            "runner",
            "recorder",
            "plot",
            "bench-harness",
            "serial-protocol",
            "chair-emulator",
            "observer",
            "os",
            "test-support",
        ]
        .contains(&m.as_str());
        assert!(is_client || known_other, "new workspace package {m:?}: add it to ARCHITECTURE.md and to this test");
    }
}

#[test]
fn ipc_types_depends_on_nothing_in_the_workspace() {
    // Architecture invariant: ipc-types depends on nothing in this workspace, and on no
    // iceoryx2 runtime (only the two no_std crates that define ZeroCopySend and its derive).
    let g = graph();
    let members: BTreeSet<String> = g.member_names().into_iter().collect();
    assert_links_none(&g, "ipc-types", |d| members.contains(d), "ipc-types depends on nothing in the workspace");
    let direct: BTreeSet<String> = g.direct("ipc-types", &g.normal).into_iter().collect();
    let allowed: BTreeSet<String> = ["bytemuck", "iceoryx2-bb-elementary-traits", "iceoryx2-bb-derive-macros"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert!(direct.is_subset(&allowed), "ipc-types depends on {direct:?}; allowed: {allowed:?}");
}

#[test]
fn the_serial_protocol_depends_on_nothing_and_builds_without_std() {
    // Architecture invariant: serial-protocol has no dependencies at all and is `#![no_std]`
    // without bringing std back outside its tests, so a board's firmware can use it as it is.
    let g = graph();
    let direct = g.direct("serial-protocol", &g.normal);
    assert!(direct.is_empty(), "serial-protocol must depend on nothing, but depends on {direct:?}");
    let lib = std::fs::read_to_string(root().join("adapters/serial-protocol/src/lib.rs")).expect("serial-protocol");
    assert!(lib.lines().any(|l| l.trim() == "#![no_std]"), "serial-protocol's lib.rs lacks #![no_std]");
    let uses_std = offending(&["extern crate std", "std::"], |r| !r.starts_with("adapters/serial-protocol/"));
    assert!(uses_std.is_empty(), "serial-protocol uses std outside its tests:\n  {}", uses_std.join("\n  "));
}

#[test]
fn the_chair_emulator_reaches_the_rest_only_through_its_serial_port() {
    // Architecture invariant: the chair emulator stands in for a physical chair, so it knows
    // nothing a physical chair does not: no hub services, no IPC, no agent SDK, no adapter. It
    // simulates its own room with the world model and speaks the serial protocol, nothing else.
    let g = graph();
    assert_links_none(
        &g,
        "chair-emulator",
        |d| {
            d.starts_with("iceoryx2")
                || ["ipc-types", "ipc-services", "agent-sdk", "hub", "serial-bridge", "udp-bridge"].contains(&d)
        },
        "the chair emulator reaches the rest only through its serial port",
    );
    let direct = g.direct("chair-emulator", &g.normal);
    assert!(direct.contains(&"serial-protocol".to_owned()), "the emulator speaks the one protocol crate: {direct:?}");
}

#[test]
fn the_shared_formulas_and_formats_link_no_ipc_runtime() {
    // Architecture invariant: sim-model depends on nothing; records, recorder, plot and the
    // world link no iceoryx2 runtime (nothing of iceoryx2 beyond the no_std traits ipc-types
    // uses), so drawing a log, reading a recording or checking a map never needs shared memory.
    let g = graph();
    assert!(
        g.direct("sim-model", &g.normal).is_empty(),
        "sim-model has dependencies: {:?}",
        g.direct("sim-model", &g.normal)
    );
    let payload_traits: BTreeSet<String> = g.linked("ipc-types").into_keys().collect();
    for c in ["places", "robot-log", "run-records", "recorder", "plot", "world"] {
        assert_links_none(
            &g,
            c,
            |d| d == "ipc-services" || (d.starts_with("iceoryx2") && !payload_traits.contains(d)),
            &format!("{c} links no iceoryx2 runtime"),
        );
    }
}

#[test]
fn only_ipc_services_depends_on_iceoryx2() {
    // Architecture invariant: every iceoryx2 service is built in ipc-services; no other crate
    // even depends on iceoryx2 directly.
    let g = graph();
    for m in g.member_names() {
        if m != "ipc-services" {
            assert!(!g.direct(&m, &g.normal).contains(&"iceoryx2".to_owned()), "{m} depends on iceoryx2 directly");
        }
    }
}

/// Every `.rs` file of the workspace's own source (not `target/`, not the fuzz package).
fn sources() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for e in entries.flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                if !["target", "fuzz", ".git", "node_modules"].contains(&name.as_str()) {
                    walk(&p, out);
                }
            } else if name.ends_with(".rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(&root(), &mut out);
    out.sort();
    out
}

/// The code lines of a file a release build compiles: comments dropped, and every item under
/// `#[cfg(test)]` skipped (a test module, inline or declared, or a single test helper).
fn production_lines(path: &Path) -> Vec<(usize, String)> {
    let text = std::fs::read_to_string(path).expect("readable source");
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate();
    while let Some((i, line)) = lines.next() {
        let t = line.trim_start();
        if t.starts_with("//") {
            continue;
        }
        if t.starts_with("#[cfg(test)]") {
            // Skip the item that follows: up to its `;`, or to the brace closing its body.
            let mut depth = 0i32;
            let mut opened = false;
            for (_, l) in lines.by_ref() {
                let code = l.split("//").next().unwrap_or("");
                depth += code.matches('{').count() as i32 - code.matches('}').count() as i32;
                opened |= code.contains('{');
                if (opened && depth <= 0) || (!opened && code.trim_end().ends_with(';')) {
                    break;
                }
            }
            continue;
        }
        out.push((i + 1, line.to_owned()));
    }
    out
}

/// Test-only files: integration tests, and unit-test modules kept in their own file.
fn is_test_file(r: &str) -> bool {
    r.starts_with("tests/") || r.contains("/tests/") || r.ends_with("/tests.rs") || r.ends_with("_tests.rs")
}

fn rel(p: &Path) -> String {
    p.strip_prefix(root()).unwrap_or(p).display().to_string()
}

/// Every production line of the tree containing one of `needles`, outside the files `allowed`.
fn offending(needles: &[&str], allowed: impl Fn(&str) -> bool) -> Vec<String> {
    let mut bad = Vec::new();
    for f in sources() {
        let r = rel(&f);
        if allowed(&r) || is_test_file(&r) {
            continue;
        }
        for (n, line) in production_lines(&f) {
            if needles.iter().any(|k| line.contains(k)) {
                bad.push(format!("{r}:{n}: {}", line.trim()));
            }
        }
    }
    bad
}

#[test]
fn only_ipc_services_names_iceoryx2_service_builders() {
    // Architecture invariant: every iceoryx2 service is built in ipc-services, nowhere else.
    let bad = offending(&[".service_builder(", ".publish_subscribe::<", ".request_response::<", ".event()"], |r| {
        r.starts_with("libs/ipc-services/")
    });
    assert!(bad.is_empty(), "iceoryx2 services built outside ipc-services:\n  {}", bad.join("\n  "));
    // Architecture invariant: iceoryx2's `testing` API is called in one place only (the node
    // counter's removal, whose race ARCHITECTURE.md explains).
    let calls = offending(&["iceoryx2::testing"], |_| false);
    assert!(
        calls.len() == 1 && calls[0].starts_with("libs/ipc-services/src/lib.rs:"),
        "iceoryx2::testing must be called exactly once, in ipc-services: {calls:#?}"
    );
}

#[test]
fn the_hub_writes_every_per_tick_sample_in_place() {
    // Architecture invariant: the hub builds no per-tick sample in a Vec to copy it into shared
    // memory; it fills the loaned sample (`ports::fill`). A slice is copied in only where it is
    // kept anyway: the maps (published once) and the robot roster (on change, kept for the
    // recorder), both in hub/src/ports.rs.
    let bad = offending(&["write_from_slice"], |r| !r.starts_with("hub/src/") || r == "hub/src/ports.rs");
    assert!(bad.is_empty(), "per-tick samples staged in a Vec and copied:\n  {}", bad.join("\n  "));
    let kept = offending(&["write_from_slice"], |r| r != "hub/src/ports.rs");
    assert_eq!(kept.len(), 2, "the maps and the roster only: {kept:#?}");
}

#[test]
fn parry2d_is_met_in_one_module_and_quick_xml_in_two() {
    // Architecture invariant: parry2d and glam types appear only in hub/world/src/geom.rs.
    let bad = offending(&["parry2d::", "glam::"], |r| r == "hub/world/src/geom.rs");
    assert!(bad.is_empty(), "parry2d outside the world's boundary module:\n  {}", bad.join("\n  "));
    // Architecture invariant: quick-xml appears only in the map reader and the UDP codec.
    let bad = offending(&["quick_xml"], |r| r == "hub/world/src/map/xml.rs" || r == "adapters/udp-bridge/src/codec.rs");
    assert!(bad.is_empty(), "quick-xml outside its two modules:\n  {}", bad.join("\n  "));
}

#[test]
fn the_world_model_does_no_io_and_reads_no_clock() {
    // Architecture invariant: the world model never does I/O, never reads a clock and owns no
    // global state; the one function that reads a file is `world::map::xml::read_text`.
    let needles =
        ["fs::", "io::", "net::", "process::", "thread::", "env::", "Instant", "SystemTime", "static mut", "std::{"];
    let mut bad = Vec::new();
    for f in sources().into_iter().filter(|f| rel(f).starts_with("hub/world/src/")) {
        let r = rel(&f);
        if is_test_file(&r) {
            continue;
        }
        let mut in_fn = String::new();
        for (n, line) in production_lines(&f) {
            if let Some(rest) = line.split("fn ").nth(1).filter(|_| line.contains("fn ") && line.contains('(')) {
                in_fn = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            }
            if needles.iter().any(|k| line.contains(k)) {
                let xml = r == "hub/world/src/map/xml.rs";
                // The one boundary: `read_text` reads the file; an error type may carry the
                // io::Error it returns.
                let boundary = xml && (in_fn == "read_text" || line.trim_start().starts_with("source: std::io::Error"));
                if !boundary {
                    bad.push(format!("{r}:{n}: {}", line.trim()));
                }
            }
        }
    }
    assert!(bad.is_empty(), "I/O or clocks in the world model:\n  {}", bad.join("\n  "));
}

#[test]
fn the_cli_crate_only_parses_arguments_and_calls_libraries() {
    // Architecture invariant: the `iwsim` binary's src/ is thin (well under 1,000 lines).
    let src = root().join("src");
    let lines: usize = sources()
        .into_iter()
        .filter(|f| f.starts_with(&src))
        .map(|f| std::fs::read_to_string(f).expect("readable").lines().count())
        .sum();
    assert!(lines < 1000, "src/ has {lines} lines: move logic into a library crate");
}

#[test]
fn every_ipc_payload_asserts_its_size_and_alignment() {
    // Architecture invariant: every type that crosses processes has a compile-time size and
    // alignment assert, so a layout change is a compile error until its .vN name is bumped.
    let text = std::fs::read_to_string(root().join("ipc-types/src/lib.rs")).expect("ipc-types");
    let mut missing = Vec::new();
    let mut repr_c = false;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("#[repr(C") {
            repr_c = true;
        } else if repr_c && t.starts_with("pub struct ") {
            let name: String =
                t["pub struct ".len()..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            for what in ["size_of", "align_of"] {
                let assert = format!("const _: () = assert!(core::mem::{what}::<{name}>() == ");
                if !text.lines().any(|l| l.trim_start().starts_with(&assert)) {
                    missing.push(format!("{what}::<{name}>()"));
                }
            }
            repr_c = false;
        } else if !t.starts_with("#[") && !t.starts_with("///") && !t.is_empty() {
            repr_c = false;
        }
    }
    assert!(missing.is_empty(), "ipc-types lacks compile-time asserts: {missing:?}");
    assert!(text.contains("#![no_std]"), "ipc-types is no_std");
}

#[test]
fn only_the_sdk_decodes_the_hubs_map_stream() {
    // Architecture invariant: the map's item kinds are named only where the hub writes them
    // and where the SDK decodes them; every client builds on `agent_sdk::map::Map`.
    let kinds = ["MAP_WALL", "MAP_CORNER", "MAP_BEACON", "MAP_TARGET", "MAP_GRID", "MAP_CHECKPOINT"];
    let bad = offending(&kinds, |r| {
        r == "ipc-types/src/lib.rs" || r == "hub/src/core.rs" || r == "agents/agent-sdk/src/map.rs"
    });
    assert!(bad.is_empty(), "the hub's map stream decoded outside agent_sdk::map:\n  {}", bad.join("\n  "));
}

#[test]
fn the_recorder_never_links_the_hub() {
    // Architecture invariant: the recorder (MCAP files) depends on world, ipc-types and records,
    // never on the hub: the hub uses it, replay tools and plots read with it.
    let g = graph();
    assert_links_none(&g, "recorder", |d| d == "hub" || d == "runner", "the recorder must not link the hub");
}

#[test]
fn agents_never_name_the_observers_services() {
    // Architecture invariant: agents see only their robots' sensors and the agents' map. No
    // source of an agent, of the serial bridge or of the Python agent module names the
    // observer crate (true poses, the scenario's obstacles) or the world, observer-map and
    // observer-chairs services; the UDP bridge does only to serve its viewers.
    let drives_robots = |r: &str| {
        ["agents/", "adapters/serial-bridge/", "adapters/serial-protocol/"].iter().any(|a| r.starts_with(a))
            || r == "python/src/lib.rs"
    };
    let needles = ["Observer", "observer::", "observer_map", "observer_chairs", "service::WORLD", ".world(&"];
    let bad = offending(&needles, |r| !drives_robots(r));
    assert!(bad.is_empty(), "agents reading the truth:\n{}", bad.join("\n"));
}

#[test]
fn no_agent_and_no_adapter_that_drives_a_real_chair_links_the_observer() {
    // Architecture invariant: the truth (the `observer` crate) is a capability an agent does
    // not have: no crate under agents/ links it, nor the serial bridge (it drives a real chair)
    // nor the chair emulator; the Python package's agent API cannot reach it either (its
    // referee is a submodule only `iwsim.env` imports, checked below).
    let g = graph();
    let agents = ["agent-sdk", "navigator", "door", "teleop", "wheelchair", "serial-bridge", "chair-emulator"];
    for a in agents {
        assert_links_none(&g, a, |d| d == "observer", &format!("{a} drives robots and must not link the observer"));
    }
    // Every crate under agents/ is in the list: a new agent is checked from its first commit.
    for entry in std::fs::read_dir(root().join("agents")).expect("agents/") {
        let dir = entry.expect("an entry").path();
        let Ok(manifest) = std::fs::read_to_string(dir.join("Cargo.toml")) else { continue };
        let name = manifest
            .lines()
            .find_map(|l| l.strip_prefix("name = ").map(|n| n.trim_matches('"').to_owned()))
            .expect("a package name");
        assert!(agents.contains(&name.as_str()), "new agent {name:?}: add it to this test's list");
    }
}

#[test]
fn the_python_agent_api_never_imports_the_referee() {
    // Architecture invariant: in the Python package, the truth is in `iwsim.referee` (over the
    // native submodule `_iwsim.referee`); the agent API (`iwsim/__init__.py`) and the example
    // agents never import it, and `iwsim.env` is the one module that does.
    let py = root().join("python");
    let mut files: Vec<PathBuf> = Vec::new();
    for dir in ["iwsim", "examples"] {
        for e in std::fs::read_dir(py.join(dir)).expect("python dir").flatten() {
            if e.path().extension().is_some_and(|x| x == "py") {
                files.push(e.path());
            }
        }
    }
    assert!(files.len() >= 4, "the Python package's sources are found: {files:?}");
    let mut bad = Vec::new();
    for f in files {
        let r = rel(&f);
        if r == "python/iwsim/env.py" || r == "python/iwsim/referee.py" {
            continue;
        }
        let text = std::fs::read_to_string(&f).expect("readable");
        for (n, line) in text.lines().enumerate() {
            let code = line.split('#').next().unwrap_or("");
            if ["referee", "observe(", "env_step"].iter().any(|k| code.contains(k)) {
                bad.push(format!("{r}:{}: {}", n + 1, line.trim()));
            }
        }
    }
    assert!(bad.is_empty(), "Python agent code reaching the referee:\n{}", bad.join("\n"));
}

#[test]
fn test_support_is_linked_by_tests_only() {
    // Architecture invariant: no workspace package links `test-support` (the checkers' Python
    // environment) as a normal dependency; tests take it as a dev-dependency, so no process
    // carries test set-up.
    let g = graph();
    for m in g.member_names() {
        assert_links_none(&g, &m, |d| d == "test-support", &format!("{m} must not link test-support"));
    }
}

#[test]
fn only_the_os_layer_calls_the_c_library() {
    // Architecture invariant: production code calls no libc function outside the OS layer
    // (`os/`): poll, terminals, ptys, signals, clocks and process calls go through it, so
    // there is one wrapper of each. libc's constants (signal numbers) may be named anywhere.
    let mut bad = Vec::new();
    for f in sources() {
        let r = rel(&f);
        if r.starts_with("libs/os/") || is_test_file(&r) {
            continue;
        }
        for (n, line) in production_lines(&f) {
            let calls = line.match_indices("libc::").any(|(i, _)| {
                let name: String =
                    line[i + 6..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                name.starts_with(|c: char| c.is_ascii_lowercase()) && line[i + 6 + name.len()..].starts_with('(')
            });
            if calls {
                bad.push(format!("{r}:{n}: {}", line.trim()));
            }
        }
    }
    assert!(bad.is_empty(), "libc called outside the OS layer (os/):\n  {}", bad.join("\n  "));
}

#[test]
fn the_live_hub_and_the_replay_serve_through_one_server() {
    // Architecture invariant: the session's serving ports (registrations, commands, actions)
    // are read in one place, `hub::server::Server`, whose phases both the live hub and the
    // served replay turn through; neither has a serving loop of its own to drift.
    let ports = ["register_server", "control_server", "actions_sub", "doorbell.try_wait"];
    let bad = offending(&ports, |r| r == "hub/src/server.rs" || r == "hub/src/ports.rs");
    assert!(bad.is_empty(), "serving ports read outside hub::server:\n  {}", bad.join("\n  "));
}

#[test]
fn no_two_modules_of_the_hub_import_each_other() {
    // Architecture invariant: the hub's modules form layers (the crate root aside, which
    // declares them): a module never imports, directly or through others, one that imports it.
    let dir = root().join("hub/src");
    let mut uses: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> = Default::default();
    let modules: Vec<String> = std::fs::read_dir(&dir)
        .expect("hub/src")
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.strip_suffix(".rs").map(str::to_owned))
        .filter(|m| m != "lib")
        .collect();
    for m in &modules {
        let lines = production_lines(&dir.join(format!("{m}.rs")));
        let text: String = lines.into_iter().map(|(_, l)| l + "\n").collect();
        let named = modules.iter().filter(|other| {
            *other != m
                && (text.contains(&format!("crate::{other}::"))
                    || text.contains(&format!("crate::{other}}}"))
                    || text.contains(&format!("crate::{other};"))
                    || text.contains(&format!("crate::{{{other}")))
        });
        uses.insert(m.clone(), named.cloned().collect());
    }
    assert!(uses["serve"].contains("server") && uses["replay"].contains("serve"), "the scan reads imports: {uses:?}");
    // Depth-first search for a cycle.
    fn reaches(
        uses: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        from: &str,
        to: &str,
        seen: &mut std::collections::BTreeSet<String>,
    ) -> bool {
        uses[from].iter().any(|n| n == to || (seen.insert(n.clone()) && reaches(uses, n, to, seen)))
    }
    let circles: Vec<&String> = modules.iter().filter(|m| reaches(&uses, m, m, &mut Default::default())).collect();
    assert!(circles.is_empty(), "hub modules in an import circle: {circles:?} ({uses:?})");
}

#[test]
fn the_folders_show_the_parts() {
    // Architecture invariant: the top level shows the parts. `hub/` holds the hub process and
    // what only it runs (the world model, the recorder); the libraries many processes link are
    // under `libs/`, tools under `tools/`, the runner at the top; role folders go one level
    // deep, and a package's folder is named as the package.
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).expect("Cargo.toml");
    let members: Vec<&str> = manifest
        .split("members = [")
        .nth(1)
        .and_then(|m| m.split(']').next())
        .expect("a members list")
        .split(',')
        .map(|m| m.trim().trim_matches('"'))
        .filter(|m| !m.is_empty())
        .collect();
    assert!(members.len() >= 25, "{members:?}");
    let mut wrong = Vec::new();
    for m in &members {
        let toml = std::fs::read_to_string(root().join(m).join("Cargo.toml")).expect("a member's Cargo.toml");
        let name = toml
            .lines()
            .find_map(|l| l.strip_prefix("name = \""))
            .and_then(|l| l.split('"').next())
            .expect("a package name");
        let folder = Path::new(m).file_name().map_or("", |f| f.to_str().unwrap_or(""));
        // The root package is the binary; the test-support and Python packages keep folders
        // named for their place (tests/support, python/).
        let renamed = [(".", "iwsim"), ("tests/support", "test-support"), ("python", "iwsim-python")];
        if folder != name && !renamed.contains(&(m, name)) {
            wrong.push(format!("{m}: package {name} in a folder named otherwise"));
        }
        if m.matches('/').count() > 1 {
            wrong.push(format!("{m}: more than one level below a role folder"));
        }
        if m.starts_with("hub/") && !["hub/world", "hub/recorder"].contains(m) {
            wrong.push(format!("{m}: not the hub's, yet under hub/"));
        }
        let top = m.split('/').next().unwrap_or_default();
        let tops = [
            ".",
            "ipc-types",
            "hub",
            "libs",
            "runner",
            "adapters",
            "agents",
            "viewer",
            "tools",
            "python",
            "tests",
            "benches",
        ];
        if !tops.contains(&top) {
            wrong.push(format!("{m}: a top-level folder not in the layout ({tops:?})"));
        }
    }
    assert!(wrong.is_empty(), "the layout:\n  {}", wrong.join("\n  "));
}
