//! `iwsim plot` end to end through the library: a log and a summary.json, or a recording, on
//! disk in, an SVG file out, read back with quick-xml.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plot::PlotArgs;
use plot::draw::{CHECKPOINT_RGB, ROBOT_RGB, TRAJECTORY_RGB};
use quick_xml::events::Event;

/// A fresh directory for one test, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("iwsim-plot-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Positions of a synthetic run: 0.5 m/s east from (10, 6.1) to (12, 6.1), a quarter turn
/// left about (12, 7.1), then north to (13, 8.6); one row every 0.1 s.
fn run_positions() -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = (0..=40).map(|k| (10.0 + 0.05 * f64::from(k), 6.1)).collect();
    // Arc length π/2 m at 0.05 m a row: 31 steps.
    for k in 1..=31 {
        let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::FRAC_PI_2 * f64::from(k) / 31.0;
        p.push((12.0 + a.cos(), 7.1 + a.sin()));
    }
    p.extend((1..=30).map(|k| (13.0, 7.1 + 0.05 * f64::from(k))));
    p
}

const HEADER: &str = "tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m,proximity1_m,heading_deg,x_m,y_m,collision,contacts,power_left,power_right";

fn write_run(dir: &Path) -> (PathBuf, Vec<(f64, f64)>) {
    let positions = run_positions();
    let mut text = format!("{HEADER}\n");
    for (k, (x, y)) in positions.iter().enumerate() {
        let collision = u8::from(k == 60);
        text += &format!(
            "{},{:.3},{},{},1.5000,NaN,0.000,{x:.4},{y:.4},{collision},{collision},0.500,0.500\n",
            k + 1,
            0.1 * (k + 1) as f64,
            k * 3,
            k * 3
        );
    }
    let log = dir.join("chair1.csv");
    std::fs::write(&log, text).expect("log written");
    let summary = r#"{"scenario":"turn","lab":"builtin:liacc","obstacles":[[13.6,6.0,14.2,6.6,1.0]],
        "checkpoints":[[11,6.1,0.5],[13,8.0,0.5]],"seed":1,"robots":[{"name":"chair1","log":"chair1.csv"}]}"#;
    std::fs::write(dir.join("summary.json"), summary).expect("summary written");
    (log, positions)
}

fn args(log: &Path) -> PlotArgs {
    PlotArgs {
        log: vec![log.into()],
        robot: vec![],
        out: None,
        lab: None,
        obstacle: vec![],
        checkpoint: vec![],
        no_summary: false,
    }
}

/// One SVG element: its name, attributes and the text directly inside it.
#[derive(Debug)]
struct Element {
    name: String,
    attrs: BTreeMap<String, String>,
    text: String,
}

impl Element {
    fn attr(&self, key: &str) -> &str {
        self.attrs.get(key).map_or("", String::as_str)
    }

    fn num(&self, key: &str) -> f64 {
        self.attr(key).parse().unwrap_or(f64::NAN)
    }

    fn points(&self) -> Vec<(f64, f64)> {
        self.attr("points")
            .split_whitespace()
            .map(|p| {
                let (x, y) = p.split_once(',').expect("x,y pair");
                (x.parse().expect("x"), y.parse().expect("y"))
            })
            .collect()
    }
}

/// Parses the SVG with quick-xml, failing on malformed XML, and lists its elements.
fn parse_svg(svg: &str) -> Vec<Element> {
    let mut reader = quick_xml::Reader::from_str(svg);
    let mut elements: Vec<Element> = Vec::new();
    let (mut depth, mut roots, mut open) = (0usize, 0usize, Vec::new());
    loop {
        let event =
            reader.read_event().unwrap_or_else(|e| panic!("malformed SVG at {}: {e}", reader.buffer_position()));
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                if depth == 0 {
                    roots += 1;
                }
                let attrs = e
                    .attributes()
                    .map(|a| {
                        let a = a.expect("well-formed attribute");
                        let value = a.normalized_value(quick_xml::XmlVersion::Implicit1_0).expect("attribute value");
                        let key: &str = a.key.as_ref();
                        (key.to_owned(), value.into_owned())
                    })
                    .collect();
                let qname = e.name();
                let name: &str = qname.as_ref();
                let name = name.to_owned();
                elements.push(Element { name, attrs, text: String::new() });
                if matches!(event, Event::Start(_)) {
                    depth += 1;
                    open.push(elements.len() - 1);
                }
            }
            Event::End(_) => {
                depth = depth.checked_sub(1).expect("an end tag with nothing open");
                open.pop();
            }
            Event::Text(t) => {
                if let Some(&k) = open.last() {
                    elements[k].text += t.xml10_content().trim();
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    assert_eq!(depth, 0, "elements left open at the end");
    assert_eq!(roots, 1, "one root element");
    assert_eq!(elements.first().map(|e| e.name.as_str()), Some("svg"));
    elements
}

fn hex((r, g, b): (u8, u8, u8)) -> String {
    format!("#{r:02X}{g:02X}{b:02X}")
}

#[test]
fn the_svg_is_well_formed_and_draws_the_trajectory_through_the_checkpoints() {
    let dir = TempDir::new("trajectory");
    let (log, positions) = write_run(&dir.0);
    let out = plot::plot(&args(&log)).expect("plotted");
    assert_eq!(out, dir.0.join("chair1.svg"), "default output beside the log");
    let svg = std::fs::read_to_string(&out).expect("SVG written");
    let elements = parse_svg(&svg);

    // The checkpoint circles (the legend's sample ring is smaller) give the metres → pixels map.
    let rings: Vec<&Element> = elements
        .iter()
        .filter(|e| e.name == "circle" && e.attr("stroke") == hex(CHECKPOINT_RGB) && e.num("r") > 10.0)
        .collect();
    assert_eq!(rings.len(), 2, "two checkpoint circles: {rings:?}");
    let (c1, c2) = ((rings[0].num("cx"), rings[0].num("cy")), (rings[1].num("cx"), rings[1].num("cy")));
    let sx = (c2.0 - c1.0) / (13.0 - 11.0);
    let sy = (c2.1 - c1.1) / (8.0 - 6.1);
    assert!(sx > 10.0 && sy < -10.0, "x to the right, y up: {sx} {sy}");
    assert!((sx + sy).abs() / sx < 0.02, "equal scales on both axes: {sx} px/m vs {sy}");
    assert!((rings[0].num("r") - 0.5 * sx).abs() <= 1.0, "radius 0.5 m drawn to scale");
    let project = |(x, y): (f64, f64)| (c1.0 + sx * (x - 11.0), c1.1 + sy * (y - 6.1));

    let trajectory: Vec<&Element> = elements
        .iter()
        .filter(|e| e.name == "polyline" && e.attr("stroke") == hex(TRAJECTORY_RGB))
        .filter(|e| e.points().len() == positions.len())
        .collect();
    assert_eq!(trajectory.len(), 1, "one polyline with a point per row");
    let points = trajectory[0].points();
    for (k, row) in [(0, positions[0]), (positions.len() - 1, positions[positions.len() - 1]), (60, positions[60])] {
        let (px, py) = project(row);
        let (ax, ay) = points[k];
        assert!(
            (ax - px).abs() <= 2.0 && (ay - py).abs() <= 2.0,
            "row {k} at {row:?}: drawn at {:?}, expected {:?}",
            (ax, ay),
            (px, py)
        );
    }

    let texts: Vec<&str> = elements.iter().filter(|e| e.name == "text").map(|e| e.text.as_str()).collect();
    for want in ["chair1.csv", "1", "2", "A", "start", "end", "x (m)", "y (m)", "time (s)", "speed (m/s)"] {
        assert!(texts.contains(&want), "text {want:?} missing from {texts:?}");
    }
    assert!(texts.iter().any(|t| t.starts_with("top speed 0.5")), "top speed in the legend: {texts:?}");
    // The speed line: one point per interval.
    assert!(
        elements.iter().any(|e| e.name == "polyline" && e.points().len() == positions.len() - 1),
        "a speed polyline with one point per interval"
    );
    // The collision row is marked red at its place.
    let (cx, cy) = project(positions[60]);
    assert!(
        elements.iter().any(|e| e.name == "circle"
            && e.attr("fill") == "#D7191E"
            && (e.num("cx") - cx).abs() <= 2.0
            && (e.num("cy") - cy).abs() <= 2.0),
        "collision mark at {cx},{cy}"
    );
}

#[test]
fn the_same_log_gives_the_same_bytes() {
    let dir = TempDir::new("determinism");
    let (log, _) = write_run(&dir.0);
    let mut a = args(&log);
    a.out = Some(dir.0.join("one.svg"));
    let mut b = args(&log);
    b.out = Some(dir.0.join("two.svg"));
    plot::plot(&a).expect("first");
    plot::plot(&b).expect("second");
    let one = std::fs::read(dir.0.join("one.svg")).expect("one");
    let two = std::fs::read(dir.0.join("two.svg")).expect("two");
    assert!(one.len() > 1000);
    assert!(one == two, "two plots of one log differ");
}

#[test]
fn the_command_line_overrides_the_summary() {
    let dir = TempDir::new("override");
    let (log, _) = write_run(&dir.0);
    let mut a = args(&log);
    a.checkpoint = vec!["12,6.1,1.0".into()];
    let svg = std::fs::read_to_string(plot::plot(&a).expect("plotted")).expect("SVG");
    let rings = parse_svg(&svg)
        .into_iter()
        .filter(|e| e.name == "circle" && e.attr("stroke") == hex(CHECKPOINT_RGB) && e.num("r") > 10.0)
        .count();
    assert_eq!(rings, 1, "the one --checkpoint replaces the summary's two");

    a.checkpoint.clear();
    a.no_summary = true;
    let svg = std::fs::read_to_string(plot::plot(&a).expect("plotted")).expect("SVG");
    let elements = parse_svg(&svg);
    assert!(!elements.iter().any(|e| e.name == "circle" && e.attr("stroke") == hex(CHECKPOINT_RGB)));
    assert!(elements.iter().any(|e| e.name == "text" && e.text.starts_with("no map")), "no lab without the summary");
}

#[test]
fn a_bad_summary_or_place_is_an_error_naming_where_it_is() {
    let dir = TempDir::new("bad-summary");
    let (log, _) = write_run(&dir.0);
    let summary = dir.0.join("summary.json");
    std::fs::write(&summary, "{\n  \"lab\": builtin }").expect("written");
    let text = format!("{:#}", plot::plot(&args(&log)).expect_err("not JSON"));
    assert!(text.contains(&format!("{}:2:", summary.display())) && text.contains("not JSON"), "{text}");
    std::fs::write(&summary, r#"{"obstacles":[[1,1,2,2],[3,3,1,4]]}"#).expect("written");
    let text = format!("{:#}", plot::plot(&args(&log)).expect_err("upside down"));
    assert!(text.contains("key `obstacles[1]`: \"3,3,1,4,1\": want X0 < X1"), "{text}");

    let mut a = args(&log);
    a.no_summary = true;
    a.obstacle = vec!["1,2,3".into()];
    let text = format!("{:#}", plot::plot(&a).expect_err("three numbers"));
    assert!(
        text.contains("--obstacle \"1,2,3\" is not an obstacle X0,Y0,X1,Y1[,H]: expected 4 to 5 numbers"),
        "{text}"
    );
    a.obstacle.clear();
    a.checkpoint = vec!["1,2,-1".into()];
    let text = format!("{:#}", plot::plot(&a).expect_err("negative radius"));
    assert!(text.contains("--checkpoint \"1,2,-1\": want finite X, Y and a positive radius R"), "{text}");
}

#[test]
fn a_bad_log_is_an_error_naming_file_line_and_column() {
    let dir = TempDir::new("bad");
    let log = dir.0.join("broken.csv");
    std::fs::write(&log, "tick,time_s,x_m,y_m\n1,0.1,10,6\n2,0.2,ten,6\n").expect("written");
    let err = plot::plot(&args(&log)).expect_err("bad number");
    let text = format!("{err:#}");
    assert!(text.contains("broken.csv:3: column 3 (x_m): `ten` is not a number"), "{text}");
    assert!(!dir.0.join("broken.svg").exists(), "no SVG for a bad log");

    let err = plot::plot(&args(&dir.0.join("missing.csv"))).expect_err("missing");
    assert!(format!("{err:#}").contains("missing.csv: cannot read the log"), "{err:#}");
}

#[test]
fn several_logs_of_one_run_are_drawn_together_a_colour_each() {
    let dir = TempDir::new("several");
    let (one, positions) = write_run(&dir.0);
    // A second robot: the same path shifted 1 m south and driven in half the rows.
    let mut text = format!("{HEADER}\n");
    for (k, (x, y)) in positions.iter().step_by(2).enumerate() {
        text += &format!("{},{:.3},0,0,1.5,NaN,0.0,{x:.4},{:.4},0,0,0.5,0.5\n", k + 1, 0.1 * (k + 1) as f64, y - 1.0);
    }
    let two = dir.0.join("chair2.csv");
    std::fs::write(&two, text).expect("second log written");
    let mut a = args(&one);
    a.log.push(two.clone());
    let out = plot::plot(&a).expect("plotted");
    assert_eq!(out, dir.0.join("trajectories.svg"), "default output for several logs");
    let elements = parse_svg(&std::fs::read_to_string(&out).expect("SVG written"));
    let lines = |rgb, n: usize| {
        elements
            .iter()
            .filter(|e| e.name == "polyline" && e.attr("stroke") == hex(rgb) && e.points().len() == n)
            .count()
    };
    let (n1, n2) = (positions.len(), positions.len().div_ceil(2));
    // Each robot: a trajectory with a point per row and a speed line with one per interval.
    assert_eq!((lines(ROBOT_RGB[0], n1), lines(ROBOT_RGB[0], n1 - 1)), (1, 1), "chair1 in the first colour");
    assert_eq!((lines(ROBOT_RGB[1], n2), lines(ROBOT_RGB[1], n2 - 1)), (1, 1), "chair2 in the second colour");
    let texts: Vec<&str> = elements.iter().filter(|e| e.name == "text").map(|e| e.text.as_str()).collect();
    for want in ["chair1.csv, chair2.csv", "chair1", "chair2", "Trajectories over the map"] {
        assert!(texts.contains(&want), "text {want:?} missing from {texts:?}");
    }
    assert!(texts.iter().any(|t| t.contains("2 robots")), "{texts:?}");
    // A log among the inputs is never overwritten.
    a.out = Some(two);
    assert!(plot::plot(&a).expect_err("would overwrite").to_string().contains("overwrite the log"));
}

/// Records the synthetic run as the hub would: chair1 along [`run_positions`] and a door that
/// stays put, one frame every 0.1 s, the liacc lab with one scenario obstacle and two
/// checkpoints.
fn write_recording(path: &Path) -> Vec<(f64, f64)> {
    use ipc_types::{FixedName, RobotInfo, RobotState};
    use recorder::journal::{Event, RunStart};
    use world::map::{Params, Wall, builtin};

    let mut lab = builtin::map("liacc").expect("built in").lab;
    let obstacle_from = lab.walls.len();
    lab.walls.push(Wall::rectangle(13.6, 6.0, 14.2, 6.6, 1.0));
    let start = RunStart {
        iwsim_version: "0.1.0-test".into(),
        seed: 1,
        dt_s: 0.1,
        lockstep: true,
        tick_limit: 0,
        cycle_ms: 100,
        deadline_ms: 1000,
        lab,
        params: Params::default(),
        grid: Default::default(),
        obstacle_from,
        checkpoints: vec![
            plot::scene::Checkpoint { x: 11.0, y: 6.1, radius: 0.5 },
            plot::scene::Checkpoint { x: 13.0, y: 8.0, radius: 0.5 },
        ],
    };
    let robot = |id, (x_m, y_m): (f64, f64)| RobotState {
        id,
        x_m,
        y_m,
        width_m: 1.1,
        height_m: 0.65,
        com: 0.5,
        ..bytemuck::Zeroable::zeroed()
    };
    let info =
        |id, name: &str| RobotInfo { robot_id: id, name: FixedName::truncated(name), ..bytemuck::Zeroable::zeroed() };
    let infos = [info(1, "chair1"), info(2, "door1")];
    let positions = run_positions();
    let mut rec = recorder::Recorder::create(path, &start, recorder::RecorderOptions::default()).expect("created");
    for (k, &p) in positions.iter().enumerate() {
        let tick = k as u64 + 1;
        rec.event(&Event::Step { tick: tick - 1, actions: Vec::new(), hash: 0 });
        rec.world(tick, &[robot(1, p), robot(2, (9.445, 5.46))], &infos);
    }
    let stats = rec.finish().expect("finished");
    assert_eq!(stats.dropped_world_frames, 0);
    positions
}

#[test]
fn a_recording_is_drawn_with_its_lab_obstacles_and_checkpoints_without_a_summary() {
    let dir = TempDir::new("recording");
    let recording = dir.0.join("run.mcap");
    let positions = write_recording(&recording);
    let out = plot::plot(&args(&recording)).expect("plotted");
    assert_eq!(out, dir.0.join("run.svg"), "default output beside the recording");
    let elements = parse_svg(&std::fs::read_to_string(&out).expect("SVG written"));
    let n = positions.len();
    let lines = |rgb, n: usize| {
        elements
            .iter()
            .filter(|e| e.name == "polyline" && e.attr("stroke") == hex(rgb) && e.points().len() == n)
            .collect::<Vec<_>>()
    };
    // Both robots, in the order they appear: a trajectory with a point per frame and a speed
    // line with one per interval each.
    assert_eq!((lines(ROBOT_RGB[0], n).len(), lines(ROBOT_RGB[0], n - 1).len()), (1, 1), "chair1");
    assert_eq!((lines(ROBOT_RGB[1], n).len(), lines(ROBOT_RGB[1], n - 1).len()), (1, 1), "door1");
    let rings = elements
        .iter()
        .filter(|e| e.name == "circle" && e.attr("stroke") == hex(CHECKPOINT_RGB) && e.num("r") > 10.0)
        .count();
    assert_eq!(rings, 2, "the run start's two checkpoints");
    let texts: Vec<&str> = elements.iter().filter(|e| e.name == "text").map(|e| e.text.as_str()).collect();
    for want in ["run.mcap", "chair1", "door1", "A", "1", "2", "speed (m/s)"] {
        assert!(texts.contains(&want), "text {want:?} missing from {texts:?}");
    }
    assert!(texts.iter().any(|t| t.starts_with("lab ") && t.contains("2 robots")), "{texts:?}");
    assert!(!texts.iter().any(|t| t.contains("ticks in collision")), "a track does not know collisions: {texts:?}");
    assert!(texts.iter().any(|t| t.starts_with("top speed 0.5")), "chair1 drove 0.5 m/s: {texts:?}");

    // One robot by name: drawn alone, in the first colour, the speed line its own.
    let mut a = args(&recording);
    a.robot = vec!["door1".into()];
    a.out = Some(dir.0.join("door1.svg"));
    let elements = parse_svg(&std::fs::read_to_string(plot::plot(&a).expect("plotted")).expect("SVG written"));
    let texts: Vec<&str> = elements.iter().filter(|e| e.name == "text").map(|e| e.text.as_str()).collect();
    assert!(texts.contains(&"run.mcap: door1"), "{texts:?}");
    assert!(texts.iter().any(|t| t.contains("top speed 0.00")), "the door stood still: {texts:?}");
    a.robot = vec!["chair7".into()];
    let err = format!("{:#}", plot::plot(&a).expect_err("no chair7"));
    assert!(err.contains("has no robot named \"chair7\"; it has chair1, door1"), "{err}");
}

#[test]
fn a_log_without_gps_says_to_draw_the_recording_and_dropouts_are_skipped() {
    let dir = TempDir::new("no-gps");
    let log = dir.0.join("chair1.csv");
    let mut text = format!("{HEADER}\n");
    for k in 1..=5 {
        text += &format!("{k},{:.3},0,0,1.5,NaN,NaN,NaN,NaN,0,0,0.5,0.5\n", 0.1 * f64::from(k));
    }
    std::fs::write(&log, &text).expect("written");
    let err = format!("{:#}", plot::plot(&args(&log)).expect_err("no positions"));
    assert_eq!(
        err,
        format!(
            "{} has no positions (the run has no GPS: its x_m, y_m columns are NaN); \
             draw the run's recording instead: iwsim plot {}",
            log.display(),
            dir.0.join("run.mcap").display()
        )
    );
    assert!(!dir.0.join("chair1.svg").exists(), "no SVG");

    // A GPS that drops out: the rows with a fix are drawn, the others counted.
    let mut text = format!("{HEADER}\n");
    for k in 1..=10 {
        let (x, y) = if (4..=6).contains(&k) { (f64::NAN, f64::NAN) } else { (10.0 + 0.05 * f64::from(k), 6.1) };
        text += &format!("{k},{:.3},0,0,1.5,NaN,0.0,{x:.4},{y:.4},0,0,0.5,0.5\n", 0.1 * f64::from(k));
    }
    std::fs::write(&log, &text).expect("written");
    let elements = parse_svg(&std::fs::read_to_string(plot::plot(&args(&log)).expect("plotted")).expect("SVG"));
    assert!(
        elements
            .iter()
            .any(|e| e.name == "polyline" && e.attr("stroke") == hex(TRAJECTORY_RGB) && e.points().len() == 7)
    );
    let texts: Vec<&str> = elements.iter().filter(|e| e.name == "text").map(|e| e.text.as_str()).collect();
    assert!(texts.iter().any(|t| t.contains("7 ticks (3 without a GPS fix)")), "{texts:?}");
    assert!(texts.iter().any(|t| t.starts_with("top speed 0.5")), "speed over the dropout too: {texts:?}");
}

#[test]
fn a_recording_and_logs_are_not_drawn_together_and_robot_needs_a_recording() {
    let dir = TempDir::new("mixed");
    let (log, _) = write_run(&dir.0);
    let recording = dir.0.join("run.mcap");
    write_recording(&recording);
    let mut a = args(&recording);
    a.log.push(log.clone());
    let err = plot::plot(&a).expect_err("mixed").to_string();
    assert!(err.contains("give one recording (.mcap) or the CSV logs of one run"), "{err}");
    let mut a = args(&log);
    a.robot = vec!["chair1".into()];
    let err = plot::plot(&a).expect_err("--robot with a log").to_string();
    assert!(err.contains("--robot picks robots of a recording"), "{err}");
}
