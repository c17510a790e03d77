//! The world model against hand-computed numbers: thesis equations, sensor geometry,
//! collisions, messages and determinism.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::Point2;

use super::*;
use crate::map::{Beacon, NoiseParams, Target, Wall};

fn empty_lab(w: Real, h: Real) -> Lab {
    Lab { name: "test".into(), width_m: w, height_m: h, walls: vec![], beacons: vec![], targets: vec![] }
}

fn rect_wall(x0: Real, y0: Real, x1: Real, y1: Real, height_m: Real) -> Wall {
    Wall { height_m, corners: vec![Point2::new(x0, y0), Point2::new(x1, y0), Point2::new(x1, y1), Point2::new(x0, y1)] }
}

fn quiet() -> Params {
    Params { noise: NoiseParams::NONE, proximity_range_m: Some(10.0), ..Params::default() }
}

fn world(lab: Lab, params: Params) -> World {
    World::new(&lab, params, 1).expect("valid lab")
}

fn close(a: Real, b: Real, tol: Real) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn straight_run_follows_the_motor_filter_and_eq_4_7() {
    let mut w = world(empty_lab(20.0, 20.0), quiet());
    let r = w.add_robot(RobotSpec::at(2.0, 5.0, 0.0).motors(0.5, 0.5)).expect("valid");
    // out = 0.5, 0.75, 0.875 → v = 0.25, 0.375, 0.4375 m/s → Δx = 0.025, 0.0375, 0.04375 m.
    let mut x = vec![];
    for _ in 0..3 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.1);
        x.push(w.robot(r).expect("alive").pose.x);
    }
    assert!(close(x[0], 2.025, 1e-12) && close(x[1], 2.0625, 1e-12) && close(x[2], 2.10625, 1e-12), "{x:?}");
    let p = w.robot(r).expect("alive").pose;
    assert_eq!((p.y, p.theta), (5.0, 0.0));
}

#[test]
fn spin_in_place_turns_at_twice_max_speed_over_the_track() {
    let mut w = world(empty_lab(20.0, 20.0), quiet());
    let r = w.add_robot(RobotSpec::at(5.0, 5.0, 0.0).body(1.0, 0.5, 0.5).motors(0.5, 0.0)).expect("valid");
    // ω = MaxSpeed·(R − L)/Height = 0.5·2/0.5 = 2 rad/s; five ticks of 0.1 s turn 1 rad.
    for _ in 0..5 {
        w.step(&[Action::motors(r, -1.0, 1.0)], 0.1);
    }
    let p = w.robot(r).expect("alive").pose;
    assert_eq!((p.x, p.y), (5.0, 5.0));
    assert!(close(p.theta, 1.0, 1e-12), "{}", p.theta);
}

#[test]
fn an_arc_integrates_with_the_old_heading_eqs_4_7_to_4_9() {
    let mut w = world(empty_lab(20.0, 20.0), quiet());
    let r = w.add_robot(RobotSpec::at(5.0, 5.0, 0.0).motors(1.0, 0.0)).expect("valid");
    // v = 0.75 m/s, ω = 0.5 rad/s.
    w.step(&[Action::motors(r, 0.5, 1.0)], 0.1);
    w.step(&[], 0.1);
    let p = w.robot(r).expect("alive").pose;
    assert!(close(p.x, 5.0 + 0.075 + 0.075 * 0.05f64.cos(), 1e-12));
    assert!(close(p.y, 5.0 + 0.075 * 0.05f64.sin(), 1e-12));
    assert!(close(p.theta, 0.1, 1e-12));
}

#[test]
fn headings_wrap_past_180_degrees() {
    let mut w = world(empty_lab(20.0, 20.0), quiet());
    let r = w.add_robot(RobotSpec::at(5.0, 5.0, 170.0).body(1.0, 1.0, 0.5).motors(1.0, 0.0)).expect("valid");
    // ω = 2 rad/s for 0.2 s: 170° + 22.9° wraps to −167.1°.
    w.step(&[Action::motors(r, -1.0, 1.0)], 0.2);
    let t = w.robot(r).expect("alive").pose.theta;
    assert!(close(t, (170f64.to_radians() + 0.4) - 2.0 * PI, 1e-12), "{t}");
}

/// Speed samples of a full-power start from rest.
fn speeds(max_speed: Real, curve: Real, dt: Real, ticks: usize) -> Vec<Real> {
    let mut w = world(empty_lab(200.0, 20.0), quiet());
    let r = w.add_robot(RobotSpec::at(2.0, 10.0, 0.0).motors(max_speed, curve)).expect("valid");
    let mut last = 2.0;
    (0..ticks)
        .map(|_| {
            w.step(&[Action::motors(r, 1.0, 1.0)], dt);
            let x = w.robot(r).expect("alive").pose.x;
            let v = (x - last) / dt;
            last = x;
            v
        })
        .collect()
}

#[test]
fn the_10_to_90_percent_rise_time_for_curve_0_83_at_100_ms_is_1_2_s() {
    let v = speeds(0.49, 0.83, 0.1, 200);
    let top = *v.last().expect("samples");
    assert!(close(top, 0.49, 1e-9), "top speed {top}");
    let first = |frac: Real| v.iter().position(|&s| s >= frac * top).expect("reached");
    // Samples are at t = 0.1·(n+1); 10 % is first reached at n = 0 (17 %), 90 % at n = 12.
    assert_eq!((first(0.1), first(0.9)), (0, 12));
    let rise = (first(0.9) - first(0.1)) as Real * 0.1;
    assert!(close(rise, 1.2, 1e-12), "rise time {rise}");
}

#[test]
fn top_speed_is_max_speed() {
    for (max, curve) in [(0.5, 0.5), (1.2, 0.0), (0.26, 0.9)] {
        let v = speeds(max, curve, 0.1, 400);
        assert!(close(*v.last().expect("samples"), max, 1e-9));
        assert!(v.iter().all(|&s| s <= max + 1e-12));
    }
}

#[test]
fn default_sensors_read_the_lab_border_within_a_millimetre() {
    let mut w = world(empty_lab(10.0, 8.0), quiet());
    let r = w.add_robot(RobotSpec::at(3.0, 2.0, 0.0)).expect("valid");
    w.step(&[], 0.1);
    let d = w.robot(r).expect("alive").readings.proximity().to_vec();
    // front (3.5, 2): the wall x = 10 is 6.5 m ahead, but the cone's right edge (−30°) meets
    // the floor wall y = 0 at 2 / sin 30° = 4 m. left (3, 2.5) → y = 8 at 5.5 (x = 0 along the
    // cone edge would be 6); right (3, 1.5) → y = 0 at 1.5; back (2.5, 2) → x = 0 at 2.5.
    for (got, want) in d.iter().zip([4.0, 5.5, 1.5, 2.5]) {
        assert!(close(*got, want, 1e-3), "{d:?}");
    }
}

#[test]
fn readings_turn_with_the_robot_and_respect_com_0_8() {
    let mut w = world(empty_lab(10.0, 8.0), quiet());
    let spec = RobotSpec::at(3.0, 2.0, 90.0).body(1.2, 0.7, 0.8);
    let r = w.add_robot(spec).expect("valid");
    w.step(&[], 0.1);
    let d = w.robot(r).expect("alive").readings.proximity().to_vec();
    // Heading +y. front (3, 2.96) → y = 8 at 5.04; left (2.65, 2) → x = 0 at 2.65; right
    // (3.35, 2) → x = 10 at 6.65 but its cone meets y = 0 at 2 / sin 30° = 4; back (3, 1.76) →
    // y = 0 at 1.76.
    for (got, want) in d.iter().zip([5.04, 2.65, 4.0, 1.76]) {
        assert!(close(*got, want, 1e-3), "{d:?}");
    }
}

#[test]
fn a_box_beside_the_cone_is_read_along_the_cone_edge() {
    let mut lab = empty_lab(10.0, 8.0);
    lab.walls.push(rect_wall(5.0, 3.0, 6.0, 4.0, 2.0));
    let mut w = world(lab, quiet());
    let r = w.add_robot(RobotSpec::at(3.0, 2.0, 0.0)).expect("valid");
    w.step(&[], 0.1);
    let front = w.robot(r).expect("alive").readings.proximity()[0];
    // The corner (5, 3) is 33.7° off the axis, outside the ±30° cone; the cone's left edge
    // meets the box's lower face at (3.5 + √3, 3): 2 m away (the corner would be 1.80 m).
    assert!(close(front, 2.0, 1e-3), "{front}");
}

#[test]
fn narrow_cones_see_only_what_is_inside_them() {
    let mut lab = empty_lab(10.0, 8.0);
    lab.walls.push(rect_wall(5.0, 2.3, 6.0, 3.0, 2.0));
    let mut w = world(lab, quiet());
    let sensors = vec![ProximitySpec::deg(0.5, 0.0, 0.0, 10.0), ProximitySpec::deg(0.5, 0.0, 0.0, 60.0)];
    let r = w.add_robot(RobotSpec::at(3.0, 2.0, 0.0).sensors(sensors)).expect("valid");
    w.step(&[], 0.1);
    let d = w.robot(r).expect("alive").readings.proximity().to_vec();
    // The box's corner (5, 2.3) is at 8.5° from (3.5, 2): outside ±5°, inside ±30°.
    assert!(close(d[0], 6.5, 1e-3), "{d:?}");
    assert!(close(d[1], (1.5f64 * 1.5 + 0.3 * 0.3).sqrt(), 1e-3), "{d:?}");
}

#[test]
fn a_cone_wider_than_half_a_turn_sees_walls_and_robots_beside_a_narrow_one() {
    // Sensor 0 looks back over 270° (everything but the 90° ahead), sensor 1 ahead over 60°:
    // the wide one is measured on its own path, which needs the candidate edges in full.
    let sensors = vec![ProximitySpec::deg(0.0, 0.0, 180.0, 270.0), ProximitySpec::deg(0.5, 0.0, 0.0, 60.0)];
    for with_b in [false, true] {
        let mut w = world(empty_lab(20.0, 8.0), quiet());
        let a = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0).sensors(sensors.clone())).expect("valid");
        if with_b {
            // Heading +y with half-height 0.3: its right side is the face x = 1.5.
            w.add_robot(RobotSpec::at(1.2, 4.0, 90.0).body(1.0, 0.6, 0.5)).expect("valid");
        }
        w.step(&[], 0.1);
        let d = w.robot(a).expect("alive").readings.proximity().to_vec();
        // Without B the nearest wall in the wide cone is x = 0, 3 m behind; with B, its face.
        let behind = if with_b { 1.5 } else { 3.0 };
        assert!(close(d[0], behind, 1e-9), "{d:?}");
        // The narrow cone ahead meets the side walls along its edges, 4 / sin 30° = 8 m away,
        // or reads its range if that is shorter.
        assert!(close(d[1], w.params().proximity_range().min(8.0), 1e-3), "{d:?}");
    }
}

#[test]
fn other_robots_are_seen_by_proximity_sensors() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let a = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0)).expect("valid");
    w.add_robot(RobotSpec::at(7.0, 4.0, 90.0).body(1.0, 0.6, 0.5)).expect("valid");
    w.step(&[], 0.1);
    // B heading +y with half-height 0.3: its side faces x = 6.7. A's front sensor is at 3.5.
    let front = w.robot(a).expect("alive").readings.proximity()[0];
    assert!(close(front, 3.2, 1e-3), "{front}");
}

#[test]
fn readings_are_capped_at_the_range_and_noise_can_be_switched_on() {
    let mut p = quiet();
    p.proximity_range_m = Some(3.0);
    let mut w = world(empty_lab(20.0, 8.0), p);
    let r = w.add_robot(RobotSpec::at(10.0, 4.0, 0.0)).expect("valid");
    w.step(&[], 0.1);
    assert_eq!(w.robot(r).expect("alive").readings.proximity()[0], 3.0);

    let mut noisy = quiet();
    noisy.noise.proximity_m = 0.1;
    let mut w = world(empty_lab(10.0, 8.0), noisy);
    let r = w.add_robot(RobotSpec::at(3.0, 2.0, 0.0)).expect("valid");
    let mut samples = vec![];
    for _ in 0..2000 {
        w.step(&[], 0.1);
        samples.push(w.robot(r).expect("alive").readings.proximity()[2]);
    }
    let mean = samples.iter().sum::<Real>() / samples.len() as Real;
    let sd = (samples.iter().map(|s| (s - mean).powi(2)).sum::<Real>() / samples.len() as Real).sqrt();
    assert!(close(mean, 1.5, 0.01) && close(sd, 0.1, 0.01), "mean {mean}, sd {sd}");
}

#[test]
fn a_plain_ciber_rato_robot_has_its_ir_noise_on_one_over_the_distance() {
    // Ciber-Rato adds ObstacleNoise to the IR value 1/d, not to d: at 2 m (0.5) with σ 0.1 the
    // value spreads by 0.1, where the distance would spread by 0.4 m.
    let mut noisy = quiet();
    noisy.noise.proximity_m = 0.1;
    let mut w = world(empty_lab(10.0, 8.0), noisy);
    // A disc of diameter 1 at x = 7.5 facing east: its rim sensor is 2 m from the east border.
    let r = w.add_robot(RobotSpec::at(7.5, 4.0, 0.0).disc(1.0)).expect("valid");
    let mut values = vec![];
    for _ in 0..2000 {
        w.step(&[], 0.1);
        values.push(1.0 / w.robot(r).expect("alive").readings.proximity()[0]);
    }
    let mean = values.iter().sum::<Real>() / values.len() as Real;
    let sd = (values.iter().map(|s| (s - mean).powi(2)).sum::<Real>() / values.len() as Real).sqrt();
    assert!(close(mean, 0.5, 0.01) && close(sd, 0.1, 0.01), "mean {mean}, sd {sd}");
}

#[test]
fn a_robot_stops_when_its_next_pose_hits_a_wall_and_counts_the_contact_once() {
    let mut lab = empty_lab(20.0, 8.0);
    lab.walls.push(rect_wall(6.0, 0.0, 7.0, 8.0, 2.0));
    let mut w = world(lab, quiet());
    let r = w.add_robot(RobotSpec::at(4.0, 4.0, 0.0).motors(1.0, 0.0)).expect("valid");
    let mut last_x = 4.0;
    let mut blocked_at = None;
    for t in 0..40 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.1);
        let rb = w.robot(r).expect("alive");
        if rb.collision && blocked_at.is_none() {
            blocked_at = Some(t);
            // Refused: the robot kept its pose.
            assert_eq!(rb.pose.x, last_x);
        }
        last_x = rb.pose.x;
        assert!(rb.pose.x + 0.5 < 6.0, "front went into the wall: {}", rb.pose.x);
    }
    let rb = w.robot(r).expect("alive");
    assert!(blocked_at.is_some() && rb.collision && rb.readings.collision);
    assert_eq!(rb.collision_count, 1, "pushing on keeps one contact");
    // Backing off clears it; driving in again counts a second contact.
    for _ in 0..10 {
        w.step(&[Action::motors(r, -1.0, -1.0)], 0.1);
    }
    assert!(!w.robot(r).expect("alive").collision);
    for _ in 0..40 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.1);
    }
    assert_eq!(w.robot(r).expect("alive").collision_count, 2);
}

#[test]
fn a_move_that_would_end_fully_inside_a_wall_or_a_body_is_refused() {
    // A thick pillar and a small, fast robot that would jump wholly inside it in one tick:
    // no edge of the robot crosses an edge of the pillar, yet it collides.
    let mut lab = empty_lab(20.0, 8.0);
    lab.walls.push(rect_wall(5.0, 2.0, 9.0, 6.0, 2.0));
    let mut w = world(lab, quiet());
    let small = RobotSpec::at(4.0, 4.0, 0.0).body(0.2, 0.2, 0.5).motors(5.0, 0.0);
    let r = w.add_robot(small.clone()).expect("valid");
    w.step(&[Action::motors(r, 1.0, 1.0)], 0.6); // would move 3 m to x = 7
    assert_eq!(w.robot(r).expect("alive").pose.x, 4.0);
    assert!(w.robot(r).expect("alive").collision);

    // The same against a big robot.
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    w.add_robot(RobotSpec::at(7.0, 4.0, 0.0).body(4.0, 4.0, 0.5)).expect("valid");
    let r = w.add_robot(small).expect("valid");
    w.step(&[Action::motors(r, 1.0, 1.0)], 0.6);
    assert_eq!(w.robot(r).expect("alive").pose.x, 4.0);
    assert!(w.robot(r).expect("alive").collision);
}

#[test]
fn two_robots_driving_head_on_both_stop_and_never_overlap() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let a = w.add_robot(RobotSpec::at(5.0, 4.0, 0.0).motors(1.0, 0.0)).expect("valid");
    let b = w.add_robot(RobotSpec::at(8.0, 4.0, 180.0).motors(1.0, 0.0)).expect("valid");
    for _ in 0..30 {
        w.step(&[Action::motors(a, 1.0, 1.0), Action::motors(b, 1.0, 1.0)], 0.1);
        let (pa, pb) = (w.robot(a).expect("alive").pose, w.robot(b).expect("alive").pose);
        assert!(pb.x - pa.x >= 1.0 - 1e-9, "overlap: {} {}", pa.x, pb.x);
    }
    assert!(w.robot(a).expect("alive").collision && w.robot(b).expect("alive").collision);
}

#[test]
fn a_door_with_com_0_99_turns_about_its_hinge() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let door = RobotSpec::at(5.0, 4.0, 0.0).body(1.0, 0.1, 0.99).motors(0.5, 0.0).kind(RobotKind::Door);
    let d = w.add_robot(door).expect("valid");
    let before = w.robot(d).expect("alive").corners();
    // ω = 0.5·2/0.1 = 10 rad/s: a tick of π/20 s turns it 90°.
    w.step(&[Action::motors(d, -1.0, 1.0)], PI / 20.0);
    let r = w.robot(d).expect("alive");
    assert_eq!((r.pose.x, r.pose.y), (5.0, 4.0), "the hinge does not move");
    assert!(close(r.pose.theta, FRAC_PI_2, 1e-12));
    let after = r.corners();
    // The leaf's far end swings from x = 5.99 to y = 4.99; the hinge end stays within 1 cm.
    assert!(close(before[0].x, 5.99, 1e-12) && close(after[0].y, 4.99, 1e-12) && close(after[0].x, 5.05, 1e-12));
    assert!((after[2] - Point2::new(5.0, 4.0)).norm() < 0.06);
}

#[test]
fn real_robots_take_pushed_poses_are_never_blocked_and_report_collisions() {
    let mut lab = empty_lab(20.0, 8.0);
    lab.walls.push(rect_wall(6.0, 0.0, 7.0, 8.0, 2.0));
    let mut w = world(lab, quiet());
    let r = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0).motors(1.0, 0.0).kind(RobotKind::Real)).expect("valid");
    // Ticks of 1 s: at 1 m/s the body can be 1.12 m on, turned 30°.
    w.step(&[Action::pose(r, Pose::from_deg(4.0, 4.5, 30.0))], 1.0);
    let rb = w.robot(r).expect("alive");
    assert_eq!((rb.pose.x, rb.pose.y), (4.0, 4.5));
    assert!(!rb.collision);
    // Pushed into the wall: it goes there anyway, flagged.
    w.step(&[Action::pose(r, Pose::from_deg(6.2, 4.0, 0.0))], 2.0);
    let rb = w.robot(r).expect("alive");
    assert_eq!(rb.pose.x, 6.2);
    assert!(rb.collision && rb.collision_count == 1);
    // A simulated robot cannot drive into the real one.
    let s = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0).motors(1.0, 0.0)).expect("valid");
    for _ in 0..30 {
        w.step(&[Action::motors(s, 1.0, 1.0)], 0.1);
    }
    let sx = w.robot(s).expect("alive").pose.x;
    assert!(sx + 0.5 <= 6.2 - 0.5 + 1e-9 && w.robot(s).expect("alive").collision, "{sx}");
}

#[test]
fn a_real_robot_cannot_be_pushed_where_its_body_could_not_have_gone() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let r = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0).motors(0.8, 0.0).kind(RobotKind::Real)).expect("valid");
    // 0.8 m/s for 0.1 s is 8 cm: a push 2 m away (an agent probing the lab) is refused and
    // counted, and the robot stays.
    let stats = w.step(&[Action::pose(r, Pose::from_deg(5.0, 4.0, 0.0))], 0.1);
    assert_eq!(stats.refused_poses, 1);
    assert_eq!(w.robot(r).expect("alive").pose.x, 3.0);
    // So is a spin of 90° in a tick, in place.
    let stats = w.step(&[Action::pose(r, Pose::from_deg(3.0, 4.0, 90.0))], 0.1);
    assert_eq!(stats.refused_poses, 1);
    // A chair's own pace (9 cm, 5°) goes; after three silent ticks, a pose 3 ticks on does too.
    let stats = w.step(&[Action::pose(r, Pose::from_deg(3.09, 4.0, 5.0))], 0.1);
    assert_eq!((stats.refused_poses, w.robot(r).expect("alive").pose.x), (0, 3.09));
    for _ in 0..3 {
        w.step(&[], 0.1);
    }
    let stats = w.step(&[Action::pose(r, Pose::from_deg(3.49, 4.0, 5.0))], 0.1);
    assert_eq!((stats.refused_poses, w.robot(r).expect("alive").pose.x), (0, 3.49));
}

#[test]
fn beacons_are_hidden_by_taller_walls_and_outside_the_aperture() {
    let mut lab = empty_lab(20.0, 8.0);
    lab.walls.push(rect_wall(9.0, 3.0, 10.0, 5.0, 2.0));
    lab.beacons = vec![
        Beacon { pos: Point2::new(15.0, 4.0), height_m: 1.0 },
        Beacon { pos: Point2::new(15.0, 4.0), height_m: 3.0 },
        Beacon { pos: Point2::new(5.0, 7.0), height_m: 1.0 },
    ];
    let mut p = quiet();
    p.sensors.beacon = true;
    p.beacon_aperture_rad = FRAC_PI_2;
    let mut w = world(lab, p);
    let r = w.add_robot(RobotSpec::at(5.0, 4.0, 0.0)).expect("valid");
    let r2 = w.add_robot(RobotSpec::at(5.0, 1.0, 180.0)).expect("valid");
    w.step(&[], 0.1);
    let b = w.robot(r).expect("alive").readings.beacons().to_vec();
    assert_eq!(b[0], None, "a 1 m beacon behind a 2 m wall is hidden");
    assert_eq!(b[1], Some(0.0), "a 3 m beacon is seen over it");
    assert!(close(b[2].expect("seen"), 90.0, 1e-9), "bearing is relative to the heading: {b:?}");
    // Facing away (−x), the robot at (5, 1) has beacon 2 at bearing −90° (inside the
    // aperture) and beacon 1 at ~−167° (outside).
    let b2 = w.robot(r2).expect("alive").readings.beacons().to_vec();
    assert!(close(b2[2].expect("in aperture"), -90.0, 1e-9), "{b2:?}");
    assert_eq!(b2[1], None);
}

#[test]
fn compass_gps_and_ground_report_the_pose_when_noise_is_off() {
    let mut lab = empty_lab(20.0, 8.0);
    lab.targets = vec![
        Target { pos: Point2::new(15.0, 4.0), radius_m: 1.0 },
        Target { pos: Point2::new(5.0, 4.0), radius_m: 0.5 },
    ];
    let mut p = quiet();
    p.sensors.gps = true;
    let mut w = world(lab, p);
    let r = w.add_robot(RobotSpec::at(5.2, 4.1, -135.0)).expect("valid");
    w.step(&[], 0.1);
    let rd = w.robot(r).expect("alive").readings;
    assert!(close(rd.compass_deg.expect("on"), -135.0, 1e-9));
    let g = rd.gps.expect("on");
    assert_eq!((g.x_m, g.y_m), (5.2, 4.1));
    assert_eq!(rd.ground, Some(1));
    assert_eq!(rd.tick, 1);
}

#[test]
fn encoders_count_wheel_travel() {
    let mut p = quiet();
    p.encoder_ticks_per_rev = 1000;
    p.wheel_radius_m = 0.5 / PI; // one revolution per metre... of 1000 ticks
    let mut w = world(empty_lab(40.0, 8.0), p);
    let r = w.add_robot(RobotSpec::at(2.0, 4.0, 0.0).motors(1.0, 0.0)).expect("valid");
    for _ in 0..10 {
        w.step(&[Action::motors(r, 0.5, 1.0)], 0.1);
    }
    // Left wheel 0.5 m/s, right 1 m/s for 1 s.
    let [l, rt] = w.robot(r).expect("alive").readings.encoder_ticks;
    assert!((l - 500).abs() <= 1 && (rt - 1000).abs() <= 1, "{l} {rt}");
}

#[test]
fn encoders_keep_counting_while_a_wall_holds_the_chair() {
    let mut lab = empty_lab(20.0, 8.0);
    lab.walls.push(rect_wall(6.0, 0.0, 7.0, 8.0, 2.0));
    let mut w = world(lab, quiet());
    let r = w.add_robot(RobotSpec::at(4.0, 4.0, 0.0).motors(1.0, 0.0)).expect("valid");
    for _ in 0..40 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.1);
    }
    let held = w.robot(r).expect("alive");
    assert!(held.collision, "pressed against the wall");
    let (x, ticks) = (held.pose.x, held.readings.encoder_ticks);
    for _ in 0..10 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.1);
    }
    let rb = w.robot(r).expect("alive");
    assert_eq!(rb.pose.x, x, "the wall holds the body");
    // Full power for 1 s: each wheel turns 1 m on the spot, as a real chair's wheels spin.
    let per_m = sim_model::encoder_ticks_per_m(1024.0, 0.17);
    for (w, (now, then)) in rb.readings.encoder_ticks.iter().zip(ticks).enumerate() {
        let counted = (now - then) as Real / per_m;
        assert!(close(counted, 1.0, 2.0 / per_m), "wheel {w} counted {counted} m");
    }
}

#[test]
fn a_doors_encoder_counts_its_leaf_exactly_whatever_the_slip() {
    let p = Params { noise: NoiseParams { encoder_slip_frac: 0.5, ..NoiseParams::NONE }, ..Params::default() };
    let mut w = World::new(&empty_lab(20.0, 8.0), p, 5).expect("valid");
    let door = RobotSpec::at(5.0, 4.0, 0.0).body(1.0, 0.1, 0.99).motors(0.5, 0.0).kind(RobotKind::Door);
    let d = w.add_robot(door).expect("valid");
    let chair = w.add_robot(RobotSpec::at(12.0, 4.0, 0.0).motors(0.5, 0.0)).expect("valid");
    for _ in 0..10 {
        w.step(&[Action::motors(d, -0.1, 0.1), Action::motors(chair, 1.0, 1.0)], 0.1);
    }
    // 0.05 m/s a wheel for 1 s; the chair's counts, at 50 % slip, are nowhere near exact.
    let per_m = sim_model::encoder_ticks_per_m(1024.0, 0.17);
    let [l, r] = w.robot(d).expect("alive").readings.encoder_ticks;
    assert!(
        (l as Real / per_m + 0.05).abs() <= 1.0 / per_m && (r as Real / per_m - 0.05).abs() <= 1.0 / per_m,
        "{l} {r}"
    );
    let truth = w.robot(chair).expect("alive").pose.x - 12.0;
    let [cl, cr] = w.robot(chair).expect("alive").readings.encoder_ticks;
    assert!((cl as Real / per_m - truth).abs() > 0.01 || (cr as Real / per_m - truth).abs() > 0.01, "the chair slips");
}

/// Dead reckoning as an agent does it: each tick's wheel travel from the encoder counts, along
/// the heading the tick began with.
fn dead_reckon(pose: sim_model::Pose, last: [i64; 2], now: [i64; 2], per_m: Real, track_m: Real) -> sim_model::Pose {
    let dl = (now[0] - last[0]) as Real / per_m;
    let dr = (now[1] - last[1]) as Real / per_m;
    let (s, c) = pose.heading_rad.sin_cos();
    sim_model::advance(pose, (dl + dr) / 2.0, (dr - dl) / track_m, c, s, 1.0)
}

#[test]
fn default_slip_makes_pure_odometry_drift_by_a_few_percent_of_the_distance() {
    // A chair (0.65 m track, 0.49 m/s) drives 10 m straight ahead at 10 Hz, many times; the
    // spread of odometry's error is what NoiseParams::WHEELCHAIR documents.
    let per_m = sim_model::encoder_ticks_per_m(1024.0, 0.17);
    let (mut side2, mut heading2, mut along2) = (0.0, 0.0, 0.0);
    let runs = 60;
    for seed in 0..runs {
        let p = Params { noise: NoiseParams { encoder_slip_frac: 0.02, ..NoiseParams::NONE }, ..Params::default() };
        assert_eq!(p.noise.encoder_slip_frac, Params::default().noise.encoder_slip_frac, "the default");
        let mut w = World::new(&empty_lab(40.0, 8.0), p, seed).expect("valid");
        let r = w.add_robot(RobotSpec::at(2.0, 4.0, 0.0).body(1.1, 0.65, 0.8).motors(0.49, 0.83)).expect("valid");
        let mut est = sim_model::Pose::new(2.0, 4.0, 0.0);
        let mut last = [0, 0];
        while w.robot(r).expect("alive").pose.x < 12.0 {
            w.step(&[Action::motors(r, 1.0, 1.0)], 0.1);
            let now = w.robot(r).expect("alive").readings.encoder_ticks;
            est = dead_reckon(est, last, now, per_m, 0.65);
            last = now;
        }
        let truth = w.robot(r).expect("alive").pose;
        assert!(close(truth.y, 4.0, 1e-9), "slip moves only the counts, not the chair");
        side2 += (est.y_m - truth.y).powi(2);
        along2 += (est.x_m - truth.x).powi(2);
        heading2 += sim_model::wrap_rad(est.heading_rad - truth.theta).powi(2);
    }
    let rms = |sum: Real| (sum / runs as Real).sqrt();
    let (side, along, heading_deg) = (rms(side2), rms(along2), rms(heading2).to_degrees());
    // Sideways 1–4 % of the 10 m, heading 1–4°: the heading dominates, as on real chairs.
    assert!((0.1..0.4).contains(&side), "sideways {side} m");
    assert!((1.0..4.0).contains(&heading_deg), "heading {heading_deg}°");
    assert!(along < side / 4.0, "along {along} m, sideways {side} m");
}

#[test]
fn latency_delays_a_sensor_by_whole_ticks() {
    let mut p = quiet();
    p.latency.compass = 3;
    let mut w = world(empty_lab(20.0, 8.0), p);
    let r = w.add_robot(RobotSpec::at(5.0, 4.0, 0.0).motors(0.5, 0.0)).expect("valid");
    let mut compass = vec![];
    let mut truth = vec![];
    for _ in 0..6 {
        w.step(&[Action::motors(r, -0.1, 0.1)], 0.1);
        let rb = w.robot(r).expect("alive");
        compass.push(rb.readings.compass_deg);
        truth.push(rb.pose.heading_deg());
    }
    assert_eq!(&compass[..3], &[None, None, None]);
    assert_eq!(compass[3], Some(truth[0]));
    assert_eq!(compass[5], Some(truth[2]));
}

#[test]
fn messages_reach_robots_within_8_m_and_no_farther() {
    let mut w = world(empty_lab(40.0, 8.0), quiet());
    let speaker = w.add_robot(RobotSpec::at(5.0, 4.0, 0.0)).expect("valid");
    let near = w.add_robot(RobotSpec::at(12.9, 4.0, 0.0)).expect("valid");
    let far = w.add_robot(RobotSpec::at(13.1, 4.0, 0.0)).expect("valid");
    let msg = Message::new(b"after you").expect("short");
    w.step(&[Action::say(speaker, msg)], 0.1);
    let heard = &w.robot(near).expect("alive").inbox;
    assert_eq!(heard.len(), 1);
    assert_eq!((heard[0].from, heard[0].message.as_bytes()), (speaker, &b"after you"[..]));
    assert!(w.robot(far).expect("alive").inbox.is_empty());
    assert!(w.robot(speaker).expect("alive").inbox.is_empty(), "a speaker does not hear itself");
    // Heard once: the next tick is silent.
    w.step(&[], 0.1);
    assert!(w.robot(near).expect("alive").inbox.is_empty());
}

#[test]
fn a_robot_hears_at_most_400_bytes_a_tick() {
    let mut w = world(empty_lab(40.0, 20.0), quiet());
    let listener = w.add_robot(RobotSpec::at(10.0, 10.0, 0.0)).expect("valid");
    let speakers: Vec<_> =
        (0..5).map(|k| w.add_robot(RobotSpec::at(4.0 + 3.0 * k as Real, 7.0, 0.0)).expect("valid")).collect();
    let full = Message::new(&[b'x'; 100]).expect("100 bytes");
    let actions: Vec<_> = speakers.iter().map(|&s| Action::say(s, full)).collect();
    let stats = w.step(&actions, 0.1);
    let inbox = &w.robot(listener).expect("alive").inbox;
    assert_eq!(inbox.len(), 4);
    // Nearest first (x 10, then 7 and 13 at one distance, then 4 and 16 at another; ties by
    // slot): the one left unheard is the farthest in the highest slot, x 16.
    let nearest_first = vec![speakers[2], speakers[1], speakers[3], speakers[0]];
    assert_eq!(inbox.iter().map(|h| h.from).collect::<Vec<_>>(), nearest_first, "nearest speakers first");
    assert_eq!(stats.dropped_messages, 1);
}

#[test]
fn actions_for_removed_robots_are_ignored_and_handles_do_not_alias() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let a = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0)).expect("valid");
    assert!(w.remove_robot(a));
    assert!(!w.remove_robot(a));
    let b = w.add_robot(RobotSpec::at(10.0, 4.0, 0.0)).expect("valid");
    assert_eq!(a.index(), b.index());
    assert!(w.robot(a).is_none());
    let stats = w.step(&[Action::motors(a, 1.0, 1.0), Action::motors(b, f64::NAN, 0.5)], 0.1);
    assert_eq!((stats.unknown_robot_actions, stats.bad_values), (1, 1));
    assert_eq!(w.robot(b).expect("alive").motor_in, [0.0, 0.5]);
}

#[test]
fn the_world_refuses_robots_past_its_capacity() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    w.set_capacity(2);
    w.add_robot(RobotSpec::at(3.0, 4.0, 0.0)).expect("room");
    w.add_robot(RobotSpec::at(6.0, 4.0, 0.0)).expect("room");
    assert_eq!(w.add_robot(RobotSpec::at(9.0, 4.0, 0.0)), Err(AddRobotError::Full { max: 2 }));
}

/// A noisy run with many robots, messages and collisions; returns the state hash per tick.
fn noisy_run(seed: u64) -> Vec<u64> {
    let mut lab = empty_lab(30.0, 20.0);
    lab.walls.push(rect_wall(10.0, 5.0, 12.0, 15.0, 2.0));
    lab.beacons.push(Beacon { pos: Point2::new(25.0, 10.0), height_m: 1.0 });
    let mut p =
        Params { sensors: crate::map::SensorSwitches { gps: true, beacon: true, compass: true }, ..Params::default() };
    p.noise.encoder_slip_frac = 0.01;
    let mut w = World::new(&lab, p, seed).expect("valid");
    let robots: Vec<_> = (0..20)
        .map(|k| {
            w.add_robot(RobotSpec::at(2.0 + (k % 5) as Real * 5.0, 2.0 + (k / 5) as Real * 4.0, k as Real * 37.0))
                .expect("valid")
        })
        .collect();
    let hello = Message::new(b"hello").expect("short");
    patterned_run(&mut w, &robots, 200, (hello, 9), |t, k| {
        (((t + k) % 7) as Real / 6.0, ((t * 3 + k) % 5) as Real / 4.0 - 0.2)
    })
}

/// Steps `w` for `ticks` ticks, robot k driving at `powers(t, k)` and saying `say.0` every
/// `say.1`-th tick (staggered by k); the state hash after each tick.
fn patterned_run(
    w: &mut World,
    robots: &[RobotHandle],
    ticks: usize,
    say: (Message, usize),
    powers: impl Fn(usize, usize) -> (Real, Real),
) -> Vec<u64> {
    (0..ticks)
        .map(|t| {
            let actions: Vec<_> = robots
                .iter()
                .enumerate()
                .map(|(k, &r)| {
                    let (left, right) = powers(t, k);
                    let mut a = Action::motors(r, left, right);
                    if (t + k) % say.1 == 0 {
                        a.say = Some(say.0);
                    }
                    a
                })
                .collect();
            w.step(&actions, 0.1);
            w.state_hash()
        })
        .collect()
}

#[test]
fn one_seed_gives_bit_identical_runs_and_another_seed_differs() {
    let a = noisy_run(42);
    let b = noisy_run(42);
    let c = noisy_run(43);
    assert_eq!(a, b);
    assert_ne!(a.last(), c.last());
}

#[test]
fn is_free_sees_walls_and_robots_added_since_the_last_step() {
    let mut lab = empty_lab(20.0, 8.0);
    lab.walls.push(rect_wall(6.0, 0.0, 7.0, 8.0, 2.0));
    let mut w = world(lab, quiet());
    assert!(w.is_free(&RobotSpec::at(3.0, 4.0, 0.0)));
    assert!(!w.is_free(&RobotSpec::at(5.8, 4.0, 0.0)), "overlaps the wall");
    assert!(!w.is_free(&RobotSpec::at(0.3, 4.0, 0.0)), "overlaps the lab border");
    w.add_robot(RobotSpec::at(3.0, 4.0, 0.0)).expect("valid");
    assert!(!w.is_free(&RobotSpec::at(3.5, 4.5, 45.0)), "overlaps the robot just added");
    assert!(w.is_free(&RobotSpec::at(3.0, 6.0, 0.0)));
}

#[test]
fn a_frozen_robot_stops_at_once_and_stays_an_obstacle() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let a = w.add_robot(RobotSpec::at(3.0, 4.0, 0.0).motors(1.0, 0.0)).expect("valid");
    let b = w.add_robot(RobotSpec::at(8.0, 4.0, 180.0)).expect("valid");
    w.step(&[Action::motors(a, 1.0, 1.0)], 0.1);
    assert!(w.set_frozen(a, true));
    let x = w.robot(a).expect("alive").pose.x;
    for _ in 0..5 {
        w.step(&[Action::motors(a, 1.0, 1.0)], 0.1);
    }
    assert_eq!(w.robot(a).expect("alive").pose.x, x);
    assert_eq!(w.robot(a).expect("alive").motor_out, [0.0, 0.0]);
    // The other robot still sees it and cannot drive through it.
    for _ in 0..60 {
        w.step(&[Action::motors(b, 1.0, 1.0)], 0.1);
    }
    assert!(w.robot(b).expect("alive").pose.x - x >= 1.0 - 1e-9);
    assert!(w.set_frozen(a, false));
    w.step(&[Action::motors(a, -1.0, -1.0)], 0.1);
    assert!(w.robot(a).expect("alive").pose.x < x);
}

#[test]
fn readings_exist_before_the_first_step_as_noisy_as_any_later_and_priming_changes_no_run() {
    let mut p = Params::default();
    p.sensors.gps = true;
    let mut w = World::new(&empty_lab(10.0, 8.0), p.clone(), 3).expect("valid");
    let r = w.add_robot(RobotSpec::at(3.0, 2.0, 0.0)).expect("valid");
    let before = w.state_hash();
    w.refresh_sensors();
    let d = w.robot(r).expect("alive").readings;
    // Noisy from tick 0: neither the GPS fix nor the compass hands the agent its true start.
    let g = d.gps.expect("a fix");
    let (gx, gy, gh) = (g.x_m, g.y_m, g.heading_deg);
    assert!((gx, gy) != (3.0, 2.0) && close(gx, 3.0, 2.0) && close(gy, 2.0, 2.0), "{:?}", d.gps);
    let compass = d.compass_deg.expect("a heading");
    assert!(compass != 0.0 && gh != 0.0 && compass.abs() < 30.0, "{compass} {gh}");
    assert!(d.proximity()[2] != 1.5 && close(d.proximity()[2], 1.5, 0.5), "{:?}", d.proximity());
    // Priming again draws the same (the stream is the tick's).
    w.refresh_sensors();
    assert_eq!(w.robot(r).expect("alive").readings, d);
    // Without noise, priming is exact.
    let mut q = World::new(&empty_lab(10.0, 8.0), quiet(), 3).expect("valid");
    let rq = q.add_robot(RobotSpec::at(3.0, 2.0, 0.0)).expect("valid");
    q.refresh_sensors();
    let dq = q.robot(rq).expect("alive").readings;
    assert!(close(dq.proximity()[2], 1.5, 1e-3) && dq.compass_deg == Some(0.0), "{dq:?}");
    // A primed world and an unprimed one step identically.
    let mut other = World::new(&empty_lab(10.0, 8.0), p, 3).expect("valid");
    let r2 = other.add_robot(RobotSpec::at(3.0, 2.0, 0.0)).expect("valid");
    w.step(&[Action::motors(r, 1.0, 0.5)], 0.1);
    other.step(&[Action::motors(r2, 1.0, 0.5)], 0.1);
    assert_eq!(w.state_hash(), other.state_hash());
    assert_ne!(before, w.state_hash());
}

#[test]
fn priming_draws_the_same_noise_whatever_order_the_robots_came_in() {
    // Before the first step slots follow the order agents registered in; the priming noise
    // must not, or one seed would give two runs.
    let mut p = Params::default();
    p.sensors.gps = true;
    let a = RobotSpec::at(3.0, 2.0, 0.0).named("a");
    let b = RobotSpec::at(7.0, 6.0, 90.0).named("b");
    let primed = |first: &RobotSpec, second: &RobotSpec| {
        let mut w = World::new(&empty_lab(10.0, 8.0), p.clone(), 3).expect("valid");
        let h1 = w.add_robot(first.clone()).expect("valid");
        let h2 = w.add_robot(second.clone()).expect("valid");
        w.refresh_sensors();
        let mut out = [
            (first.name.clone(), w.robot(h1).expect("alive").readings),
            (second.name.clone(), w.robot(h2).expect("alive").readings),
        ];
        out.sort_by(|x, y| x.0.cmp(&y.0));
        out
    };
    assert_eq!(primed(&a, &b), primed(&b, &a));
}

#[test]
fn a_lab_beyond_the_size_limit_is_refused_with_an_error_not_an_abort() {
    // The 10,000,000 m lab once asked for a 25 TB wall index.
    let mut lab = empty_lab(10_000_000.0, 10_000_000.0);
    lab.walls.push(rect_wall(1.0, 1.0, 2.0, 2.0, 1.0));
    let err = World::new(&lab, quiet(), 1).expect_err("too large");
    assert!(matches!(err, WorldBuildError::Static(StaticBuildError::BadLabSize { .. })), "{err:?}");
    assert!(err.to_string().contains("at most 10000 m"), "{err}");
}

#[test]
fn the_largest_lab_builds_a_wall_index_within_its_budget() {
    // A 10 km lab with walls whose bounding boxes span it all: the index coarsens its cells
    // instead of listing every edge in millions of cells.
    let mut lab = empty_lab(MAX_LAB_SIZE_M, MAX_LAB_SIZE_M);
    for k in 0..50 {
        let o = k as Real;
        lab.walls.push(Wall {
            height_m: 1.0,
            corners: vec![
                Point2::new(o, 0.0),
                Point2::new(o + 1.0, 0.0),
                Point2::new(MAX_LAB_SIZE_M, MAX_LAB_SIZE_M - o),
            ],
        });
    }
    let mut w = world(lab, quiet());
    let spec = w.statics.spec;
    let cells = (spec.nx * spec.ny) as u64;
    assert!(cells <= grid::MAX_WALL_CELLS, "{cells} cells");
    let entries = cells + (w.statics.edges_in_all() + w.statics.triangles_in_all()) as u64;
    assert!(entries <= grid::MAX_WALL_ENTRIES, "{entries} entries");
    // The coarse index still serves the world: a robot starts beside the walls.
    let r = w.add_robot(RobotSpec::at(5000.0, 2.0, 0.0)).expect("free start");
    assert!(w.robot(r).is_some());
}

#[test]
fn a_usual_lab_keeps_its_four_metre_wall_cells() {
    let w = world(empty_lab(44.0, 17.75), quiet());
    assert_eq!(w.statics.spec.cell, STATIC_CELL_M);
}

#[test]
fn a_robot_cannot_start_outside_the_lab() {
    let mut w = world(empty_lab(40.0, 14.0), quiet());
    let err = w.add_robot(RobotSpec::at(200.0, 3.0, 0.0)).expect_err("x = 200 on a 40 m lab");
    assert!(
        matches!(err, AddRobotError::OutsideLab { x, y, width, height } if x == 200.0 && y == 3.0 && width == 40.0 && height == 14.0),
        "{err:?}"
    );
    assert!(w.add_robot(RobotSpec::at(5.0, -0.5, 0.0)).is_err(), "below the lab");
    assert!(w.add_robot(RobotSpec::at(5.0, 7.0, 0.0)).is_ok(), "inside");
}

/// A plain Ciber-Rato robot at a 50 ms cycle: a 1 m disc moving 0.15 m per cycle at full
/// power (3 m/s), with Ciber-Rato's filter `out = (in + out)/2`.
fn ciber_rato(x: Real, y: Real, heading_deg: Real) -> RobotSpec {
    RobotSpec::at(x, y, heading_deg).disc(1.0).motors(0.15 / 0.05, 0.5)
}

/// Heading change from `a` to `b`, radians, taking the short way round.
fn turned(a: Real, b: Real) -> Real {
    crate::math::wrap_rad(b - a)
}

#[test]
fn a_plain_robot_moves_by_ciber_ratos_formula_each_cycle() {
    let mut w = world(empty_lab(20.0, 20.0), quiet());
    let r = w.add_robot(ciber_rato(2.0, 5.0, 0.0)).expect("valid");
    // Full power from rest: out = 0.5, 0.75, 0.875, 0.9375 of 0.15 m per cycle.
    let want = [0.075, 0.1125, 0.13125, 0.140625];
    let mut x = w.robot(r).expect("alive").pose.x;
    for (k, step) in want.iter().enumerate() {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.05);
        let p = w.robot(r).expect("alive").pose;
        assert!(close(p.x - x, *step, 1e-12), "tick {k}: moved {} instead of {step}", p.x - x);
        assert_eq!((p.y, p.theta), (5.0, 0.0));
        x = p.x;
    }
    // Ciber-Rato's observed spin at −0.05/+0.05 (a third of full power): 0.05, 0.075, 0.0875
    // rad per cycle, rot = outR − outL over a diameter of 1.
    let mut w = world(empty_lab(20.0, 20.0), quiet());
    let r = w.add_robot(ciber_rato(5.0, 5.0, 0.0)).expect("valid");
    let mut theta = 0.0;
    for want in [0.05, 0.075, 0.0875, 0.09375] {
        w.step(&[Action::motors(r, -1.0 / 3.0, 1.0 / 3.0)], 0.05);
        let p = w.robot(r).expect("alive").pose;
        assert!(close(p.theta - theta, want, 1e-12), "turned {} instead of {want}", p.theta - theta);
        assert_eq!((p.x, p.y), (5.0, 5.0));
        theta = p.theta;
    }
}

#[test]
fn a_disc_against_a_wall_turns_in_place_where_a_square_cannot() {
    let lab = Lab { walls: vec![rect_wall(6.0, 0.0, 7.0, 10.0, 1.0)], ..empty_lab(20.0, 10.0) };
    let mut w = world(lab.clone(), quiet());
    let r = w.add_robot(ciber_rato(5.0, 5.0, 0.0)).expect("valid");
    // Drive into the wall until it holds the disc.
    for _ in 0..20 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.05);
    }
    let pinned = w.robot(r).expect("alive").pose;
    assert!(w.robot(r).expect("alive").collision);
    assert!(pinned.x > 5.4 && pinned.x < 5.5, "{pinned:?}");
    // Spin: the residual forward speed is refused at first, then the disc turns freely.
    let (mut total, mut theta) = (0.0, pinned.theta);
    for tick in 0..60 {
        w.step(&[Action::motors(r, -1.0, 1.0)], 0.05);
        let robot = w.robot(r).expect("alive");
        total += turned(theta, robot.pose.theta);
        theta = robot.pose.theta;
        let at = RobotSpec { pose: robot.pose, ..robot.spec.clone() };
        assert!(w.is_clear_of_walls(&at), "tick {tick}: the disc overlaps the wall at {:?}", robot.pose);
        assert!(robot.pose.x <= 5.5 && (robot.pose.x - pinned.x).abs() < 0.2, "tick {tick}: {:?}", robot.pose);
    }
    assert!(total > 4.0 * PI, "turned only {total} rad in 60 ticks");

    // A 1 m square 1 cm from the same wall cannot turn at all: its corners would enter it.
    let mut w = world(lab, quiet());
    let sq = w.add_robot(RobotSpec::at(5.49, 5.0, 0.0).motors(3.0, 0.5)).expect("valid");
    for _ in 0..60 {
        w.step(&[Action::motors(sq, -1.0, 1.0)], 0.05);
    }
    let s = w.robot(sq).expect("alive");
    assert_eq!((s.pose.x, s.pose.theta), (5.49, 0.0));
    assert!(s.collision);
}

#[test]
fn a_disc_held_by_a_wall_still_turns_when_its_move_is_refused() {
    // Ciber-Rato's rule, which stock clients rely on: pClient escapes a wall by pivoting on one
    // wheel (0, 0.1). The arc would take the disc into the wall, so the move is refused, but
    // the turn is kept: the disc turns where it stands until the arc leads away.
    let lab = Lab { walls: vec![rect_wall(6.0, 0.0, 7.0, 10.0, 1.0)], ..empty_lab(20.0, 10.0) };
    let mut w = world(lab, quiet());
    let r = w.add_robot(ciber_rato(5.0, 5.0, 0.0)).expect("valid");
    for _ in 0..20 {
        w.step(&[Action::motors(r, 1.0, 1.0)], 0.05);
    }
    let pinned = w.robot(r).expect("alive").pose;
    let mut refused_but_turned = 0;
    for _ in 0..40 {
        let before = w.robot(r).expect("alive").pose;
        w.step(&[Action::motors(r, 0.0, 1.0)], 0.05);
        let robot = w.robot(r).expect("alive");
        if robot.collision && (robot.pose.x, robot.pose.y) == (before.x, before.y) && robot.pose.theta != before.theta {
            refused_but_turned += 1;
        }
        let at = RobotSpec { pose: robot.pose, ..robot.spec.clone() };
        assert!(w.is_clear_of_walls(&at), "the disc overlaps the wall at {:?}", robot.pose);
    }
    assert!(refused_but_turned > 0, "no tick turned the held disc");
    let end = w.robot(r).expect("alive").pose;
    assert!(end.x < pinned.x - 0.1 || (end.y - pinned.y).abs() > 0.1, "it never got away: {end:?} from {pinned:?}");
}

#[test]
fn two_discs_driving_head_on_stop_with_their_circles_apart() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    // Offset by 0.6 m across, so they meet off-centre; their centres never come closer than one
    // diameter.
    let a = w.add_robot(ciber_rato(3.0, 4.0, 0.0)).expect("valid");
    let b = w.add_robot(ciber_rato(8.0, 4.6, 180.0)).expect("valid");
    for _ in 0..60 {
        w.step(&[Action::motors(a, 1.0, 1.0), Action::motors(b, 1.0, 1.0)], 0.05);
        let (pa, pb) = (w.robot(a).expect("alive").pose, w.robot(b).expect("alive").pose);
        let gap = (pb.position() - pa.position()).norm();
        assert!(gap >= 1.0 - 1e-6, "overlap: centres {gap} m apart");
    }
    let (ra, rb) = (w.robot(a).expect("alive"), w.robot(b).expect("alive"));
    assert!(ra.collision && rb.collision);
    // Held within one cycle's travel each (0.15 m) of touching.
    let gap = (rb.pose.position() - ra.pose.position()).norm();
    assert!(gap < 1.3, "stopped {gap} m apart");
}

#[test]
fn a_disc_is_seen_as_a_circle_and_its_sensors_sit_on_its_rim() {
    let mut w = world(empty_lab(20.0, 8.0), quiet());
    let sensors = [0.0, 60.0, -60.0, 180.0].map(|a: Real| {
        let r = a.to_radians();
        ProximitySpec::deg(0.5 * r.cos(), 0.5 * r.sin(), a, 60.0)
    });
    let a = w.add_robot(ciber_rato(2.0, 4.0, 0.0).sensors(sensors.to_vec())).expect("valid");
    // B's centre is 0.4 m off A's axis: its circle is √(2.5² + 0.4²) − 0.5 from A's front
    // sensor at (2.5, 4); the square around it would read 2.0.
    w.add_robot(ciber_rato(5.0, 4.4, 0.0)).expect("valid");
    w.step(&[], 0.05);
    let d = w.robot(a).expect("alive").readings.proximity()[0];
    let want = (2.5f64 * 2.5 + 0.4 * 0.4).sqrt() - 0.5;
    assert!(close(d, want, 1e-4), "{d} vs {want}");
    // The back sensor, on the rim at (1.5, 4), reads the lab border at x = 0.
    let back = w.robot(a).expect("alive").readings.proximity()[3];
    assert!(close(back, 1.5, 1e-4), "{back}");
}

#[test]
fn worlds_of_discs_are_deterministic_and_hash_their_shape() {
    let run = |disc: bool| {
        let lab = Lab { walls: vec![rect_wall(6.0, 0.0, 7.0, 10.0, 1.0)], ..empty_lab(20.0, 10.0) };
        let mut w = World::new(&lab, Params::default(), 42).expect("valid");
        let mut handles = vec![];
        for k in 0..6 {
            let spec = RobotSpec::at(1.5 + 0.8 * k as Real, 2.0 + 1.1 * k as Real, 30.0 * k as Real).motors(3.0, 0.5);
            handles.push(w.add_robot(if disc { spec.disc(0.6) } else { spec.body(0.6, 0.6, 0.5) }).expect("valid"));
        }
        for t in 0..100 {
            let acts: Vec<Action> =
                handles.iter().enumerate().map(|(k, &h)| Action::motors(h, 1.0, ((k + t) % 3) as Real - 1.0)).collect();
            w.step(&acts, 0.05);
        }
        w.state_hash()
    };
    assert_eq!(run(true), run(true));
    assert_ne!(run(true), run(false));
}

/// One robot's readings and pose per tick, driven on a fixed pattern with every noise on, in a
/// world that also holds `others` robots far out of its sensors' and messages' reach.
fn lone_run(others: usize) -> Vec<(u64, Pose, [i64; 2])> {
    let mut lab = empty_lab(120.0, 20.0);
    lab.walls.push(rect_wall(10.0, 5.0, 12.0, 15.0, 2.0));
    let mut p =
        Params { sensors: crate::map::SensorSwitches { gps: true, beacon: true, compass: true }, ..Params::default() };
    p.noise.encoder_slip_frac = 0.02;
    lab.beacons.push(Beacon { pos: Point2::new(25.0, 10.0), height_m: 1.0 });
    let mut w = World::new(&lab, p, 11).expect("valid");
    let me = w.add_robot(RobotSpec::at(4.0, 10.0, 0.0)).expect("room");
    let far: Vec<_> =
        (0..others).map(|k| w.add_robot(RobotSpec::at(60.0 + 6.0 * k as Real, 10.0, 90.0)).expect("room")).collect();
    (0..150)
        .map(|t| {
            let mut actions = vec![Action::motors(me, 0.8, 0.5 + 0.4 * ((t / 20) % 2) as Real)];
            // The others drive too, so they draw noise of their own every tick.
            actions.extend(far.iter().map(|&r| Action::motors(r, 0.7, 0.6)));
            w.step(&actions, 0.1);
            let r = w.robot(me).expect("alive");
            let mut h = Fnv::new();
            for &d in r.readings.proximity() {
                h.f64(d);
            }
            h.f64(r.readings.compass_deg.unwrap_or(Real::NAN));
            if let Some(g) = r.readings.gps {
                h.f64(g.x_m);
                h.f64(g.heading_deg);
            }
            for b in r.readings.beacons() {
                h.f64(b.unwrap_or(Real::NAN));
            }
            (h.finish(), r.pose, r.readings.encoder_ticks)
        })
        .collect()
}

#[test]
fn a_robots_noise_is_its_own_whoever_else_is_in_the_world() {
    // Each robot draws from streams of its own: robots added elsewhere (and their draws) leave
    // its noisy readings, slipping encoders and noisy motors exactly as they were.
    let alone = lone_run(0);
    assert_eq!(alone, lone_run(1));
    assert_eq!(alone, lone_run(5));
    // And the noise is really there: two ticks' readings are not copies of each other.
    assert_ne!(alone[100].0, alone[101].0);
}

/// A crowded, noisy, talking world of `n` robots stepped on `threads` threads with the
/// parallel path on from the first robot; the state hash per tick.
fn crowded_run(n: usize, threads: usize) -> Vec<u64> {
    let mut lab = empty_lab(70.0, 70.0);
    for k in 0..6 {
        let x = 8.0 + 10.0 * k as Real;
        lab.walls.push(rect_wall(x, 10.0, x + 0.5, 60.0, 2.0));
    }
    let mut p =
        Params { sensors: crate::map::SensorSwitches { gps: true, beacon: false, compass: true }, ..Params::default() };
    p.noise.encoder_slip_frac = 0.01;
    let mut w = World::new(&lab, p, 5).expect("valid");
    w.set_parallel_min_robots(0);
    assert_eq!(w.set_threads(threads), threads);
    let robots: Vec<_> = (0..n)
        .map(|k| {
            // Rows 2 m apart, 1.7 m along: close enough that chairs meet and see each other.
            let (x, y) = (2.0 + 1.7 * (k % 38) as Real, 3.0 + 2.0 * (k / 38) as Real);
            let spec = RobotSpec::at(x, y, (k * 53 % 360) as Real);
            if k % 7 == 3 { spec.disc(0.8) } else { spec }
        })
        .filter_map(|spec| if w.is_free(&spec) { w.add_robot(spec).ok() } else { None })
        .collect();
    assert!(robots.len() > n / 2, "placed {} of {n}", robots.len());
    let hello = Message::new(b"hi").expect("short");
    patterned_run(&mut w, &robots, 80, (hello, 11), |t, k| {
        (((t + k) % 5) as Real / 4.0, ((t * 3 + k) % 7) as Real / 6.0 - 0.1)
    })
}

#[test]
fn the_thread_count_never_changes_a_run() {
    let one = crowded_run(512, 1);
    assert_eq!(one, crowded_run(512, 2), "two threads");
    assert_eq!(one, crowded_run(512, 3), "three threads");
}

#[test]
fn a_crowded_run_meets_walls_and_robots_so_the_thread_test_covers_contacts() {
    // What `the_thread_count_never_changes_a_run` steps must exercise the collision phase.
    let mut lab = empty_lab(70.0, 70.0);
    lab.walls.push(rect_wall(8.0, 10.0, 8.5, 60.0, 2.0));
    let mut w = World::new(&lab, quiet(), 5).expect("valid");
    w.set_parallel_min_robots(0);
    w.set_threads(2);
    let a = w.add_robot(RobotSpec::at(6.0, 20.0, 0.0)).expect("room");
    let b = w.add_robot(RobotSpec::at(3.0, 30.0, 0.0)).expect("room");
    let c = w.add_robot(RobotSpec::at(5.5, 30.0, 180.0)).expect("room");
    for _ in 0..40 {
        w.step(&[Action::motors(a, 1.0, 1.0), Action::motors(b, 1.0, 1.0), Action::motors(c, 1.0, 1.0)], 0.1);
    }
    assert!(w.robot(a).expect("alive").collision_count >= 1, "a meets the wall");
    assert!(w.robot(b).expect("alive").collision_count >= 1, "b and c meet");
    assert!(w.robot(c).expect("alive").collision_count >= 1, "c and b meet");
}

/// The line sensor's string as Ciber-Rato writes it: element 0 (the leftmost) first.
fn line_string(bits: u8) -> String {
    (0..LINE_ELEMENTS).map(|k| if bits >> k & 1 == 1 { '1' } else { '0' }).collect()
}

#[test]
fn a_line_on_the_floor_is_read_by_the_line_sensor_as_ciber_rato_reads_it() {
    // A line across the lab, 0.2 m wide (y 9.9 to 10.1): a wall of height 0. The readings are
    // those the real simulator (ciberRatoTools 528480e, LineSensorTrueProb 1) gave a robot
    // heading east with its centre at y = 10.0, 10.1 and 9.9: a point on the line's lower
    // edge reads it, one on its upper edge does not.
    let mut lab = empty_lab(30.0, 20.0);
    lab.walls.push(rect_wall(0.0, 9.9, 30.0, 10.1, 0.0));
    let mut w = world(lab, quiet());
    let at = |w: &mut World, x: Real, y: Real| w.add_robot(RobotSpec::at(x, y, 0.0).disc(1.0)).expect("free");
    let (mid, top, bottom) = (at(&mut w, 5.0, 10.0), at(&mut w, 10.0, 10.1), at(&mut w, 15.0, 9.9));
    // Across the line, heading north: a robot drives over it, and its front sensor sees no wall.
    let over = w.add_robot(RobotSpec::at(25.0, 8.0, 90.0).disc(1.0).motors(1.0, 0.0)).expect("free");
    let mut crossed = false;
    for _ in 0..50 {
        w.step(&[Action::motors(over, 1.0, 1.0)], 0.1);
        let r = w.robot(over).expect("alive");
        assert!(!r.collision, "the line stopped the robot at y {}", r.pose.y);
        // The front sensor, on the rim, sees the lab's north side (or its 10 m range's end).
        let far = (20.0 - (r.pose.y + 0.5)).min(10.0);
        assert!(close(r.readings.proximity()[0], far, 1e-6), "it saw the line: {:?}", r.readings.proximity());
        crossed |= r.pose.y > 10.6;
    }
    assert!(crossed, "it crossed the line");
    let read = |h| line_string(w.robot(h).expect("alive").readings.line);
    assert_eq!((read(mid), read(top), read(bottom)), ("0011100".into(), "0000110".into(), "0111000".into()));
}

#[test]
fn line_elements_read_the_opposite_at_the_flip_rate() {
    // No line anywhere: every 1 is a flip, at LineSensorTrueProb 0.9 one element in ten.
    let params = Params { noise: NoiseParams { line_flip_prob: 0.1, ..NoiseParams::NONE }, ..quiet() };
    let mut w = world(empty_lab(20.0, 20.0), params);
    let r = w.add_robot(RobotSpec::at(5.0, 5.0, 0.0).disc(1.0)).expect("free");
    let mut ones = 0;
    for _ in 0..1000 {
        w.step(&[], 0.1);
        ones += w.robot(r).expect("alive").readings.line.count_ones();
    }
    let rate = f64::from(ones) / (1000.0 * LINE_ELEMENTS as f64);
    assert!(close(rate, 0.1, 0.015), "{rate}");
}

#[test]
fn the_line_sensors_noise_leaves_the_other_readings_their_draws() {
    // The same noisy run with and without line-sensor noise: every other reading is the same.
    let run = |flip: Real| {
        let params = Params { noise: NoiseParams { line_flip_prob: flip, ..NoiseParams::WHEELCHAIR }, ..quiet() };
        let mut w = world(empty_lab(20.0, 20.0), params);
        let r = w.add_robot(RobotSpec::at(5.0, 5.0, 30.0).disc(1.0)).expect("free");
        (0..50)
            .map(|_| {
                w.step(&[Action::motors(r, 0.5, 0.3)], 0.1);
                let rb = w.robot(r).expect("alive");
                (rb.pose, SensorReadings { line: 0, ..rb.readings })
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(run(0.0), run(0.3));
}
