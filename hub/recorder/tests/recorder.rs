//! The recorder as the hub and a reader use it: a short run of a real world recorded, read back,
//! replayed, cut short, and checked by the third-party Python reader.

use std::path::{Path, PathBuf};

use ipc_types::{FixedName, ROBOT_COLLISION, RobotInfo, RobotState, SensorGeometry};
use places::Checkpoint;
use recorder::journal::{Event, RecordedAction, RunStart};
use world::map::{Params, Wall, builtin};
use world::{Action, RobotHandle, RobotSpec, World};

/// A fresh per-test directory, removed when the test ends.
struct Scratch(PathBuf);

impl Scratch {
    fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn scratch(test: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("iwsim-recorder-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    Scratch(dir)
}

fn run_start() -> RunStart {
    let mut lab = builtin::map("liacc").expect("built in").lab;
    let obstacle_from = lab.walls.len();
    lab.walls.push(Wall::rectangle(17.0, 6.1, 17.6, 6.4, 1.0));
    RunStart {
        iwsim_version: "0.1.0-test".into(),
        seed: 7,
        dt_s: 0.1,
        lockstep: true,
        tick_limit: 0,
        cycle_ms: 100,
        deadline_ms: 1000,
        lab,
        params: Params::default(),
        grid: Default::default(),
        obstacle_from,
        checkpoints: vec![Checkpoint { x: 12.0, y: 6.1, radius: 0.5 }],
    }
}

/// What the hub hands the recorder, in order.
enum Call {
    Event(Event),
    World(u64, Vec<RobotState>, Vec<RobotInfo>),
}

/// The world's robots as the hub publishes them.
fn snapshot(world: &World, ids: &[(u32, RobotHandle)]) -> (Vec<RobotState>, Vec<RobotInfo>) {
    let mut states = Vec::new();
    let mut sensors = Vec::new();
    for &(id, h) in ids {
        let Some(r) = world.robot(h) else { continue };
        let mut proximity_m = [f32::NAN; ipc_types::MAX_PROXIMITY];
        for (out, &d) in proximity_m.iter_mut().zip(r.readings.proximity()) {
            *out = d as f32;
        }
        states.push(RobotState {
            id,
            flags: if r.collision { ROBOT_COLLISION } else { 0 },
            x_m: r.pose.x,
            y_m: r.pose.y,
            heading_deg: r.pose.heading_deg(),
            width_m: r.spec.width_m as f32,
            height_m: r.spec.height_m as f32,
            com: r.spec.com as f32,
            agent_id: 1,
            proximity_m,
            ..bytemuck::Zeroable::zeroed()
        });
        let mut g =
            RobotInfo { robot_id: id, name: FixedName::truncated(&r.spec.name), ..bytemuck::Zeroable::zeroed() };
        // Four cones to the front and sides, as viewers get them.
        for (k, angle) in [0.0f32, 60.0, -60.0, 180.0].into_iter().enumerate() {
            g.sensors[k] = SensorGeometry { x_m: 0.5, y_m: 0.0, angle_deg: angle, cone_deg: 60.0, range_m: 3.0 };
        }
        g.count = r.readings.proximity().len().min(4) as u32;
        sensors.push(g);
    }
    (states, sensors)
}

/// A real world run for `ticks` ticks with three chairs (the third leaves half way), as the
/// sequence of recorder calls the hub makes, and the final world.
fn simulated_run(start: &RunStart, ticks: u64) -> (Vec<Call>, World) {
    let map = builtin::map("liacc").expect("built in");
    let mut world = World::new(&start.lab, start.params.clone(), start.seed).expect("valid lab");
    let mut calls = Vec::new();
    let mut ids = Vec::new();
    for (k, p) in map.grid.poses.iter().take(3).enumerate() {
        let id = k as u32 + 1;
        let mut spec = RobotSpec::at(p.pos.x, p.pos.y, p.heading_deg);
        spec.name = format!("chair-{id}");
        let h = world.add_robot(spec.clone()).expect("free start");
        ids.push((id, h));
        calls.push(Call::Event(Event::AddRobot { id, agent_id: 1, spec }));
    }
    calls.push(Call::Event(Event::Settle));
    for tick in 0..ticks {
        if tick == ticks / 2 {
            let (id, h) = ids.pop().expect("three robots");
            world.remove_robot(h);
            calls.push(Call::Event(Event::RemoveRobot { id }));
        }
        let recorded: Vec<RecordedAction> = ids
            .iter()
            .map(|&(id, _)| {
                let turn = (tick as f64 * 0.05 + f64::from(id)).sin() * 0.3;
                RecordedAction { id, motors: Some([0.6 - turn, 0.6 + turn]), pose: None, say: None, leds: id }
            })
            .collect();
        let actions = actions_for(&recorded, &ids);
        world.step(&actions, start.dt_s);
        calls.push(Call::Event(Event::Step { tick, actions: recorded, hash: world.state_hash() }));
        let (states, sensors) = snapshot(&world, &ids);
        calls.push(Call::World(tick + 1, states, sensors));
    }
    calls.push(Call::Event(Event::Finish { tick: ticks, reason: "time limit".into() }));
    (calls, world)
}

fn actions_for(recorded: &[RecordedAction], ids: &[(u32, RobotHandle)]) -> Vec<Action> {
    recorded
        .iter()
        .filter_map(|a| {
            let &(_, h) = ids.iter().find(|(id, _)| *id == a.id)?;
            let [l, r] = a.motors?;
            Some(Action::motors(h, l, r))
        })
        .collect()
}

fn record(path: &Path, start: &RunStart, calls: &[Call], options: recorder::RecorderOptions) -> recorder::RecordStats {
    let mut rec = recorder::Recorder::create(path, start, options).expect("create");
    for call in calls {
        match call {
            Call::Event(e) => rec.event(e),
            Call::World(tick, states, sensors) => rec.world(*tick, states, sensors),
        }
    }
    rec.finish().expect("finish")
}

fn events_of(calls: &[Call]) -> Vec<Event> {
    calls
        .iter()
        .filter_map(|c| match c {
            Call::Event(e) => Some(e.clone()),
            Call::World(..) => None,
        })
        .collect()
}

mod journal {
    use super::*;
    use proptest::prelude::*;
    use recorder::journal::{JournalDecodeError, decode_event, decode_run_start, encode_event, encode_run_start};
    use world::map::{Beacon, ChallengeParams, Lab, LatencyParams, NoiseParams, RequestParams, SensorSwitches, Target};
    use world::math::Pose;
    use world::{BodyShape, ProximitySpec, RobotKind};

    fn any_pose() -> impl Strategy<Value = Pose> {
        (any::<f64>(), any::<f64>(), any::<f64>()).prop_map(|(x, y, theta)| Pose { x, y, theta })
    }

    fn any_point() -> impl Strategy<Value = (f64, f64)> {
        (any::<f64>(), any::<f64>())
    }

    fn point((x, y): (f64, f64)) -> Pose {
        Pose { x, y, theta: 0.0 }
    }

    fn any_spec() -> impl Strategy<Value = RobotSpec> {
        let sensor =
            (any::<f64>(), any::<f64>(), any::<f64>(), any::<f64>(), proptest::option::of(any::<f64>())).prop_map(
                |(x_m, y_m, angle_rad, cone_rad, range_m)| ProximitySpec { x_m, y_m, angle_rad, cone_rad, range_m },
            );
        (
            ".{0,20}",
            prop_oneof![Just(RobotKind::Simulated), Just(RobotKind::Real), Just(RobotKind::Door)],
            prop_oneof![Just(BodyShape::Rectangle), Just(BodyShape::Disc)],
            proptest::array::uniform5(any::<f64>()),
            any_pose(),
            proptest::collection::vec(sensor, 0..9),
        )
            .prop_map(
                |(name, kind, shape, [width_m, height_m, com, max_speed_mps, accel_curve], pose, sensors)| RobotSpec {
                    name,
                    kind,
                    shape,
                    width_m,
                    height_m,
                    com,
                    max_speed_mps,
                    accel_curve,
                    pose,
                    sensors,
                },
            )
    }

    fn any_action() -> impl Strategy<Value = RecordedAction> {
        (
            any::<u32>(),
            proptest::option::of(proptest::array::uniform2(any::<f64>())),
            proptest::option::of(any_pose()),
            proptest::option::of(proptest::collection::vec(any::<u8>(), 0..40)),
            any::<u32>(),
        )
            .prop_map(|(id, motors, pose, say, leds)| RecordedAction { id, motors, pose, say, leds })
    }

    fn any_event() -> impl Strategy<Value = Event> {
        prop_oneof![
            (any::<u32>(), any::<u32>(), any_spec()).prop_map(|(id, agent_id, spec)| Event::AddRobot {
                id,
                agent_id,
                spec
            }),
            any::<u32>().prop_map(|id| Event::RemoveRobot { id }),
            (any::<u32>(), any::<bool>()).prop_map(|(id, frozen)| Event::Freeze { id, frozen }),
            Just(Event::Settle),
            (any::<u64>(), proptest::collection::vec(any_action(), 0..6), any::<u64>())
                .prop_map(|(tick, actions, hash)| Event::Step { tick, actions, hash }),
            (any::<u64>(), ".{0,30}").prop_map(|(tick, reason)| Event::Finish { tick, reason }),
        ]
    }

    fn any_lab() -> impl Strategy<Value = Lab> {
        let wall = (any::<f64>(), proptest::collection::vec(any_point(), 0..6))
            .prop_map(|(height_m, c)| Wall { height_m, corners: c.into_iter().map(|p| point(p).position()).collect() });
        let beacon =
            (any_point(), any::<f64>()).prop_map(|(p, height_m)| Beacon { pos: point(p).position(), height_m });
        let target =
            (any_point(), any::<f64>()).prop_map(|(p, radius_m)| Target { pos: point(p).position(), radius_m });
        (
            ".{0,20}",
            any::<f64>(),
            any::<f64>(),
            proptest::collection::vec(wall, 0..5),
            proptest::collection::vec(beacon, 0..3),
            proptest::collection::vec(target, 0..3),
        )
            .prop_map(|(name, width_m, height_m, walls, beacons, targets)| Lab {
                name,
                width_m,
                height_m,
                walls,
                beacons,
                targets,
            })
    }

    fn any_params() -> impl Strategy<Value = Params> {
        (
            any::<u64>(),
            any::<u32>(),
            proptest::array::uniform7(any::<f64>()),
            proptest::array::uniform6(any::<u32>()),
            proptest::array::uniform3(any::<bool>()),
            (any::<u32>(), proptest::array::uniform5(any::<bool>())),
            proptest::array::uniform4(any::<f64>()),
            any::<u32>(),
            (any::<u64>(), any::<bool>(), proptest::array::uniform6(any::<u32>()), any::<f64>()),
        )
            .prop_map(|(sim_time_ticks, cycle_ms, n, l, s, (per_cycle, r), f, encoder_ticks_per_rev, c)| {
                Params {
                    sim_time_ticks,
                    cycle_ms,
                    noise: NoiseParams {
                        proximity_m: n[0],
                        beacon_deg: n[1],
                        compass_deg: n[2],
                        gps_pos_m: n[3],
                        gps_heading_deg: n[4],
                        motor_frac: n[5],
                        encoder_slip_frac: n[6],
                        line_flip_prob: c.3,
                    },
                    latency: LatencyParams {
                        proximity: l[0],
                        beacon: l[1],
                        ground: l[2],
                        compass: l[3],
                        collision: l[4],
                        gps: l[5],
                    },
                    sensors: SensorSwitches { gps: s[0], beacon: s[1], compass: s[2] },
                    requests: RequestParams {
                        per_cycle,
                        obstacle: r[0],
                        beacon: r[1],
                        ground: r[2],
                        compass: r[3],
                        collision: r[4],
                    },
                    beacon_aperture_rad: f[0],
                    proximity_range_m: (f[1] > 0.0).then_some(f[1]),
                    message_range_m: f[2],
                    encoder_ticks_per_rev,
                    wheel_radius_m: f[3],
                    challenge: ChallengeParams {
                        key_time_ticks: c.0,
                        score_sensor: c.1,
                        return_time_penalty: c.2[0],
                        arrival_time_penalty: c.2[1],
                        collision_wall_penalty: c.2[2],
                        collision_robot_penalty: c.2[3],
                        target_reward: c.2[4],
                        home_reward: c.2[5],
                        // Any mode, from the key time's bits (the tuple is full).
                        scoring: world::challenge::Scoring::ALL[(c.0 % 8) as usize],
                    },
                }
            })
    }

    fn any_run_start() -> impl Strategy<Value = RunStart> {
        (
            (".{0,12}", any::<u64>(), any::<f64>(), any::<bool>(), any::<u64>(), any::<u32>(), any::<u32>()),
            any_lab(),
            any_params(),
            0usize..100,
            proptest::collection::vec(proptest::array::uniform3(any::<f64>()), 0..4),
        )
            .prop_map(
                |(
                    (iwsim_version, seed, dt_s, lockstep, tick_limit, cycle_ms, deadline_ms),
                    lab,
                    params,
                    obstacle_from,
                    cps,
                )| {
                    RunStart {
                        iwsim_version,
                        seed,
                        dt_s,
                        lockstep,
                        tick_limit,
                        cycle_ms,
                        deadline_ms,
                        lab,
                        params,
                        grid: world::map::Grid {
                            poses: cps
                                .iter()
                                .map(|&[x, y, h]| world::map::StartPose {
                                    pos: nalgebra::Point2::new(x, y),
                                    heading_deg: h,
                                })
                                .collect(),
                        },
                        obstacle_from,
                        checkpoints: cps.into_iter().map(|[x, y, radius]| Checkpoint { x, y, radius }).collect(),
                    }
                },
            )
    }

    proptest! {
        // Bit-exact identity: decoding then re-encoding gives the same bytes, NaN payloads and
        // −0 included (PartialEq on f64 could not say that).
        #[test]
        fn events_decode_to_what_was_encoded_bit_for_bit(event in any_event()) {
            let mut bytes = Vec::new();
            encode_event(&event, &mut bytes);
            let back = decode_event(&bytes).expect("decodes");
            let mut again = Vec::new();
            encode_event(&back, &mut again);
            prop_assert_eq!(&again, &bytes);
            prop_assert_eq!(format!("{back:?}"), format!("{event:?}"));
        }

        #[test]
        fn run_starts_decode_to_what_was_encoded_bit_for_bit(start in any_run_start()) {
            let mut bytes = Vec::new();
            encode_run_start(&start, &mut bytes);
            let back = decode_run_start(&bytes).expect("decodes");
            let mut again = Vec::new();
            encode_run_start(&back, &mut again);
            prop_assert_eq!(&again, &bytes);
            prop_assert_eq!(format!("{back:?}"), format!("{start:?}"));
        }

        #[test]
        fn random_bytes_never_panic_the_decoders(mut bytes in proptest::collection::vec(any::<u8>(), 0..300), tag in 0u8..8) {
            let _ = decode_run_start(&bytes);
            let _ = decode_event(&bytes);
            // Mostly a valid header, so the decoders get past the first two bytes.
            if bytes.len() >= 2 {
                bytes[0] = recorder::journal::CODEC_VERSION;
                bytes[1] = tag;
            }
            let _ = decode_run_start(&bytes);
            let _ = decode_event(&bytes);
        }

        #[test]
        fn every_cut_of_an_event_is_an_error_not_a_panic(event in any_event(), cut in 0usize..1000) {
            let mut bytes = Vec::new();
            encode_event(&event, &mut bytes);
            let cut = cut % bytes.len();
            prop_assert!(decode_event(&bytes[..cut]).is_err());
        }
    }

    #[test]
    fn a_run_recorded_before_the_challenge_parameters_reads_with_their_defaults() {
        let mut start = run_start();
        assert_eq!(start.params.challenge, ChallengeParams::default());
        // Version 2 always wrote a proximity range, and had no line sensor.
        start.params.proximity_range_m = Some(3.0);
        start.params.noise.line_flip_prob = 0.0;
        let mut bytes = Vec::new();
        encode_run_start(&start, &mut bytes);
        // Version 2 wrote the same bytes without the challenge parameters, and without the flag
        // byte before the proximity range (which the message range, encoder ticks and wheel
        // radius follow).
        let c = ChallengeParams::default();
        let mut tail = c.key_time_ticks.to_le_bytes().to_vec();
        tail.push(u8::from(c.score_sensor));
        for v in [
            c.return_time_penalty,
            c.arrival_time_penalty,
            c.collision_wall_penalty,
            c.collision_robot_penalty,
            c.target_reward,
            c.home_reward,
        ] {
            tail.extend(v.to_le_bytes());
        }
        tail.extend(0f64.to_le_bytes());
        // Version 4's scoring mode closes them.
        tail.push(c.scoring.number() as u8);
        let at = bytes.windows(tail.len()).position(|w| w == tail.as_slice()).expect("the challenge parameters");
        // Version 3: the same without the scoring mode (its runs scored competitively).
        let mut v3 = bytes.clone();
        v3.remove(at + tail.len() - 1);
        v3[0] = 3;
        assert_eq!(decode_run_start(&v3), Ok(start.clone()));
        let flag = at - (8 + 8 + 4 + 8) - 1;
        assert_eq!(bytes[flag], 1, "the proximity range flag");
        let mut old = bytes[..flag].to_vec();
        old.extend(&bytes[flag + 1..at]);
        old.extend(&bytes[at + tail.len()..]);
        old[0] = 2;
        assert_eq!(decode_run_start(&old), Ok(start));
        old[0] = 1;
        assert_eq!(decode_run_start(&old), Err(JournalDecodeError::Version { found: 1 }));
    }

    #[test]
    fn decode_errors_name_what_is_wrong_and_where() {
        let mut bytes = Vec::new();
        encode_event(&Event::Finish { tick: 9, reason: "stop".into() }, &mut bytes);
        assert_eq!(decode_event(&[]), Err(JournalDecodeError::Empty));
        assert_eq!(decode_event(&[9, 4]), Err(JournalDecodeError::Version { found: 9 }));
        assert_eq!(
            decode_event(&[recorder::journal::CODEC_VERSION, 77]),
            Err(JournalDecodeError::BadByte { offset: 1, what: "event tag", value: 77 })
        );
        assert_eq!(decode_event(&bytes[..5]), Err(JournalDecodeError::Truncated { offset: 2, len: 5, what: "tick" }));
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(decode_event(&long), Err(JournalDecodeError::Trailing { offset: bytes.len(), extra: 1 }));
        // A count far beyond the message is refused before anything is allocated.
        let mut step = vec![recorder::journal::CODEC_VERSION, 5];
        step.extend_from_slice(&3u64.to_le_bytes());
        step.extend_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            decode_event(&step),
            Err(JournalDecodeError::TooLong { offset: 10, what: "action list", count: u64::from(u32::MAX), left: 0 })
        );
        let message = decode_event(&bytes[..5]).expect_err("cut").to_string();
        assert_eq!(message, "the message ends at byte 5 inside tick starting at byte 2");
    }

    #[test]
    fn a_disc_robot_keeps_its_shape_through_the_journal() {
        let spec = RobotSpec::at(3.0, 4.0, 90.0).disc(1.0).motors(3.0, 0.5).named("p");
        let event = Event::AddRobot { id: 2, agent_id: 1, spec };
        let mut bytes = Vec::new();
        encode_event(&event, &mut bytes);
        assert_eq!(decode_event(&bytes), Ok(event));
        // Version, tag, id, agent id, the name's length and byte, the kind: then the shape.
        assert_eq!(bytes[16], 1);
        bytes[16] = 7;
        assert_eq!(
            decode_event(&bytes),
            Err(JournalDecodeError::BadByte { offset: 16, what: "robot shape", value: 7 })
        );
    }
}

mod recording {
    use super::*;
    use recorder::{RecorderCreateError, RecorderOptions, Recording, RecordingReadError, WorldTrack};

    #[test]
    fn a_recording_gives_back_the_run_start_and_every_event_in_order() {
        let dir = scratch("roundtrip");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 40);
        let stats = record(&path, &start, &calls, RecorderOptions::default());
        let back = Recording::open(&path).expect("reads");
        assert_eq!(back.start, start);
        assert_eq!(back.events, events_of(&calls));
        assert_eq!(back.truncated, None);
        assert_eq!(stats.events, back.events.len() as u64);
        assert_eq!(stats.world_frames + stats.dropped_world_frames, 40);
        // Run start + lab, every event, three messages per world frame.
        assert_eq!(stats.messages, 2 + stats.events + 3 * stats.world_frames);
        assert_eq!(stats.bytes, std::fs::metadata(&path).expect("file").len());
        assert_eq!(back.metadata["iwsim.run"]["seed"], "7");
        assert!(!back.metadata.contains_key("iwsim.wall_clock"));
    }

    #[test]
    fn replaying_the_recorded_actions_reproduces_every_state_hash() {
        let dir = scratch("replay");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, original) = simulated_run(&start, 60);
        record(&path, &start, &calls, RecorderOptions::default());
        let back = Recording::open(&path).expect("reads");

        let s = &back.start;
        let mut world = World::new(&s.lab, s.params.clone(), s.seed).expect("valid lab");
        let mut ids = Vec::new();
        let mut steps = 0;
        for event in &back.events {
            match event {
                Event::AddRobot { id, spec, .. } => ids.push((*id, world.add_robot(spec.clone()).expect("free"))),
                Event::RemoveRobot { id } => {
                    let k = ids.iter().position(|(i, _)| i == id).expect("known robot");
                    world.remove_robot(ids.remove(k).1);
                }
                Event::Step { tick, actions, hash } => {
                    assert_eq!(world.tick(), *tick);
                    world.step(&actions_for(actions, &ids), s.dt_s);
                    assert_eq!(world.state_hash(), *hash, "tick {tick}");
                    steps += 1;
                }
                Event::Freeze { .. } | Event::Settle | Event::Finish { .. } => {}
            }
        }
        assert_eq!(steps, 60);
        assert_eq!(world.state_hash(), original.state_hash());
    }

    #[test]
    fn two_recordings_of_the_same_run_are_identical_byte_for_byte() {
        let dir = scratch("identical");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 30);
        let a = dir.join("a.mcap");
        let b = dir.join("b.mcap");
        record(&a, &start, &calls, RecorderOptions::default());
        record(&b, &start, &calls, RecorderOptions::default());
        assert_eq!(std::fs::read(&a).expect("a"), std::fs::read(&b).expect("b"));

        // The wall clock, when given, is kept apart in its own metadata record.
        let c = dir.join("c.mcap");
        let when = std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_700_000_000);
        record(&c, &start, &calls, RecorderOptions { wall_clock_start: Some(when), ..Default::default() });
        let back = Recording::open(&c).expect("reads");
        assert_eq!(back.metadata["iwsim.wall_clock"]["unix_ns"], "1700000000000000000");
        assert_eq!(back.events, Recording::open(&a).expect("reads").events);
    }

    #[test]
    fn chunks_close_at_one_second_of_simulated_time() {
        let dir = scratch("chunks");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 35);
        let stats = record(&path, &start, &calls, RecorderOptions::default());
        // The run start's own chunk, then one per simulated second: 0–1 s, 1–2 s, 2–3 s, 3–3.5 s.
        assert_eq!(stats.chunks, 5);
        let small = dir.join("small.mcap");
        let stats = record(&small, &start, &calls, RecorderOptions { chunk_bytes: 4096, ..Default::default() });
        assert!(stats.chunks > 5, "{stats:?}");
    }

    #[test]
    fn a_file_cut_anywhere_reads_up_to_a_prefix_of_its_events() {
        let dir = scratch("cut");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 40);
        record(&path, &start, &calls, RecorderOptions { chunk_bytes: 8 * 1024, ..Default::default() });
        let bytes = std::fs::read(&path).expect("file");
        let all = events_of(&calls);
        let cut_path = dir.join("cut.mcap");
        let mut readable_from = None;
        let mut lengths_seen = std::collections::BTreeSet::new();
        for cut in (0..bytes.len()).step_by(97).chain([bytes.len() - 1]) {
            std::fs::write(&cut_path, &bytes[..cut]).expect("write cut");
            match Recording::open(&cut_path) {
                Ok(r) => {
                    readable_from.get_or_insert(cut);
                    assert_eq!(r.start, start);
                    assert_eq!(r.events[..], all[..r.events.len()], "cut at {cut}");
                    let said = r.truncated.expect("a cut file says so");
                    assert!(said.contains(&format!("byte {cut}")), "{said}");
                    assert!(said.contains("lost"), "{said}");
                    lengths_seen.insert(r.events.len());
                }
                Err(RecordingReadError::NoRunStart { truncated, .. }) => {
                    assert!(readable_from.is_none(), "cut at {cut} lost the run start again");
                    assert!(truncated.is_some());
                }
                Err(e) => panic!("cut at {cut}: {e}"),
            }
        }
        // The run start's chunk comes first (after the schemas'), and later cuts keep more events.
        assert!(readable_from.expect("some cut readable") < bytes.len() / 3);
        assert!(lengths_seen.len() > 3, "{lengths_seen:?}");
        // A file whose writer died after a complete chunk reads the same way.
        let world = WorldTrack::open(&cut_path).expect("world of a cut file");
        assert!(world.truncated.is_some());
    }

    /// What a hub killed with SIGKILL leaves: the file as it is while the recorder runs.
    #[test]
    fn a_live_recording_is_readable_up_to_its_last_closed_chunk() {
        let dir = scratch("live");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 25);
        let mut rec = recorder::Recorder::create(&path, &start, RecorderOptions::default()).expect("create");
        for call in &calls {
            match call {
                Call::Event(e) => rec.event(e),
                Call::World(tick, states, sensors) => rec.world(*tick, states, sensors),
            }
        }
        // The chunks of 0–1 s and 1–2 s are closed (a message at 2 s arrived); the writer
        // thread gets there on its own time, so wait for it with a bound.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        let live = loop {
            let r = Recording::open(&path).expect("a live file reads");
            let last_step = r.events.iter().rev().find_map(|e| match e {
                Event::Step { tick, .. } => Some(*tick),
                _ => None,
            });
            if last_step >= Some(19) {
                break r;
            }
            assert!(std::time::Instant::now() < deadline, "the closed chunks never reached the file: {r:?}");
            std::thread::yield_now();
        };
        let said = live.truncated.expect("no summary yet");
        assert!(said.contains("without its summary"), "{said}");
        assert!(said.contains("replay events after tick 19 are lost"), "{said}");
        assert_eq!(live.events[..], events_of(&calls)[..live.events.len()]);
        drop(rec);
        // Dropping the recorder finishes the file.
        assert_eq!(Recording::open(&path).expect("reads").truncated, None);
    }

    #[test]
    fn the_world_track_gives_each_robots_pose_per_tick() {
        let dir = scratch("world");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, world) = simulated_run(&start, 20);
        record(&path, &start, &calls, RecorderOptions::default());
        let track = WorldTrack::open(&path).expect("reads");
        assert_eq!(track.cycle_ms, 100);
        assert_eq!(track.frames.len(), 20);
        assert_eq!(track.frames[0].tick, 1);
        assert_eq!(track.frames[19].tick, 20);
        assert_eq!(track.frames[0].robots.len(), 3);
        let last = &track.frames[19];
        assert_eq!(last.robots.len(), 2, "the third chair left half way");
        for (_, r) in world.robots() {
            let p = last.robots.iter().find(|p| p.name == r.spec.name).expect("recorded");
            assert_eq!((p.x_m, p.y_m), (r.pose.x, r.pose.y));
            assert!(
                (p.heading_deg - r.pose.heading_deg()).abs() < 1e-9,
                "{} vs {}",
                p.heading_deg,
                r.pose.heading_deg()
            );
        }
    }

    #[test]
    fn world_frames_may_be_dropped_but_events_never_are() {
        let dir = scratch("queue");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 200);
        let stats = record(&path, &start, &calls, RecorderOptions { queue_len: 1, ..Default::default() });
        let back = Recording::open(&path).expect("reads");
        assert_eq!(back.events, events_of(&calls));
        assert_eq!(stats.world_frames + stats.dropped_world_frames, 200);
        assert_eq!(WorldTrack::open(&path).expect("reads").frames.len() as u64, stats.world_frames);
    }

    #[test]
    fn keeping_every_frame_waits_for_the_writer_and_loses_no_tick() {
        // What a lock-step hub asks for: the same one-item queue, 2,000 frames as fast as they
        // come, and every one of them in the file.
        let dir = scratch("keep");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, _) = simulated_run(&start, 2000);
        let keep = RecorderOptions { queue_len: 1, keep_every_frame: true, ..Default::default() };
        let stats = record(&path, &start, &calls, keep);
        assert_eq!((stats.world_frames, stats.dropped_world_frames), (2000, 0));
        let track = WorldTrack::open(&path).expect("reads");
        assert!(track.frames.iter().map(|f| f.tick).eq(1..=2000), "a frame for every tick");
    }

    #[test]
    fn a_recording_that_cannot_be_created_says_where() {
        let dir = scratch("create");
        let path = dir.join("no-such-dir").join("run.mcap");
        match recorder::Recorder::create(&path, &run_start(), RecorderOptions::default()) {
            Err(RecorderCreateError::Create { path: p, .. }) => assert_eq!(p, path),
            other => panic!("expected a create error, got {other:?}"),
        }
        match Recording::open(&path) {
            Err(RecordingReadError::Io { path: p, .. }) => assert_eq!(p, path),
            other => panic!("expected an I/O error, got {other:?}"),
        }
        let junk = dir.join("junk.mcap");
        std::fs::write(&junk, b"not an mcap file at all, just text").expect("write");
        assert!(Recording::open(&junk).is_err());
    }
}

mod python {
    use super::*;
    use recorder::RecorderOptions;

    /// Runs `hub/recorder/python/check_recording.py` (the PyPI `mcap` reader and Foxglove's
    /// published schema package) on a recording and compares what it prints with the world.
    #[test]
    fn the_python_mcap_reader_decodes_every_foxglove_channel() {
        let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
        let dir = scratch("python");
        let path = dir.join("run.mcap");
        let start = run_start();
        let (calls, world) = simulated_run(&start, 25);
        record(&path, &start, &calls, RecorderOptions::default());

        // A summary.json with the final poses rounded as iwsim writes them.
        let robots: Vec<String> = world
            .robots()
            .map(|(_, r)| {
                format!(
                    r#"{{"name":"{}","final_pose":[{:.4},{:.4},{:.2}]}}"#,
                    r.spec.name,
                    r.pose.x,
                    r.pose.y,
                    r.pose.heading_deg()
                )
            })
            .collect();
        let summary = dir.join("summary.json");
        std::fs::write(&summary, format!(r#"{{"robots":[{}]}}"#, robots.join(","))).expect("summary");

        let script = test_support::python::checker_script();
        let out = std::process::Command::new(&python)
            .arg(&script)
            .arg(&path)
            .arg("--summary")
            .arg(&summary)
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}", python.display()));
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "check_recording.py failed:\n{stdout}\n{stderr}");
        assert!(stdout.contains("robots: 3\n"), "{stdout}");
        assert!(stdout.contains("ticks: 25\n"), "{stdout}");
        assert!(stdout.contains("summary: 2 final poses match"), "{stdout}");
        for (_, r) in world.robots() {
            let line = format!("last pose {}: {:.6} {:.6} ", r.spec.name, r.pose.x, r.pose.y);
            assert!(stdout.contains(&line), "{line} not in\n{stdout}");
        }

        // A damaged Foxglove message makes the check fail rather than pass quietly.
        let mut bytes = std::fs::read(&path).expect("file");
        let lab_at = bytes.windows(10).position(|w| w == b"lab/border").expect("lab entity in the file");
        bytes[lab_at - 1] = 0xff;
        let bad = dir.join("bad.mcap");
        std::fs::write(&bad, &bytes).expect("write");
        let out = std::process::Command::new(&python).arg(&script).arg(&bad).output().expect("runs");
        assert!(!out.status.success(), "a damaged file passed:\n{}", String::from_utf8_lossy(&out.stdout));
    }
}
