//! The viewer's wire formats: the map as one JSON text message when a page connects, then
//! compact little-endian binary frames of the world at display rate.
//!
//! Frame layout (all little-endian): `"IWVF"`, version u16 (1), run state u8, reserved u8,
//! tick u64, sim time f64 (s), robot count u32, then per robot 40 bytes: id u32, kind u8,
//! flags u8, reserved u16, x f32 (m), y f32 (m), heading f32 (deg), width f32, height f32,
//! com f32, collisions u32 (36 bytes). Names travel in the roster, a JSON text message sent
//! when the set of robots changes.

use std::fmt::Write as _;

use agent_sdk::MapData;
use ipc_types::{MAP_BEACON, MAP_CORNER, MAP_GRID, MAP_TARGET, MAP_WALL, RobotState, WorldHeader};

/// Frame magic.
pub const MAGIC: &[u8; 4] = b"IWVF";
/// Frame version.
pub const VERSION: u16 = 1;
/// Bytes of the frame header.
pub const HEADER_BYTES: usize = 28;
/// Bytes per robot.
pub const ROBOT_BYTES: usize = 36;

/// One robot as a frame carries it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameRobot {
    /// Robot id.
    pub id: u32,
    /// `ipc_types::RobotKind` as a byte.
    pub kind: u8,
    /// Low byte of `ipc_types::ROBOT_*` flags.
    pub flags: u8,
    /// Pose: x, y metres, heading degrees.
    pub pose: [f32; 3],
    /// Body: width, height metres, centre of movement.
    pub body: [f32; 3],
    /// Contacts so far.
    pub collisions: u32,
}

/// A decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Run state (`ipc_types::RunState` as a byte).
    pub run_state: u8,
    /// Tick.
    pub tick: u64,
    /// Simulated seconds.
    pub sim_time_s: f64,
    /// Robots.
    pub robots: Vec<FrameRobot>,
}

/// Encodes a world snapshot as a frame.
pub fn encode(h: &WorldHeader, robots: &[RobotState]) -> Vec<u8> {
    let mut v = Vec::with_capacity(HEADER_BYTES + robots.len() * ROBOT_BYTES);
    v.extend_from_slice(MAGIC);
    v.extend_from_slice(&VERSION.to_le_bytes());
    v.push(h.run_state as u8);
    v.push(0);
    v.extend_from_slice(&h.tick.to_le_bytes());
    v.extend_from_slice(&h.sim_time_s.to_le_bytes());
    v.extend_from_slice(&(robots.len() as u32).to_le_bytes());
    for r in robots {
        v.extend_from_slice(&r.id.to_le_bytes());
        v.push(r.kind as u8);
        v.push(r.flags as u8);
        v.extend_from_slice(&[0, 0]);
        for f in [r.x_m as f32, r.y_m as f32, r.heading_deg as f32, r.width_m, r.height_m, r.com] {
            v.extend_from_slice(&f.to_le_bytes());
        }
        v.extend_from_slice(&r.collision_count.to_le_bytes());
    }
    v
}

/// Decodes a frame; `None` when it is not one.
pub fn decode(b: &[u8]) -> Option<Frame> {
    let u32_at = |i: usize| Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?));
    let f32_at = |i: usize| Some(f32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?));
    if b.get(..4)? != MAGIC || u16::from_le_bytes(b.get(4..6)?.try_into().ok()?) != VERSION {
        return None;
    }
    let n = u32_at(24)? as usize;
    if b.len() != HEADER_BYTES + n.checked_mul(ROBOT_BYTES)? {
        return None;
    }
    let robots = (0..n)
        .map(|k| {
            let o = HEADER_BYTES + k * ROBOT_BYTES;
            Some(FrameRobot {
                id: u32_at(o)?,
                kind: *b.get(o + 4)?,
                flags: *b.get(o + 5)?,
                pose: [f32_at(o + 8)?, f32_at(o + 12)?, f32_at(o + 16)?],
                body: [f32_at(o + 20)?, f32_at(o + 24)?, f32_at(o + 28)?],
                collisions: u32_at(o + 32)?,
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(Frame {
        run_state: b[6],
        tick: u64::from_le_bytes(b.get(8..16)?.try_into().ok()?),
        sim_time_s: f64::from_le_bytes(b.get(16..24)?.try_into().ok()?),
        robots,
    })
}

fn json_str(s: &str) -> String {
    let mut o = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(o, "\\u{:04x}", c as u32);
            }
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// The map as the JSON text message a page gets first.
pub fn map_json(map: &MapData) -> String {
    let h = &map.header;
    let mut walls: Vec<(f64, Vec<(f64, f64)>)> = Vec::new();
    let (mut beacons, mut targets, mut grid) = (Vec::new(), Vec::new(), Vec::new());
    for i in &map.items {
        match i.kind {
            MAP_WALL => walls.push((i.a, Vec::new())),
            MAP_CORNER => {
                if let Some(w) = walls.last_mut() {
                    w.1.push((i.a, i.b));
                }
            }
            MAP_BEACON => beacons.push(format!("[{},{},{}]", i.a, i.b, i.c)),
            MAP_TARGET => targets.push(format!("[{},{},{}]", i.a, i.b, i.c)),
            MAP_GRID => grid.push(format!("[{},{},{}]", i.a, i.b, i.c)),
            _ => {}
        }
    }
    let walls: Vec<String> = walls
        .iter()
        .map(|(height, c)| {
            let pts: Vec<String> = c.iter().map(|(x, y)| format!("[{x},{y}]")).collect();
            format!("{{\"height\":{height},\"corners\":[{}]}}", pts.join(","))
        })
        .collect();
    format!(
        "{{\"type\":\"map\",\"name\":{},\"width\":{},\"height\":{},\"walls\":[{}],\"beacons\":[{}],\"targets\":[{}],\"grid\":[{}]}}",
        json_str(h.name.as_str().unwrap_or("")),
        h.width_m,
        h.height_m,
        walls.join(","),
        beacons.join(","),
        targets.join(","),
        grid.join(",")
    )
}

/// The robots' names as a JSON text message, sent when the set of robots changes.
pub fn roster_json(robots: &[RobotState]) -> String {
    let names: Vec<String> =
        robots.iter().map(|r| format!("[{},{}]", r.id, json_str(r.name.as_str().unwrap_or("")))).collect();
    format!("{{\"type\":\"roster\",\"names\":[{}]}}", names.join(","))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::FixedName;

    fn robot(id: u32, x: f64) -> RobotState {
        RobotState {
            id,
            kind: 2,
            flags: 1,
            collision_count: 3,
            x_m: x,
            y_m: 6.1,
            heading_deg: -45.0,
            width_m: 1.0,
            height_m: 0.1,
            com: 0.99,
            agent_id: 1,
            motor_out: [0.0; 2],
            name: FixedName::new("door \"A\"").expect("fits"),
        }
    }

    #[test]
    fn frames_decode_to_what_was_encoded() {
        let h = WorldHeader { tick: 42, sim_time_s: 4.2, run_state: 1, robot_count: 2, ..WorldHeader::default() };
        let robots = [robot(1, 10.5), robot(7, 20.25)];
        let f = decode(&encode(&h, &robots)).expect("a frame");
        assert_eq!((f.tick, f.sim_time_s, f.run_state), (42, 4.2, 1));
        assert_eq!(f.robots.len(), 2);
        assert_eq!(
            f.robots[1],
            FrameRobot { id: 7, kind: 2, flags: 1, pose: [20.25, 6.1, -45.0], body: [1.0, 0.1, 0.99], collisions: 3 }
        );
    }

    #[test]
    fn truncated_or_foreign_bytes_are_not_frames() {
        let h = WorldHeader::default();
        let mut b = encode(&h, &[robot(1, 1.0)]);
        b.pop();
        assert_eq!(decode(&b), None);
        assert_eq!(decode(b"IWVX"), None);
        assert_eq!(decode(&[]), None);
    }

    #[test]
    fn names_are_escaped_in_the_roster() {
        assert_eq!(roster_json(&[robot(1, 0.0)]), "{\"type\":\"roster\",\"names\":[[1,\"door \\\"A\\\"\"]]}");
    }
}
