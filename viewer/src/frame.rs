//! The viewer's wire formats: the map as one JSON text message when a page connects, then
//! compact little-endian binary frames of the world at display rate.
//!
//! Frame layout (all little-endian): `"IWVF"`, version u16 (3), run state u8, reserved u8,
//! tick u64, sim time f64 (s), robot count u32, then per robot 52 bytes: id u32, kind u8,
//! flags u8, reserved u16, x f32 (m), y f32 (m), heading f32 (deg), width f32, height f32,
//! com f32, collisions u32, then 8 proximity readings as u16 millimetres (`NO_READING` past
//! the robot's sensors). f32 positions keep 4 µm over a 100 m lab, far below a pixel; u16
//! millimetres reach 65 m, past any sensor's range. Names and sensor geometry travel in the
//! roster, a JSON text message sent when the set of robots changes.
//!
//! After the robots, the physical chairs (mixed reality, `observer/chairs`): chair count u32
//! (0 in a session without chairs or a served replay), then per chair 52 bytes: robot id u32,
//! sensor mode u8 (`ipc_types::SensorMode`), flags u8 (`ipc_types::CHAIR_*`), reserved u16,
//! the true pose a test bench reports (x f32, y f32 m, heading f32 deg; NaN without
//! `CHAIR_GHOST`), then the 8 real and the 8 virtual readings as u16 millimetres
//! (`NO_READING` for none yet, no echo, or no sensor). The robot's own pose and proximity
//! readings stay those of its robot entry: the odometry pose and what its controller got.

use std::fmt::Write as _;

use agent_sdk::map::{Circle, Map};
use ipc_types::{CHAIR_GHOST, ChairState, MAX_PROXIMITY, RobotInfo, RobotState, WorldHeader};

/// Frame magic.
pub const MAGIC: &[u8; 4] = b"IWVF";
/// Frame version.
pub const VERSION: u16 = 3;
/// Bytes of the frame header.
pub const HEADER_BYTES: usize = 28;
/// Bytes per robot.
pub const ROBOT_BYTES: usize = 52;
/// Bytes of the chair count that follows the robots.
pub const CHAIR_COUNT_BYTES: usize = 4;
/// Bytes per physical chair.
pub const CHAIR_BYTES: usize = 52;
/// A proximity slot with no sensor (or no finite reading).
pub const NO_READING: u16 = u16::MAX;

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
    /// Proximity readings, millimetres; `NO_READING` past the robot's sensors.
    pub proximity_mm: [u16; MAX_PROXIMITY],
}

/// A physical chair as a frame carries it: what mixed reality adds to its robot entry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameChair {
    /// Robot id (the chair's robot entry in the same frame).
    pub robot_id: u32,
    /// `ipc_types::SensorMode` as a byte.
    pub sensor_mode: u8,
    /// `ipc_types::CHAIR_*` bits.
    pub flags: u8,
    /// The true pose a test bench reports: x, y metres, heading degrees; NaN without
    /// `CHAIR_GHOST`.
    pub ghost: [f32; 3],
    /// The chair's real readings, millimetres; `NO_READING` for none yet or no echo.
    pub real_mm: [u16; MAX_PROXIMITY],
    /// The virtual readings on the chair's twin, millimetres; `NO_READING` for no echo.
    pub virtual_mm: [u16; MAX_PROXIMITY],
}

/// A reading in millimetres as a frame carries it.
pub fn reading_mm(m: f32) -> u16 {
    if m.is_finite() && m >= 0.0 { (m * 1000.0).round().min((NO_READING - 1) as f32) as u16 } else { NO_READING }
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
    /// Physical chairs, each one of `robots`.
    pub chairs: Vec<FrameChair>,
}

/// Encodes a world snapshot without chairs as a frame.
pub fn encode(h: &WorldHeader, robots: &[RobotState]) -> Vec<u8> {
    encode_with_chairs(h, robots, &[])
}

/// Whether chair states of `chairs_tick` belong with a world snapshot of `world_tick`. The hub
/// publishes both every tick, the chairs just after the world, so the viewer may read one a
/// tick before the other; anything older is a chair that has gone (the hub publishes no empty
/// slice) or a previous run's sample kept for late subscribers.
pub fn chairs_current(world_tick: u64, chairs_tick: u64) -> bool {
    world_tick.abs_diff(chairs_tick) <= 1
}

/// The chair states to show with a world snapshot: those of a current sample (see
/// [`chairs_current`]) whose robot is in the snapshot.
pub fn chairs_for(world_tick: u64, robots: &[RobotState], chairs: Option<&(u64, Vec<ChairState>)>) -> Vec<ChairState> {
    match chairs {
        Some((tick, cs)) if chairs_current(world_tick, *tick) => {
            cs.iter().filter(|c| robots.iter().any(|r| r.id == c.robot_id)).copied().collect()
        }
        _ => Vec::new(),
    }
}

/// Encodes a world snapshot and its physical chairs as a frame.
pub fn encode_with_chairs(h: &WorldHeader, robots: &[RobotState], chairs: &[ChairState]) -> Vec<u8> {
    let mut v =
        Vec::with_capacity(HEADER_BYTES + robots.len() * ROBOT_BYTES + CHAIR_COUNT_BYTES + chairs.len() * CHAIR_BYTES);
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
        for p in r.proximity_m {
            v.extend_from_slice(&reading_mm(p).to_le_bytes());
        }
    }
    v.extend_from_slice(&(chairs.len() as u32).to_le_bytes());
    for c in chairs {
        v.extend_from_slice(&c.robot_id.to_le_bytes());
        // Modes and flags are small enumerations; anything wider is not a value the page knows.
        v.push(u8::try_from(c.sensor_mode).unwrap_or(u8::MAX));
        v.push(c.flags as u8);
        v.extend_from_slice(&[0, 0]);
        let ghost = if c.flags & CHAIR_GHOST != 0 { c.ghost.map(|g| g as f32) } else { [f32::NAN; 3] };
        for g in ghost {
            v.extend_from_slice(&g.to_le_bytes());
        }
        for p in c.real_m.iter().chain(&c.virtual_m) {
            v.extend_from_slice(&reading_mm(*p).to_le_bytes());
        }
    }
    v
}

/// Decodes a frame; `None` when it is not one.
pub fn decode(b: &[u8]) -> Option<Frame> {
    let u32_at = |i: usize| Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?));
    let u16_at = |i: usize| Some(u16::from_le_bytes(b.get(i..i + 2)?.try_into().ok()?));
    let f32_at = |i: usize| Some(f32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?));
    if b.get(..4)? != MAGIC || u16::from_le_bytes(b.get(4..6)?.try_into().ok()?) != VERSION {
        return None;
    }
    let n = u32_at(24)? as usize;
    let chairs_at = HEADER_BYTES.checked_add(n.checked_mul(ROBOT_BYTES)?)?;
    let chair_count = u32_at(chairs_at)? as usize;
    let first_chair = chairs_at + CHAIR_COUNT_BYTES;
    if b.len() != first_chair.checked_add(chair_count.checked_mul(CHAIR_BYTES)?)? {
        return None;
    }
    let readings = |o: usize| {
        let mut p = [NO_READING; MAX_PROXIMITY];
        for (k, v) in p.iter_mut().enumerate() {
            *v = u16_at(o + 2 * k)?;
        }
        Some(p)
    };
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
                proximity_mm: readings(o + 36)?,
            })
        })
        .collect::<Option<Vec<_>>>()?;
    let chairs = (0..chair_count)
        .map(|k| {
            let o = first_chair + k * CHAIR_BYTES;
            Some(FrameChair {
                robot_id: u32_at(o)?,
                sensor_mode: *b.get(o + 4)?,
                flags: *b.get(o + 5)?,
                ghost: [f32_at(o + 8)?, f32_at(o + 12)?, f32_at(o + 16)?],
                real_mm: readings(o + 20)?,
                virtual_mm: readings(o + 36)?,
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(Frame {
        run_state: b[6],
        tick: u64::from_le_bytes(b.get(8..16)?.try_into().ok()?),
        sim_time_s: f64::from_le_bytes(b.get(16..24)?.try_into().ok()?),
        robots,
        chairs,
    })
}

/// `s` as a JSON string literal.
pub fn json_str(s: &str) -> String {
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
pub fn map_json(map: &Map) -> String {
    let triple = |a: f64, b: f64, c: f64| format!("[{a},{b},{c}]");
    let circles = |cs: &[Circle]| cs.iter().map(|t| triple(t.pos.x, t.pos.y, t.radius_m)).collect::<Vec<_>>();
    let walls: Vec<String> = map
        .walls
        .iter()
        .map(|w| {
            let pts: Vec<String> = w.corners.iter().map(|p| format!("[{},{}]", p.x, p.y)).collect();
            format!("{{\"height\":{},\"obstacle\":{},\"corners\":[{}]}}", w.height_m, w.obstacle, pts.join(","))
        })
        .collect();
    let beacons: Vec<String> = map.beacons.iter().map(|b| triple(b.pos.x, b.pos.y, b.height_m)).collect();
    let grid: Vec<String> = map.grid.iter().map(|g| triple(g.pos.x, g.pos.y, g.heading_deg)).collect();
    let checkpoints: Vec<String> = map.checkpoints.iter().map(|c| triple(c.x, c.y, c.radius)).collect();
    format!(
        "{{\"type\":\"map\",\"name\":{},\"width\":{},\"height\":{},\"walls\":[{}],\"beacons\":[{}],\"targets\":[{}],\"checkpoints\":[{}],\"grid\":[{}]}}",
        json_str(&map.name),
        map.width_m,
        map.height_m,
        walls.join(","),
        beacons.join(","),
        circles(&map.targets).join(","),
        checkpoints.join(","),
        grid.join(",")
    )
}

/// The robots' names and proximity-sensor geometry as a JSON text message, sent when the set
/// of robots changes: `{"type":"roster","robots":[{"id","name","sensors":[[x,y,angle,cone,range]…]}]}`
/// (metres and degrees, in the body frame of the centre of movement).
pub fn roster_json(robots: &[RobotState], sensors: &[RobotInfo]) -> String {
    let entries: Vec<String> = robots
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let info = RobotInfo::find(sensors, k, r.id);
            let geometry: Vec<String> = info
                .map(|s| {
                    s.sensors[..(s.count as usize).min(MAX_PROXIMITY)]
                        .iter()
                        .map(|g| format!("[{},{},{},{},{}]", g.x_m, g.y_m, g.angle_deg, g.cone_deg, g.range_m))
                        .collect()
                })
                .unwrap_or_default();
            format!(
                "{{\"id\":{},\"name\":{},\"sensors\":[{}]}}",
                r.id,
                json_str(info.and_then(|i| i.name.as_str()).unwrap_or("")),
                geometry.join(",")
            )
        })
        .collect();
    format!("{{\"type\":\"roster\",\"robots\":[{}]}}", entries.join(","))
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
            proximity_m: [0.25, 1.0006, 80.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN, f32::NAN],
            standing: Default::default(),
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
            FrameRobot {
                id: 7,
                kind: 2,
                flags: 1,
                pose: [20.25, 6.1, -45.0],
                body: [1.0, 0.1, 0.99],
                collisions: 3,
                // Millimetres, rounded; beyond u16 saturates below the no-reading mark.
                proximity_mm: [250, 1001, 65534, NO_READING, NO_READING, NO_READING, NO_READING, NO_READING],
            }
        );
    }

    fn chair(robot_id: u32, flags: u32) -> ChairState {
        let mut real_m = [f32::NAN; MAX_PROXIMITY];
        real_m[0] = 0.5;
        real_m[1] = f32::INFINITY;
        let mut virtual_m = [f32::NAN; MAX_PROXIMITY];
        virtual_m[..3].copy_from_slice(&[2.0, 3.25, f32::INFINITY]);
        ChairState {
            robot_id,
            sensor_mode: ipc_types::SensorMode::Augmented as u32,
            flags,
            controller: 4,
            ghost: [9.4, 4.8, -10.0],
            real_m,
            virtual_m,
        }
    }

    #[test]
    fn chairs_travel_after_the_robots_with_both_readings_and_the_ghost() {
        use ipc_types::{CHAIR_CONTROLLED, CHAIR_LINK_UP};
        let h = WorldHeader { tick: 7, robot_count: 2, ..WorldHeader::default() };
        let robots = [robot(1, 10.0), robot(2, 12.0)];
        let bytes = encode_with_chairs(&h, &robots, &[chair(2, CHAIR_GHOST | CHAIR_LINK_UP | CHAIR_CONTROLLED)]);
        assert_eq!(bytes.len(), HEADER_BYTES + 2 * ROBOT_BYTES + CHAIR_COUNT_BYTES + CHAIR_BYTES);
        let f = decode(&bytes).expect("a frame");
        assert_eq!(f.robots.len(), 2);
        let n = NO_READING;
        assert_eq!(
            f.chairs,
            vec![FrameChair {
                robot_id: 2,
                sensor_mode: 2,
                flags: 7,
                ghost: [9.4, 4.8, -10.0],
                // None yet (NaN) and no echo (+inf) both mean "nothing to draw".
                real_mm: [500, n, n, n, n, n, n, n],
                virtual_mm: [2000, 3250, n, n, n, n, n, n],
            }]
        );
    }

    #[test]
    fn a_chair_without_a_test_bench_has_no_ghost_whatever_its_pose_field_holds() {
        let f = decode(&encode_with_chairs(&WorldHeader::default(), &[robot(3, 1.0)], &[chair(3, 0)])).expect("frame");
        assert!(f.chairs[0].ghost.iter().all(|g| g.is_nan()), "{:?}", f.chairs[0].ghost);
    }

    #[test]
    fn a_frame_without_chairs_ends_with_a_zero_count() {
        let bytes = encode(&WorldHeader::default(), &[robot(1, 1.0)]);
        assert_eq!(bytes.len(), HEADER_BYTES + ROBOT_BYTES + CHAIR_COUNT_BYTES);
        assert_eq!(&bytes[bytes.len() - 4..], &[0, 0, 0, 0]);
        assert_eq!(decode(&bytes).expect("frame").chairs, vec![]);
        // A version-2 frame (no chair count) is not read as one of this version.
        let mut old = bytes.clone();
        old.truncate(bytes.len() - 4);
        old[4] = 2;
        assert_eq!(decode(&old), None);
    }

    #[test]
    fn a_chair_count_past_the_bytes_is_not_a_frame() {
        let mut bytes = encode_with_chairs(&WorldHeader::default(), &[robot(1, 1.0)], &[chair(1, CHAIR_GHOST)]);
        let at = HEADER_BYTES + ROBOT_BYTES;
        bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(decode(&bytes), None);
        bytes[at..at + 4].copy_from_slice(&2u32.to_le_bytes());
        assert_eq!(decode(&bytes), None);
    }

    #[test]
    fn only_a_current_sample_of_chairs_in_the_world_is_shown() {
        let robots = [robot(1, 1.0), robot(2, 2.0)];
        let sample = (41, vec![chair(1, CHAIR_GHOST), chair(9, 0)]);
        let ids = |cs: Vec<ChairState>| cs.iter().map(|c| c.robot_id).collect::<Vec<_>>();
        // A tick apart either way: the hub publishes the chairs just after the world.
        assert_eq!(ids(chairs_for(41, &robots, Some(&sample))), vec![1], "robot 9 is not in the world");
        assert_eq!(ids(chairs_for(42, &robots, Some(&sample))), vec![1]);
        assert_eq!(ids(chairs_for(40, &robots, Some(&sample))), vec![1]);
        // Older: the chairs have gone (the hub sends no empty slice), or a late subscriber got
        // a previous sample.
        assert_eq!(ids(chairs_for(43, &robots, Some(&sample))), Vec::<u32>::new());
        assert_eq!(ids(chairs_for(41, &robots, None)), Vec::<u32>::new());
    }

    #[test]
    fn a_disc_robot_keeps_its_flag_for_the_page() {
        let disc = RobotState {
            flags: ipc_types::ROBOT_DISC | ipc_types::ROBOT_COLLISION,
            width_m: 1.0,
            height_m: 1.0,
            com: 0.5,
            ..robot(3, 4.0)
        };
        let f = decode(&encode(&WorldHeader { robot_count: 1, ..WorldHeader::default() }, &[disc])).expect("a frame");
        // The page reads bit 8 of the flags byte as "draw a circle of diameter `width`".
        assert_eq!(f.robots[0].flags, 9);
        assert_eq!(f.robots[0].body, [1.0, 1.0, 0.5]);
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
    fn the_map_message_carries_every_item_of_the_hubs_map() {
        use ipc_types::{MAP_BEACON, MAP_CHECKPOINT, MAP_CORNER, MAP_GRID, MAP_TARGET, MAP_WALL, MapHeader, MapItem};
        let item = |kind, index, a, b, c| MapItem { kind, index, a, b, c };
        let mut items = vec![item(MAP_WALL, 0, 2.5, 4.0, 0.0)];
        for (x, y) in [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)] {
            items.push(item(MAP_CORNER, 0, x, y, 0.0));
        }
        items.push(item(MAP_WALL, 1, 1.0, 3.0, 1.0));
        for (x, y) in [(5.0, 5.0), (6.5, 5.0), (6.0, 6.25)] {
            items.push(item(MAP_CORNER, 1, x, y, 0.0));
        }
        items.push(item(MAP_BEACON, 0, 9.0, 7.0, 2.0));
        items.push(item(MAP_TARGET, 0, 4.0, 4.0, 0.4));
        items.push(item(MAP_GRID, 0, 3.0, 3.0, -90.0));
        items.push(item(MAP_CHECKPOINT, 0, 8.0, 2.0, 0.5));
        let header = MapHeader {
            width_m: 10.0,
            height_m: 7.5,
            item_count: items.len() as u32,
            wall_count: 2,
            beacon_count: 1,
            target_count: 1,
            grid_count: 1,
            name: FixedName::new("lab \"B\"").expect("fits"),
            ..MapHeader::default()
        };
        let map = Map::decode(&header, &items).expect("a valid map");
        assert_eq!(
            map_json(&map),
            "{\"type\":\"map\",\"name\":\"lab \\\"B\\\"\",\"width\":10,\"height\":7.5,\"walls\":[\
             {\"height\":2.5,\"obstacle\":false,\"corners\":[[1,1],[2,1],[2,2],[1,2]]},\
             {\"height\":1,\"obstacle\":true,\"corners\":[[5,5],[6.5,5],[6,6.25]]}],\
             \"beacons\":[[9,7,2]],\"targets\":[[4,4,0.4]],\"checkpoints\":[[8,2,0.5]],\"grid\":[[3,3,-90]]}"
        );
    }

    #[test]
    fn the_roster_escapes_names_and_carries_sensor_geometry() {
        let name = FixedName::new("door \"A\"").expect("fits");
        let mut s = RobotInfo { robot_id: 1, count: 2, sensors: [ipc_types::SensorGeometry::default(); 8], name };
        s.sensors[0] = ipc_types::SensorGeometry { x_m: 0.5, y_m: 0.0, angle_deg: 0.0, cone_deg: 60.0, range_m: 4.0 };
        s.sensors[1] = ipc_types::SensorGeometry { x_m: 0.0, y_m: 0.25, angle_deg: 90.0, cone_deg: 30.0, range_m: 2.5 };
        // Names of the longest length come whole.
        let long = RobotInfo { robot_id: 2, count: 0, name: FixedName::new(&"n".repeat(255)).expect("fits"), ..s };
        assert_eq!(
            roster_json(&[robot(1, 0.0), robot(2, 0.0)], &[s, long]),
            format!(
                "{{\"type\":\"roster\",\"robots\":[{{\"id\":1,\"name\":\"door \\\"A\\\"\",\"sensors\":[[0.5,0,0,60,4],[0,0.25,90,30,2.5]]}},\
                 {{\"id\":2,\"name\":\"{}\",\"sensors\":[]}}]}}",
                "n".repeat(255)
            )
        );
        // A robot the roster has no info for yet is listed without a name.
        assert_eq!(
            roster_json(&[robot(3, 0.0)], &[s]),
            "{\"type\":\"roster\",\"robots\":[{\"id\":3,\"name\":\"\",\"sensors\":[]}]}"
        );
    }
}
