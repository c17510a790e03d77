//! Pulling over for another chair: a sideways shift along an S-curve, checked against the
//! model before it is driven.
//!
//! A rear-wheel-drive chair cannot step sideways, and in a corridor it cannot turn on the
//! spot either (the Intellwheels body sweeps a circle of 0.94 m radius round its axle in a 1.78 m
//! corridor). So the yielder drives forward along an S-curve whose lateral offset follows a
//! quintic smoothstep (straight, with no curvature, at both ends), and ends parallel to where
//! it was going, against the side. The curve is the widest offset, and for it the shortest
//! length, for which every pose keeps clear of the walls, of what the sensors found and of
//! the other chairs; if the spot it ends at leaves the other no room to pass on the far side,
//! the other side of the corridor is tried. Where neither side has room ahead (a chair of the
//! same way already pulled over just in front), the same curves are tried in reverse, ending
//! behind the chair.
//! The navigator's path follower drives it ([`crate::Navigator::manoeuvre`]), so the motor
//! model and the odometry stay in step.

use crate::geom::{Footprint, Pose};
use crate::hybrid::{Motion, PathPose};
use crate::model::WorldModel;
use crate::traffic::Peer;

/// Clearance kept from walls and sensed obstacles while pulling over, metres.
const WALL_MARGIN_M: f64 = 0.05;
/// Distance kept from the other chair while pulling over (it may still be coming to a
/// stop), metres.
const PEER_MARGIN_M: f64 = 0.5;
/// Distance kept from any third chair's rectangle as it last said (it may be pulling over
/// itself, towards a spot nobody knows yet), metres.
const OTHERS_MARGIN_M: f64 = 0.3;
/// What the other needs beside the parked chair: clearance from walls, and from us.
const PASS_WALL_M: f64 = 0.04;
const PASS_GAP_M: f64 = 0.1;
/// Lengths of S-curve tried, shortest first, metres.
const LENGTHS_M: [f64; 4] = [1.5, 2.0, 2.5, 3.0];
/// Spacing of the path's poses, metres.
const STEP_M: f64 = 0.05;

/// A planned pull-over.
#[derive(Debug, Clone, PartialEq)]
pub struct PullOver {
    /// The poses to drive, from the chair's pose now.
    pub path: Vec<PathPose>,
    /// Sideways shift, metres: negative to the right.
    pub offset_m: f64,
    /// Driven in reverse: it ends behind the chair ([`s_curve_back`]).
    pub backwards: bool,
}

impl PullOver {
    /// "right" or "left".
    pub fn side(&self) -> &'static str {
        if self.offset_m < 0.0 { "right" } else { "left" }
    }
}

/// The S-curve from `from` that ends `offset` metres to its left (negative: right),
/// `length` metres further on, parallel to it.
pub fn s_curve(from: Pose, offset: f64, length: f64) -> Vec<PathPose> {
    curve(from, offset, length, 1.0)
}

/// [`s_curve`] driven in reverse: it ends `length` metres behind `from`, `offset` metres to
/// its left (negative: right), facing the way it faced.
pub fn s_curve_back(from: Pose, offset: f64, length: f64) -> Vec<PathPose> {
    curve(from, offset, length, -1.0)
}

/// The S-curve forwards (`dir` 1) or backwards (`dir` -1).
fn curve(from: Pose, offset: f64, length: f64, dir: f64) -> Vec<PathPose> {
    let n = (length / STEP_M).ceil().max(2.0) as usize;
    let (c, s) = (from.theta.cos(), from.theta.sin());
    (0..=n)
        .map(|i| {
            let u = i as f64 / n as f64;
            let x = dir * u * length;
            let y = offset * u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
            let dy = offset / length * 30.0 * u * u * (1.0 - u) * (1.0 - u);
            let ddy = offset / (length * length) * 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u);
            let kappa = ddy / (1.0 + dy * dy).powf(1.5);
            // Backwards, the chair faces against its way along the curve.
            let pose = Pose::new(from.x + x * c - y * s, from.y + x * s + y * c, from.theta + dir * dy.atan());
            let motion = match i {
                0 => Motion::Start,
                _ if dir > 0.0 => Motion::Forward(kappa),
                _ => Motion::Reverse(kappa),
            };
            PathPose { pose, motion }
        })
        .collect()
}

/// An S-curve maker: from a pose, an offset aside and a length along ([`s_curve`]).
type Curve = fn(Pose, f64, f64) -> Vec<PathPose>;

/// Plans the pull-over of the chair at `me` (with the model's footprint) for `peer`, keeping
/// clear of the `others` chairs heard; `None` when there is no room for it on either side
/// just now. Forwards first; where the way ahead has no room (a chair of the same way parked
/// just ahead, in a platoon), backwards: the way behind a chair that has come that way is
/// most often clear.
pub fn pull_over(model: &WorldModel, me: Pose, peer: &Peer, others: &[Peer]) -> Option<PullOver> {
    let fp = model.footprint;
    // Farther aside than this helps nobody.
    let enough = fp.half + peer.footprint.half + 0.35;
    let makes: [(Curve, bool); 2] = [(s_curve, false), (s_curve_back, true)];
    for (make, backwards) in makes {
        'side: for side in [-1.0, 1.0] {
            let mut offset = enough;
            while offset >= 0.15 {
                for length in LENGTHS_M {
                    let path = make(me, side * offset, length);
                    let clear = path.iter().all(|p| {
                        model.free(&p.pose, WALL_MARGIN_M)
                            && !fp.meets(&p.pose, &peer.footprint, &peer.pose, PEER_MARGIN_M)
                            && !others.iter().any(|o| fp.meets(&p.pose, &o.footprint, &o.pose, OTHERS_MARGIN_M))
                    });
                    if !clear {
                        continue;
                    }
                    let end = path[path.len() - 1].pose;
                    if room_to_pass(model, &fp, &end, peer, others) {
                        return Some(PullOver { path, offset_m: side * offset, backwards });
                    }
                    // Less offset on this side leaves the other even less room.
                    continue 'side;
                }
                offset -= 0.02;
            }
        }
    }
    None
}

/// Whether `peer` can drive past a chair parked at `parked` (rectangle `fp`): along its own
/// line shifted away from the parked chair, some lane keeps it clear of the walls, of the
/// parked chair and of the `others` (as they last said where they are) for three metres
/// either side.
pub fn room_to_pass(model: &WorldModel, fp: &Footprint, parked: &Pose, peer: &Peer, others: &[Peer]) -> bool {
    let line = peer.pose;
    let (c, s) = (line.theta.cos(), line.theta.sin());
    let centre = fp.centre(parked) - line.pos();
    let beside = centre.x * c + centre.y * s;
    // The sweep starts ahead of where the other stands: its own rectangle is in the model
    // when it says it is waiting.
    let clear_of_itself = peer.footprint.front + peer.footprint.rear + 0.05;
    // Away from the parked chair, by at least what clears it, and by little more: a lane
    // farther off could lie beyond a wall.
    let side = -centre.x * s + centre.y * c;
    let away = if side > 0.0 { -1.0 } else { 1.0 };
    let least = (fp.half + peer.footprint.half + PASS_GAP_M - side.abs()).max(0.0);
    let mut lane = least;
    while lane <= least + 0.3 {
        let ok = (-30..=30).map(|k| beside + k as f64 * 0.1).filter(|&t| t >= clear_of_itself).all(|t| {
            let q = away * lane;
            let pose = Pose::new(line.x + t * c - q * s, line.y + t * s + q * c, line.theta);
            model.fits(&peer.footprint, &pose, PASS_WALL_M)
                && !peer.footprint.meets(&pose, fp, parked, PASS_GAP_M)
                && !others.iter().any(|o| peer.footprint.meets(&pose, &o.footprint, &o.pose, PASS_GAP_M))
        });
        if ok {
            return true;
        }
        lane += 0.03;
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Body;
    use crate::map::{MapWall, NavMap};
    use crate::traffic::State;

    /// A straight corridor like LIACC's: 1.78 m wide between y = 5.13 and y = 6.91.
    fn corridor() -> WorldModel {
        let mut map = NavMap::empty(30.0, 12.0);
        map.walls.push(MapWall::rectangle(0.0, 4.99, 30.0, 5.13, false));
        map.walls.push(MapWall::rectangle(0.0, 6.91, 30.0, 7.21, false));
        WorldModel::new(map, Body::INTELLWHEELS.footprint())
    }

    fn fp_top(p: &Pose) -> f64 {
        Body::INTELLWHEELS.footprint().corners(p, 0.0).iter().map(|c| c.y).fold(f64::MIN, f64::max)
    }

    fn peer_at(x: f64, y: f64, deg: f64) -> Peer {
        Peer {
            name: "chair1".into(),
            pose: Pose::from_deg(x, y, deg),
            state: State::Go,
            footprint: Body::INTELLWHEELS.footprint(),
            heard_s: 0.0,
            still_since_s: 0.0,
            claim: None,
        }
    }

    #[test]
    fn the_s_curve_backwards_mirrors_the_one_forwards_behind_the_chair() {
        let from = Pose::from_deg(2.0, 1.0, 90.0);
        let (ahead, back) = (s_curve(from, -0.5, 2.0), s_curve_back(from, -0.5, 2.0));
        assert_eq!(ahead.len(), back.len());
        for (a, b) in ahead.iter().zip(&back) {
            // Mirrored across the line through `from` square to its heading.
            assert!((b.pose.x - a.pose.x).abs() < 1e-9 && (b.pose.y - (2.0 * from.y - a.pose.y)).abs() < 1e-9);
            assert!((b.pose.theta - from.theta + (a.pose.theta - from.theta)).abs() < 1e-9);
        }
        let end = back[back.len() - 1].pose;
        // Facing north, backing south, the right is east.
        assert!((end.x - 2.5).abs() < 1e-9 && (end.y + 1.0).abs() < 1e-9, "{end:?}");
    }

    #[test]
    fn the_s_curve_is_smooth_and_ends_parallel_and_aside() {
        let from = Pose::from_deg(2.0, 1.0, 90.0);
        let path = s_curve(from, -0.5, 2.0);
        let end = path[path.len() - 1].pose;
        // Heading north, the right is east.
        assert!((end.x - 2.5).abs() < 1e-9 && (end.y - 3.0).abs() < 1e-9, "{end:?}");
        assert!((end.theta - from.theta).abs() < 1e-9);
        assert_eq!(path[0].motion, Motion::Start);
        for w in path.windows(2) {
            let step = (w[1].pose.pos() - w[0].pose.pos()).norm();
            assert!(step > 0.04 && step < 0.07, "{step}");
            assert!((w[1].pose.theta - w[0].pose.theta).abs() < 0.05);
        }
    }

    #[test]
    fn in_the_liacc_corridor_the_chair_pulls_over_to_its_right_and_leaves_room() {
        let model = corridor();
        // Westbound on the centre line: its right is north.
        let me = Pose::from_deg(21.0, 6.02, 180.0);
        let peer = peer_at(14.5, 6.0, 0.0);
        let p = pull_over(&model, me, &peer, &[]).expect("room to pull over");
        assert_eq!((p.side(), p.backwards), ("right", false));
        let end = p.path[p.path.len() - 1].pose;
        let fp = model.footprint;
        // Against the north wall, clear of it, and parallel to the corridor.
        let top = fp.corners(&end, 0.0).iter().map(|c| c.y).fold(f64::MIN, f64::max);
        assert!(top < 6.91 - WALL_MARGIN_M + 1e-9 && top > 6.91 - 0.16, "top edge at {top}");
        assert!((end.theta - me.theta).abs() < 1e-9);
        for q in &p.path {
            let top = fp.corners(&q.pose, 0.0).iter().map(|c| c.y).fold(f64::MIN, f64::max);
            assert!(top < 6.91 - WALL_MARGIN_M + 1e-9, "{q:?} comes within {} m of the wall", 6.91 - top);
        }
        assert!(room_to_pass(&model, &fp, &end, &peer, &[]));
        // Not by enough when the other chair is far wider than the corridor allows.
        let mut wide = peer.clone();
        wide.footprint = Footprint::of_body(1.1, 1.2, 0.8);
        assert_eq!(pull_over(&model, me, &wide, &[]), None);
    }

    #[test]
    fn a_chair_already_near_one_wall_pulls_over_to_the_other_side_when_that_leaves_room() {
        let model = corridor();
        // Eastbound near the south wall: its right has no room left; its left does.
        let me = Pose::from_deg(10.0, 5.6, 0.0);
        let peer = peer_at(17.0, 6.3, 180.0);
        let p = pull_over(&model, me, &peer, &[]).expect("room on the left");
        assert_eq!(p.side(), "left");
        let end = p.path[p.path.len() - 1].pose;
        assert!(end.y > 6.2 && fp_top(&end) < 6.91 - WALL_MARGIN_M + 1e-9, "{end:?}");
    }

    #[test]
    fn a_third_chair_where_the_pull_over_would_go_leaves_room_only_behind_until_it_has_gone() {
        let model = corridor();
        let me = Pose::from_deg(23.0, 6.0, 180.0);
        let peer = peer_at(15.0, 6.0, 0.0);
        // Another westbound chair 2 m ahead, itself pulling over to the north: no room
        // ahead, so the chair backs into the north side behind it, in line with it.
        let mut ahead = peer_at(21.0, 6.2, 170.0);
        ahead.name = "chair2".into();
        let back = pull_over(&model, me, &peer, std::slice::from_ref(&ahead)).expect("room behind");
        assert_eq!((back.side(), back.backwards), ("right", true), "said to be backwards");
        assert!(back.path[1..].iter().all(|q| matches!(q.motion, Motion::Reverse(_))), "{back:?}");
        let end = back.path[back.path.len() - 1].pose;
        assert!(end.x > me.x + 1.0 && end.y > 6.3 && (end.theta - me.theta).abs() < 1e-9, "{end:?}");
        assert!(fp_top(&end) < 6.91 - WALL_MARGIN_M + 1e-9, "{end:?}");
        for q in &back.path {
            assert!(model.free(&q.pose, WALL_MARGIN_M), "{q:?}");
            assert!(!model.footprint.meets(&q.pose, &ahead.footprint, &ahead.pose, OTHERS_MARGIN_M), "{q:?}");
        }
        // With a chair close behind too, there is no room either way.
        let mut behind = peer_at(25.2, 6.0, 180.0);
        behind.name = "chair4".into();
        assert_eq!(pull_over(&model, me, &peer, &[ahead.clone(), behind]), None);
        ahead.pose = Pose::from_deg(18.5, 6.43, 180.0);
        let p = pull_over(&model, me, &peer, &[ahead]).expect("room behind it once it has parked further on");
        assert_eq!(p.side(), "right");
        // The south side would leave chair1 an S-bend between the two: never chosen.
        let mut parked_north = peer_at(21.2, 6.43, 180.0);
        parked_north.name = "chair2".into();
        let me = Pose::from_deg(24.0, 6.0, 180.0);
        let north = Pose::from_deg(23.0, 6.43, 180.0);
        assert!(!room_to_pass(
            &model,
            &model.footprint,
            &Pose::from_deg(23.0, 5.57, 180.0),
            &peer,
            &[parked_north.clone()]
        ));
        assert!(room_to_pass(&model, &model.footprint, &north, &peer, &[parked_north.clone()]));
        if let Some(p) = pull_over(&model, me, &peer, &[parked_north]) {
            assert_eq!(p.side(), "right", "{p:?}");
        }
    }

    #[test]
    fn no_room_at_all_in_a_corridor_narrower_than_two_chairs() {
        let mut map = NavMap::empty(30.0, 12.0);
        map.walls.push(MapWall::rectangle(0.0, 4.99, 30.0, 5.13, false));
        map.walls.push(MapWall::rectangle(0.0, 6.3, 30.0, 6.6, false));
        let model = WorldModel::new(map, Body::INTELLWHEELS.footprint());
        assert_eq!(pull_over(&model, Pose::from_deg(10.0, 5.7, 0.0), &peer_at(17.0, 5.7, 180.0), &[]), None);
    }
}
