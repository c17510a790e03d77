//! The viewer process over real HTTP and WebSocket on 127.0.0.1, with a hub and an agent as
//! real processes.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use tungstenite::Message;
use viewer::frame;

use super::common::{Lines, Proc, session, text};

fn start(s: &str, view_args: &[&str]) -> (Proc, Proc, Proc, SocketAddr) {
    let (hub, agent, view, addr, _) = start_lines(s, view_args);
    (hub, agent, view, addr)
}

/// As [`start`], with the viewer's stderr lines after its first.
fn start_lines(s: &str, view_args: &[&str]) -> (Proc, Proc, Proc, SocketAddr, Lines) {
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
    let lines = view.stderr_lines();
    let url = said(&lines, "open http://");
    (hub, agent, view, url.trim_end_matches('/').parse().expect("address"), lines)
}

/// What follows `marker` on the next line of `lines` that has it (within 20 s).
fn said(lines: &Lines, marker: &str) -> String {
    lines.said(marker, Duration::from_secs(20))
}

fn get(addr: SocketAddr, path: &str) -> String {
    get_as(addr, &addr.to_string(), path)
}

/// A GET of `path` addressed to `host` (its `Host` header), whatever address it is sent to.
fn get_as(addr: SocketAddr, host: &str, path: &str) -> String {
    let mut s = TcpStream::connect(addr).expect("connect");
    write!(s, "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n").expect("send");
    let mut out = String::new();
    s.read_to_string(&mut out).expect("read");
    out
}

type Ws = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

fn ws(addr: SocketAddr) -> Ws {
    let (ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("websocket");
    ws
}

fn next_frame<S: Read + Write>(ws: &mut tungstenite::WebSocket<S>) -> frame::Frame {
    loop {
        if let Message::Binary(b) = ws.read().expect("message") {
            return frame::decode(&b).expect("a valid frame");
        }
    }
}

/// The first frame that shows `n` robots (within 20 s): the agent has registered them all, so
/// stopping the run now cannot catch it half-way through its registrations.
fn frame_with_robots<S: Read + Write>(ws: &mut tungstenite::WebSocket<S>, n: usize) -> frame::Frame {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let f = next_frame(ws);
        if f.robots.len() == n {
            return f;
        }
        assert!(Instant::now() < deadline, "no frame with {n} robots within 20 s");
    }
}

/// Stops the run and checks that the hub, the agent and the viewer all end cleanly.
fn stop_and_expect_clean_exits(s: &str, procs: [Proc; 3]) {
    assert_eq!(agent_sdk::control(s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
    for p in procs {
        let out = p.wait(Duration::from_secs(10));
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
}

/// Waits until the stream shows both chairs (the agent has finished registering, so a stop
/// cannot catch it half-way), then stops as [`stop_and_expect_clean_exits`] does.
fn stop_once_both_chairs_run(s: &str, addr: SocketAddr, procs: [Proc; 3]) {
    frame_with_robots(&mut ws(addr), 2);
    stop_and_expect_clean_exits(s, procs);
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
    stop_and_expect_clean_exits(&s, [hub, agent, view]);
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
        proximity_m: [0.5, 1.25, f32::NAN, f32::NAN, f32::NAN, f32::NAN, f32::NAN, f32::NAN],
        standing: Default::default(),
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

/// A WebSocket handshake to the viewer carrying `origin`; `Err` holds the HTTP status.
fn ws_from(addr: SocketAddr, origin: &str) -> Result<Ws, u16> {
    use tungstenite::client::IntoClientRequest;
    let mut req = format!("ws://{addr}/ws").into_client_request().expect("request");
    req.headers_mut().insert("Origin", origin.parse().expect("header value"));
    match tungstenite::connect(req) {
        Ok((ws, _)) => Ok(ws),
        Err(tungstenite::Error::Http(resp)) => Err(resp.status().as_u16()),
        Err(e) => panic!("handshake failed without an HTTP answer: {e}"),
    }
}

#[test]
fn a_websocket_from_another_origin_is_refused_unless_allowed() {
    let s = session("view-origin");
    let (hub, agent, view, addr, lines) =
        start_lines(&s, &["--allow-control", "--allow-origin", "http://lab.example:8080"]);
    // A page from elsewhere (what a browser sends when evil.example's script opens the socket).
    assert_eq!(ws_from(addr, "http://evil.example").err(), Some(403));
    assert_eq!(ws_from(addr, "http://127.0.0.1:1").err(), Some(403), "another port is another origin");
    // The viewer's own pages, and the origin named with --allow-origin, get the stream.
    for ok in [format!("http://{addr}"), "http://lab.example:8080".to_owned()] {
        let mut w = ws_from(addr, &ok).unwrap_or_else(|status| panic!("{ok} refused with {status}"));
        let Message::Text(map) = w.read().expect("map") else { panic!("the map comes first") };
        assert!(map.contains("\"type\":\"map\""), "{map}");
    }
    // The refusal is reported, naming the origin and the option.
    let line = said(&lines, "refused a WebSocket from origin");
    assert!(line.contains("evil.example") && line.contains("--allow-origin"), "{line}");
    stop_once_both_chairs_run(&s, addr, [hub, agent, view]);
}

/// A WebSocket handshake written by hand on a TCP socket, with exactly these `Host` and
/// `Origin` headers (as a browser sends them): the answer's status and head, and the socket
/// just past the head.
fn handshake(addr: SocketAddr, host: &str, origin: &str) -> (u16, String, TcpStream) {
    let mut tcp = TcpStream::connect(addr).expect("connect");
    tcp.set_read_timeout(Some(Duration::from_secs(10))).expect("timeout");
    write!(
        tcp,
        "GET /ws HTTP/1.1\r\nHost: {host}\r\nOrigin: {origin}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    .expect("send");
    // Byte by byte, so nothing past the head is taken from the socket.
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        assert_eq!(tcp.read(&mut byte).expect("an answer"), 1, "the answer ended in its head: {head:?}");
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head).into_owned();
    let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).expect("a status code");
    (status, head, tcp)
}

/// A page's text message as a client sends it (masked, one frame).
fn masked_text(text: &str) -> Vec<u8> {
    let mask = [0x11u8, 0x22, 0x33, 0x44];
    assert!(text.len() < 126, "a short message");
    let mut frame = vec![0x81, 0x80 | text.len() as u8];
    frame.extend_from_slice(&mask);
    frame.extend(text.bytes().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    frame
}

#[test]
fn a_page_under_another_sites_name_is_refused_even_with_that_sites_origin() {
    // DNS rebinding: attacker.example is made to resolve to 127.0.0.1 once its page has
    // loaded; the page's requests then carry Host: attacker.example and the matching Origin,
    // which the origin check alone took for the viewer's own.
    let s = session("view-rebind");
    let (hub, agent, view, addr, lines) = start_lines(&s, &["--allow-control", "--allow-host", "lab.example"]);
    let (status, head, mut tcp) = handshake(addr, "attacker.example", "http://attacker.example");
    // Its pause goes down the socket whatever the answer; a refused one must get no ack, up
    // to the end of the stream (or 10 s of a stream that does not end).
    let _ = tcp.write_all(&masked_text("pause"));
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut buf = [0u8; 65536];
    while Instant::now() < deadline && !got.windows(5).any(|w| w == b"\"ack\"") {
        match tcp.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
        }
    }
    let acked = got.windows(5).any(|w| w == b"\"ack\"");
    assert!(status == 421 && !acked, "status {status}, pause acked: {acked}\n{head}");
    let body = String::from_utf8_lossy(&got);
    assert!(body.contains("attacker.example") && body.contains("--allow-host"), "{body}");
    // The page under that name is refused too, and the refusal is reported.
    let page = get_as(addr, "attacker.example", "/");
    assert!(page.starts_with("HTTP/1.1 421"), "{page}");
    let line = said(&lines, "refused a request for host");
    assert!(line.contains("attacker.example") && line.contains("--allow-host"), "{line}");

    // The viewer's own address, and a name allowed with --allow-host, are served.
    let lab = format!("lab.example:{}", addr.port());
    assert!(get_as(addr, &lab, "/").starts_with("HTTP/1.1 200 OK"));
    let (status, head, _) = handshake(addr, &lab, &format!("http://{lab}"));
    assert_eq!(status, 101, "{head}");
    let (status, head, tcp) = handshake(addr, &addr.to_string(), &format!("http://{addr}"));
    assert_eq!(status, 101, "{head}");
    let mut w = tungstenite::WebSocket::from_raw_socket(tcp, tungstenite::protocol::Role::Client, None);
    // Both chairs registered first, so the stop below cannot catch the agent half-way.
    frame_with_robots(&mut w, 2);
    w.send(Message::text("pause")).expect("send");
    let reply = loop {
        if let Message::Text(t) = w.read().expect("reply")
            && !t.contains("\"map\"")
            && !t.contains("\"roster\"")
        {
            break t;
        }
    };
    assert!(reply.contains("\"ack\""), "{reply}");
    drop(w);
    stop_and_expect_clean_exits(&s, [hub, agent, view]);
}

#[test]
fn connections_beyond_the_cap_are_refused_and_a_freed_slot_serves_again() {
    let s = session("view-cap");
    let (hub, agent, view, addr) = start(&s, &[]);
    let mut held: Vec<Ws> = (0..viewer::server::MAX_CONNECTIONS).map(|_| ws(addr)).collect();
    for w in &mut held {
        let Message::Text(_) = w.read().expect("map") else { panic!("the map comes first") };
    }
    // One more is answered at once and closed, whatever it asks.
    let mut extra = TcpStream::connect(addr).expect("connect");
    extra.set_read_timeout(Some(Duration::from_secs(10))).expect("timeout");
    let mut answer = String::new();
    extra.read_to_string(&mut answer).expect("an answer, then end of stream");
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    assert!(answer.contains(&format!("at most {} connections", viewer::server::MAX_CONNECTIONS)), "{answer}");
    // A page that leaves frees its slot (once its thread notices, so poll with a bound).
    drop(held.pop());
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        // Until the slot is free the viewer answers 503 and may close before the request is
        // even written: a failed write or read is "not yet", like the 503.
        let page = TcpStream::connect(addr).and_then(|mut c| {
            write!(c, "GET / HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n")?;
            let mut out = String::new();
            c.read_to_string(&mut out).map(|_| out)
        });
        if page.as_deref().is_ok_and(|p| p.starts_with("HTTP/1.1 200 OK")) {
            break;
        }
        assert!(Instant::now() < deadline, "no slot freed: {page:?}");
    }
    drop(held);
    stop_once_both_chairs_run(&s, addr, [hub, agent, view]);
}

#[test]
fn a_websocket_message_over_the_size_bound_closes_its_connection_only() {
    let s = session("view-size");
    let (hub, agent, view, addr) = start(&s, &["--allow-control"]);
    let mut w = ws(addr);
    let bound = viewer::server::MAX_MESSAGE_BYTES;
    // At the bound a message is read (and is no command).
    w.send(Message::text("x".repeat(bound))).expect("send");
    let reply = loop {
        if let Message::Text(t) = w.read().expect("reply")
            && t.contains("\"error\"")
        {
            break t;
        }
    };
    assert!(reply.contains("unknown command"), "{reply}");
    // One byte over, the connection ends; reading it drains frames until it does.
    w.send(Message::text("x".repeat(bound + 1))).expect("send");
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match w.read() {
            Ok(Message::Close(_)) | Err(_) => break,
            Ok(_) => assert!(Instant::now() < deadline, "the connection stayed open"),
        }
    }
    // Everyone else is served as before.
    stop_once_both_chairs_run(&s, addr, [hub, agent, view]);
}

/// Waits for a world snapshot that satisfies `done`; returns it, or the last one seen.
fn watch(
    obs: &mut observer::Observer,
    timeout: Duration,
    done: impl Fn(&ipc_types::WorldHeader, &[ipc_types::RobotState]) -> bool,
) -> (ipc_types::WorldHeader, Vec<ipc_types::RobotState>) {
    let deadline = Instant::now() + timeout;
    let mut last = None;
    loop {
        if let Some((h, robots)) = obs.try_world().expect("world") {
            if done(&h, &robots) {
                return (h, robots);
            }
            last = Some((h, robots));
        }
        if Instant::now() > deadline {
            return last.expect("some snapshot");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn udp_viewers_control_the_run_only_with_allow_control() {
    for allow in [false, true] {
        let s = session("udp-ctl");
        let hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "10", "--no-noise"]);
        let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--robots", "2", "--pose", "10,6.1,0"]);
        let mut bargs = vec!["udp", "--session", &s, "--port", "0"];
        if allow {
            bargs.push("--allow-control");
        }
        let mut bridge = Proc::spawn(&bargs);
        let lines = bridge.stderr_lines();
        let reg: SocketAddr = said(&lines, "registrations on ").parse().expect("address");
        let mut obs =
            observer::Observer::connect_within(&s, "udp-ctl-test", Duration::from_secs(20)).expect("observer");
        let (_, robots) = watch(&mut obs, Duration::from_secs(20), |h, r| h.run_state == 1 && r.len() == 2);
        assert_eq!(robots.len(), 2, "both chairs registered");
        let victim = robots[0].id;

        // A stock Ciber-Rato Viewer: <View/> on the registration port, later traffic to the
        // port that answered.
        let sock = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        sock.set_read_timeout(Some(Duration::from_secs(5))).expect("timeout");
        sock.send_to(b"<View/>\n\0", reg).expect("send");
        let mut buf = [0u8; 65536];
        let (_, port) = sock.recv_from(&mut buf).expect("a reply");
        let send = |xml: &str| {
            sock.send_to(xml.as_bytes(), port).expect("send");
        };
        // The bridge reads a client's datagrams in order: once the lab comes back, the
        // commands before it were handled. The viewer's socket also takes a world update
        // every 10 ms tick; on a loaded machine one reply among them can be lost (UDP), so
        // the request is repeated until a lab arrives; the order argument holds for any copy.
        let handled = || {
            let end = Instant::now() + Duration::from_secs(20);
            let mut buf = [0u8; 65536];
            let mut asked = Instant::now() - Duration::from_secs(1);
            loop {
                if asked.elapsed() >= Duration::from_millis(500) {
                    send("<LabReq/>\n\0");
                    asked = Instant::now();
                }
                let (n, _) = sock.recv_from(&mut buf).expect("datagrams keep coming");
                if buf[..n].starts_with(b"<Lab") {
                    break;
                }
                assert!(Instant::now() < end, "no lab within 20 s");
            }
        };
        send(&format!("<Robot Id=\"{victim}\" Removed=\"Yes\"/>\n\0"));
        handled();
        let (h, robots) = watch(&mut obs, Duration::from_secs(5), |_, r| r.len() == 1);
        assert_eq!(robots.len(), if allow { 1 } else { 2 }, "allow={allow}: robots at tick {}", h.tick);
        send("<Stop/>\n\0");
        handled();
        let (h, _) = watch(&mut obs, Duration::from_secs(5), |h, _| h.run_state == 2);
        assert_eq!(h.run_state == 2, allow, "allow={allow}: paused?");
        send("<Start/>\n\0");
        handled();
        if allow {
            let (h, _) = watch(&mut obs, Duration::from_secs(5), |h, _| h.run_state == 1);
            assert_eq!(h.run_state, 1, "started again");
        }
        obs.close();
        assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
        let b = bridge.wait(Duration::from_secs(10));
        // The process is gone: read its stderr to the end.
        let err = lines.to_end(Duration::from_secs(10)).join("\n");
        assert!(b.status.success(), "bridge: {err}");
        let ignored = if allow { 0 } else { 3 };
        assert!(err.contains(&format!("{ignored} viewer commands ignored")), "{err}");
        assert_eq!(err.contains("--allow-control"), !allow, "the hint is given when a command is ignored: {err}");
        for p in [hub, agent] {
            let _ = p.wait(Duration::from_secs(10));
        }
        super::common::assert_no_shared_memory_left(&s);
    }
}

/// A hub with `robots` chairs in an open 400 m lab, their agent and a viewer: enough robots that
/// the world frames fill a page's socket buffers within seconds once it stops reading. The
/// hub's stdout is drained, so its closing report of every robot cannot block it.
struct Crowd {
    hub: Proc,
    agent: Proc,
    view: Proc,
    addr: SocketAddr,
    dir: std::path::PathBuf,
    _hub_out: Lines,
}

impl Crowd {
    fn start(s: &str, robots: usize) -> Self {
        let dir = std::env::temp_dir().join(format!("iwsim-e2e-{s}"));
        std::fs::create_dir_all(&dir).expect("dir");
        let lab = dir.join("open.xml");
        std::fs::write(&lab, "<Lab Name=\"open\" Width=\"400\" Height=\"400\"></Lab>\n").expect("lab");
        let mut hub = Proc::spawn(&[
            "hub",
            "--session",
            s,
            "--lab",
            lab.to_str().expect("utf-8"),
            "--cycle-ms",
            "10",
            "--no-noise",
        ]);
        let hub_out = hub.stdout_lines();
        let agent = Proc::spawn(&[
            "agent",
            "wheelchair",
            "--session",
            s,
            "--robots",
            &robots.to_string(),
            "--pose",
            "5,5,0",
            "--spacing",
            "1.5",
            "--powers",
            "0.1,0.1",
        ]);
        let mut view = Proc::spawn(&["view", "--session", s, "--http", "127.0.0.1:0"]);
        let lines = view.stderr_lines();
        let addr = said(&lines, "open http://").trim_end_matches('/').parse().expect("address");
        Self { hub, agent, view, addr, dir, _hub_out: hub_out }
    }

    /// Stops the run; the hub and the viewer must end cleanly.
    fn stop(self, s: &str) {
        assert_eq!(agent_sdk::control(s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
        assert!(self.hub.wait(Duration::from_secs(20)).status.success());
        let _ = self.agent.wait(Duration::from_secs(20));
        assert!(self.view.wait(Duration::from_secs(20)).status.success());
        let _ = std::fs::remove_dir_all(self.dir);
    }
}

/// A TCP connection to the viewer whose receive buffer is small (which also stops the kernel
/// growing it), so what the kernel holds for a page that does not read is what a real browser
/// tab would hold, and the viewer's writes block within a second rather than after tens of
/// megabytes.
fn connect_with_small_receive_buffer(addr: SocketAddr) -> TcpStream {
    let tcp = TcpStream::connect(addr).expect("connect");
    let small: libc::c_int = 64 * 1024;
    #[allow(unsafe_code)]
    // SAFETY: a valid socket fd and a c_int option value of the size passed.
    let set = unsafe {
        libc::setsockopt(
            std::os::fd::AsRawFd::as_raw_fd(&tcp),
            libc::SOL_SOCKET,
            libc::SO_RCVBUF,
            (&small as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    assert_eq!(set, 0, "SO_RCVBUF");
    tcp
}

/// The viewer's end of each connection to it (not its listening socket), from the kernel's
/// table, read without touching the sockets (reading one would let the viewer's writes go
/// on): the client's port, whether it is established, and the bytes the viewer has queued
/// for it that the client has not acknowledged.
fn viewer_ends(addr: SocketAddr) -> Vec<(u16, bool, u64)> {
    let table = std::fs::read_to_string("/proc/net/tcp").expect("/proc/net/tcp");
    let port = |a: &str| a.rsplit(':').next().and_then(|p| u16::from_str_radix(p, 16).ok());
    table
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            if f.len() < 5 || port(f[1]) != Some(addr.port()) || port(f[2]) == Some(0) {
                return None;
            }
            let tx_queue = f[4].split(':').next().and_then(|q| u64::from_str_radix(q, 16).ok())?;
            Some((port(f[2])?, f[3] == "01", tx_queue))
        })
        .collect()
}

/// The resident set (`VmRSS`) of process `pid`, in bytes.
fn rss_bytes(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("the process is alive");
    let line = status.lines().find_map(|l| l.strip_prefix("VmRSS:")).expect("VmRSS");
    1024 * line.trim().trim_end_matches("kB").trim().parse::<u64>().expect("a number of kB")
}

#[test]
fn a_page_that_never_reads_is_dropped_after_the_write_timeout() {
    // The world frames of 500 robots fill the socket's buffers within seconds once the page
    // stops reading; then the viewer's writes block, and after IO_TIMEOUT it must drop the page,
    // not hold its thread and buffers for ever.
    let s = session("view-stall");
    let crowd = Crowd::start(&s, 500);
    let addr = crowd.addr;
    let (mut stalled, _) =
        tungstenite::client(format!("ws://{addr}/ws"), connect_with_small_receive_buffer(addr)).expect("websocket");
    // Read until the frames carry every robot, then stop reading: a page whose tab froze. The
    // clock starts before its last read, which sent its last acknowledgement.
    let deadline = Instant::now() + Duration::from_secs(20);
    let stalled_since = loop {
        let before = Instant::now();
        if next_frame(&mut stalled).robots.len() == 500 {
            break before;
        }
        assert!(Instant::now() < deadline, "no frame with 500 robots within 20 s");
    };
    let page_port = stalled.get_ref().local_addr().expect("local address").port();
    // Once its buffers are full the viewer blocks, and after IO_TIMEOUT it must close its end
    // (FIN_WAIT or gone) rather than hold the page for ever.
    let viewer_end_open = || viewer_ends(addr).iter().any(|&(port, established, _)| port == page_port && established);
    assert!(viewer_end_open(), "the viewer's end of the page's connection is established");
    while viewer_end_open() {
        assert!(stalled_since.elapsed() < Duration::from_secs(90), "the viewer kept a page that reads nothing");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        stalled_since.elapsed() >= viewer::server::IO_TIMEOUT,
        "closed after {:?}, before its write timeout",
        stalled_since.elapsed()
    );
    drop(stalled);
    // The viewer itself is fine and serves a new page.
    let mut fresh = ws(addr);
    assert_eq!(next_frame(&mut fresh).robots.len(), 500);
    drop(fresh);
    crowd.stop(&s);
}

#[test]
fn pages_that_never_read_cannot_hold_every_slot_or_grow_the_viewers_memory() {
    // The attack: as many pages as the viewer has slots complete the handshake and then never
    // read. Each must be dropped once its socket has taken no whole frame for IO_TIMEOUT, so a
    // real page gets in, and what the viewer keeps for them must stay small meanwhile.
    let s = session("view-stall-all");
    let crowd = Crowd::start(&s, 500);
    let addr = crowd.addr;
    // The hub has every robot before the pages come, so every frame they are sent is full size.
    let mut obs = observer::Observer::connect_within(&s, "stall-all-test", Duration::from_secs(20)).expect("observer");
    let (_, robots) = watch(&mut obs, Duration::from_secs(60), |_, r| r.len() == 500);
    assert_eq!(robots.len(), 500, "every robot registered");
    obs.close();
    let stalled: Vec<_> = (0..viewer::server::MAX_CONNECTIONS)
        .map(|_| {
            tungstenite::client(format!("ws://{addr}/ws"), connect_with_small_receive_buffer(addr))
                .expect("a slot for each stalled page")
                .0
        })
        .collect();
    let ports: Vec<u16> = stalled.iter().map(|w| w.get_ref().local_addr().expect("local address").port()).collect();
    let stalled_since = Instant::now();
    // IO_TIMEOUT, plus slack for a loaded two-core machine.
    let deadline = stalled_since + viewer::server::IO_TIMEOUT + Duration::from_secs(10);
    // What the viewer holds for the stalled pages, in its memory and in its end of their
    // sockets (the kernel's send queues), measured on its side while they hold their slots.
    let (mut peak_rss, mut peak_queued) = (0, 0);
    let mut measure = || {
        peak_rss = peak_rss.max(rss_bytes(crowd.view.pid()));
        let ends = viewer_ends(addr);
        let queued: u64 = ends.iter().filter(|(port, _, _)| ports.contains(port)).map(|&(_, _, q)| q).sum();
        peak_queued = peak_queued.max(queued);
        ends
    };
    let served = loop {
        measure();
        // A real page: until a slot is free the viewer answers 503 (or closes before the
        // request is even written), which is "not yet".
        let refusal = match tungstenite::connect(format!("ws://{addr}/ws")) {
            Ok((mut page, _)) => {
                if let tungstenite::stream::MaybeTlsStream::Plain(tcp) = page.get_mut() {
                    tcp.set_read_timeout(Some(Duration::from_secs(10))).expect("timeout");
                }
                break next_frame(&mut page);
            }
            Err(e) => e,
        };
        assert!(
            Instant::now() < deadline,
            "no slot came free within {:?} of the stalled pages connecting; the last answer: {refusal}",
            deadline - stalled_since
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(served.robots.len(), 500);
    // Every stalled page is dropped, not just the first.
    while measure().iter().any(|&(port, established, _)| established && ports.contains(&port)) {
        assert!(
            Instant::now() < deadline,
            "stalled pages still held {:?} after they connected",
            stalled_since.elapsed()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        peak_queued < 64 << 20,
        "the viewer queued {} MB in the kernel for pages that read nothing",
        peak_queued >> 20
    );
    assert!(peak_rss < 200 << 20, "the viewer's resident set reached {} MB", peak_rss >> 20);
    drop(stalled);
    crowd.stop(&s);
}
