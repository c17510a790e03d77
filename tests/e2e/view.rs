//! The viewer process over real HTTP and WebSocket on 127.0.0.1, with a hub and an agent as
//! real processes.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use tungstenite::Message;
use viewer::frame;

use super::common::{Proc, session, text};

fn start(s: &str, view_args: &[&str]) -> (Proc, Proc, Proc, SocketAddr) {
    let hub = Proc::spawn(&["hub", "--session", s, "--cycle-ms", "10", "--no-noise"]);
    let agent = Proc::spawn(&[
        "agent",
        "wheelchair",
        "--session",
        s,
        "--robots",
        "2",
        "--pose",
        "10,6.1,0",
        "--powers",
        "0.6,0.5",
    ]);
    let mut args = vec!["view", "--session", s, "--http", "127.0.0.1:0"];
    args.extend_from_slice(view_args);
    let mut view = Proc::spawn(&args);
    let url = view.announced("open http://", Duration::from_secs(20));
    (hub, agent, view, url.trim_end_matches('/').parse().expect("address"))
}

fn get(addr: SocketAddr, path: &str) -> String {
    let mut s = TcpStream::connect(addr).expect("connect");
    write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").expect("send");
    let mut out = String::new();
    s.read_to_string(&mut out).expect("read");
    out
}

type Ws = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

fn ws(addr: SocketAddr) -> Ws {
    let (ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("websocket");
    ws
}

fn next_frame(ws: &mut Ws) -> frame::Frame {
    loop {
        if let Message::Binary(b) = ws.read().expect("message") {
            return frame::decode(&b).expect("a valid frame");
        }
    }
}

#[test]
fn the_page_and_the_stream_show_the_map_and_every_robot() {
    let s = session("view");
    let (hub, agent, view, addr) = start(&s, &[]);
    let page = get(addr, "/");
    assert!(
        page.starts_with("HTTP/1.1 200 OK") && page.contains("<canvas id=\"view2d\">") && page.contains("app.js"),
        "{page}"
    );
    assert!(get(addr, "/app.js").contains("function decodeFrame"));
    assert!(get(addr, "/view3d.js").contains("export function createView3D"));
    let three = get(addr, "/three-LICENSE.txt");
    assert!(three.starts_with("HTTP/1.1 200 OK") && three.contains("MIT"), "{three}");
    assert!(get(addr, "/index.html?view=3d").starts_with("HTTP/1.1 200 OK"));
    assert!(get(addr, "/nope").starts_with("HTTP/1.1 404"));

    let mut w = ws(addr);
    let Message::Text(map) = w.read().expect("map") else { panic!("the map comes first, as text") };
    assert!(
        map.contains("\"type\":\"map\"") && map.contains("\"name\":\"IW_LIACC\"") && map.contains("\"width\":44"),
        "{map}"
    );
    assert_eq!(map.matches("\"height\":2.5").count(), 23, "23 walls of 2.5 m");
    // The roster is re-sent as robots come (and their sensor geometry after them): wait for
    // the one that has both chairs.
    let roster = loop {
        if let Message::Text(t) = w.read().expect("roster")
            && t.contains("\"chair1\"")
            && t.contains("\"chair2\"")
        {
            break t;
        }
    };
    assert!(roster.contains("\"chair1\"") && roster.contains("\"chair2\""), "{roster}");
    let first = next_frame(&mut w);
    assert_eq!(first.robots.len(), 2);
    assert!(first.robots.iter().all(|r| r.body == [1.0, 1.0, 0.5]));
    // Robots drive: later frames move them forward, and frames come at most 60 a second
    // although the hub ticks 100 times a second.
    let start = Instant::now();
    let mut n = 0;
    let mut last = first.clone();
    while start.elapsed() < Duration::from_secs(1) {
        last = next_frame(&mut w);
        n += 1;
    }
    assert!(n <= 63, "{n} frames in 1 s");
    assert!(n >= 10, "only {n} frames in 1 s");
    assert!(last.tick > first.tick + 30);
    assert!(last.robots[0].pose[0] > first.robots[0].pose[0], "chair1 moves");
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
    for p in [hub, agent, view] {
        let out = p.wait(Duration::from_secs(10));
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
}

#[test]
fn pages_control_the_run_only_with_allow_control() {
    for allow in [false, true] {
        let s = session("view-ctl");
        let (hub, agent, view, addr) = start(&s, if allow { &["--allow-control"] } else { &[] });
        let mut w = ws(addr);
        next_frame(&mut w);
        w.send(Message::text("pause")).expect("send");
        let reply = loop {
            if let Message::Text(t) = w.read().expect("reply")
                && !t.contains("\"map\"")
                && !t.contains("\"roster\"")
            {
                break t;
            }
        };
        assert_eq!(reply.contains("\"ack\""), allow, "{reply}");
        assert_eq!(reply.contains("control is off"), !allow, "{reply}");
        // The run state in the frames says whether the hub obeyed (2 = paused).
        let deadline = Instant::now() + Duration::from_secs(5);
        let paused = loop {
            let f = next_frame(&mut w);
            if f.run_state == 2 || Instant::now() > deadline {
                break f.run_state == 2;
            }
        };
        assert_eq!(paused, allow);
        assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
        for p in [hub, agent, view] {
            let _ = p.wait(Duration::from_secs(10));
        }
    }
}

#[test]
fn the_pages_decoder_reads_what_the_viewer_encodes() {
    // The page's own JavaScript, run by node on a frame made here.
    let h = ipc_types::WorldHeader { tick: 9, sim_time_s: 0.9, run_state: 1, ..Default::default() };
    let robots = [ipc_types::RobotState {
        id: 4,
        kind: 0,
        flags: 1,
        collision_count: 2,
        x_m: 12.5,
        y_m: 6.25,
        heading_deg: 30.0,
        width_m: 1.2,
        height_m: 0.7,
        com: 0.8,
        agent_id: 1,
        motor_out: [0.0; 2],
        name: ipc_types::FixedName::new("c").expect("fits"),
        proximity_m: [0.5, 1.25, f32::NAN, f32::NAN, f32::NAN, f32::NAN, f32::NAN, f32::NAN],
    }];
    let bytes = frame::encode(&h, &robots);
    let dir = std::env::temp_dir().join(format!("iwsim-view-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let bin = dir.join("frame.bin");
    std::fs::write(&bin, &bytes).expect("write");
    let script = format!(
        "const {{decodeFrame, corners}} = require({:?}); const b = require('fs').readFileSync({:?}); \
         const f = decodeFrame(b.buffer.slice(b.byteOffset, b.byteOffset + b.length)); \
         const r = f.robots[0]; console.log(JSON.stringify([f.tick, f.simTime, f.runState, r.id, r.flags, r.x, r.y, r.heading, r.width, r.height, r.com, r.collisions, r.proximity[0], r.proximity[1], r.proximity[2] === null ? -1 : 0, corners(r)[0]]));",
        concat!(env!("CARGO_MANIFEST_DIR"), "/viewer/static/app.js"),
        bin.to_str().expect("utf-8")
    );
    let out = std::process::Command::new("node").arg("-e").arg(script).output().expect("node runs");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let got = String::from_utf8_lossy(&out.stdout);
    let decoded = frame::decode(&bytes).expect("frame");
    let r = &decoded.robots[0];
    // Front-right corner of a 1.2 × 0.7, COM 0.8 chair at 30°: (0.96, −0.35) rotated.
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let fr = (12.5 + c * 0.96 + s * 0.35, 6.25 + s * 0.96 - c * 0.35);
    let want = [
        9.0,
        0.9,
        1.0,
        4.0,
        1.0,
        r.pose[0] as f64,
        r.pose[1] as f64,
        r.pose[2] as f64,
        r.body[0] as f64,
        r.body[1] as f64,
        r.body[2] as f64,
        2.0,
        0.5,
        1.25,
        -1.0,
    ];
    let nums: Vec<f64> = got
        .trim()
        .trim_matches(['[', ']'])
        .split(',')
        .map(|x| x.trim_matches(['[', ']']).parse().expect("number"))
        .collect();
    for (k, w) in want.iter().enumerate() {
        assert!((nums[k] - w).abs() < 1e-6, "field {k}: {} vs {w} in {got}", nums[k]);
    }
    assert!((nums[15] - fr.0).abs() < 1e-4 && (nums[16] - fr.1).abs() < 1e-4, "corner {got} vs {fr:?}");
    let _ = std::fs::remove_dir_all(dir);
}
