//! Meeting another chair head-on: the two agree by messages who yields (beyond the thesis).
//!
//! Every navigator says where it is each second, `nav NAME X Y HEADING go|yield`. When two of
//! them are within `MEET_M`, face each other and each has the other ahead, both apply the same
//! rule to what they heard — the name that sorts last yields — and say so: the yielder pulls
//! over to its right, against the wall, stops, and says `yield`; the other waits until it has
//! heard that `yield`, then passes in a lane offset to its own right, parallel to its heading,
//! until the parked chair is behind it. Then both go back to their navigators, which re-plan
//! from where they are. Nothing is decided on one side alone: the chair with the right of way
//! does not move into the narrow part before the other has answered. (The navigator's planner
//! would treat the parked chair as an obstacle, but in a corridor the gap beside it is narrower
//! than its planning margins; the negotiated lane is exact.)

use crate::geom::Pose;

/// Chairs nearer than this, facing each other, negotiate.
pub const MEET_M: f64 = 4.5;
/// A peer not heard for this many seconds is forgotten.
const FORGET_S: f64 = 3.0;
/// How far to the right the yielder pulls over, metres (a corridor of 1.8 m leaves the other
/// chair a lane of about a metre).
pub const PULL_OVER_M: f64 = 0.52;

/// What another navigator said.
#[derive(Debug, Clone, PartialEq)]
pub struct Peer {
    /// Its name.
    pub name: String,
    /// Where it is: x, y metres, heading radians.
    pub pose: Pose,
    /// Whether it has pulled over for us.
    pub yielding: bool,
    /// When we heard it, seconds.
    pub heard_s: f64,
}

/// The message a navigator says about itself.
pub fn encode(name: &str, pose: Pose, yielding: bool) -> String {
    format!(
        "nav {name} {:.2} {:.2} {:.1} {}",
        pose.x,
        pose.y,
        pose.theta.to_degrees(),
        if yielding { "yield" } else { "go" }
    )
}

/// Reads another navigator's message; `None` for anything else.
pub fn decode(bytes: &[u8], heard_s: f64) -> Option<Peer> {
    let text = std::str::from_utf8(bytes).ok()?;
    let mut w = text.split_whitespace();
    if w.next()? != "nav" {
        return None;
    }
    let name = w.next()?.to_owned();
    let mut num = || w.next()?.parse::<f64>().ok().filter(|v| v.is_finite());
    let (x, y, deg) = (num()?, num()?, num()?);
    let yielding = match w.next()? {
        "yield" => true,
        "go" => false,
        _ => return None,
    };
    Some(Peer { name, pose: Pose { x, y, theta: deg.to_radians() }, yielding, heard_s })
}

/// How far to the right of its line the passing chair drives, metres.
pub const PASS_OFFSET_M: f64 = 0.45;

/// What the traffic rule asks of the chair this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// Drive on with the navigator.
    Go,
    /// We have the right of way but the other has not pulled over yet: stand still.
    WaitForAnswer,
    /// Pass in the lane through `origin` along `heading`.
    Pass {
        /// A point of the lane.
        origin: [f64; 2],
        /// Its direction.
        heading: f64,
    },
    /// Pull over to `spot` (facing `heading`) and stay there.
    PullOver {
        /// Where to park.
        spot: [f64; 2],
        /// Facing.
        heading: f64,
    },
}

/// One navigator's side of the negotiation.
#[derive(Debug, Clone)]
pub struct Traffic {
    name: String,
    peers: Vec<Peer>,
    /// The peer we yield to and where we park, while yielding.
    yielding_to: Option<(String, [f64; 2], f64)>,
    /// The peer we pass and our lane, while passing.
    passing: Option<(String, [f64; 2], f64)>,
    /// Peers we have already crossed; not met again until they are far away.
    crossed: Vec<String>,
}

fn ahead(me: Pose, other: Pose) -> bool {
    let (dx, dy) = (other.x - me.x, other.y - me.y);
    dx * me.theta.cos() + dy * me.theta.sin() > 0.5
}

fn facing(a: Pose, b: Pose) -> bool {
    let d = (a.theta - b.theta + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    d.abs() > 2.4 // more than about 137° apart
}

impl Traffic {
    /// The rule for the navigator called `name`.
    pub fn new(name: &str) -> Self {
        Self { name: name.to_owned(), peers: Vec::new(), yielding_to: None, passing: None, crossed: Vec::new() }
    }

    /// Whether we are pulled over (what we say).
    pub fn yielding(&self) -> bool {
        self.yielding_to.is_some()
    }

    /// Takes in a message heard at `now_s`.
    pub fn hear(&mut self, bytes: &[u8], now_s: f64) {
        if let Some(p) = decode(bytes, now_s)
            && p.name != self.name
        {
            self.peers.retain(|q| q.name != p.name);
            self.peers.push(p);
        }
    }

    /// Decides for this tick, with our pose estimate.
    pub fn decide(&mut self, me: Pose, now_s: f64) -> Decision {
        self.peers.retain(|p| now_s - p.heard_s <= FORGET_S);
        if let Some((other, spot, heading)) = self.yielding_to.clone() {
            let passed = match self.peers.iter().find(|p| p.name == other) {
                // Behind us (or gone past the parked chair) or well away: carry on.
                Some(p) => !ahead(me, p.pose) && (p.pose.x - me.x).hypot(p.pose.y - me.y) > 1.2,
                None => true,
            };
            if passed {
                self.yielding_to = None;
                self.crossed.push(other);
                return Decision::Go;
            }
            return Decision::PullOver { spot, heading };
        }
        if let Some((other, origin, heading)) = self.passing.clone() {
            let behind = match self.peers.iter().find(|p| p.name == other) {
                Some(p) => !ahead(me, p.pose) && (p.pose.x - me.x).hypot(p.pose.y - me.y) > 1.5,
                None => true,
            };
            if behind {
                self.passing = None;
                self.crossed.push(other);
                return Decision::Go;
            }
            return Decision::Pass { origin, heading };
        }
        let peers = &self.peers;
        self.crossed
            .retain(|n| peers.iter().any(|p| &p.name == n && (p.pose.x - me.x).hypot(p.pose.y - me.y) < 2.0 * MEET_M));
        for p in &self.peers {
            let d = (p.pose.x - me.x).hypot(p.pose.y - me.y);
            if self.crossed.contains(&p.name) {
                continue;
            }
            if d > MEET_M || !facing(me, p.pose) || !ahead(me, p.pose) || !ahead(p.pose, me) {
                continue;
            }
            if self.name > p.name {
                // We yield: park to our right, a little ahead, facing the way we were going.
                let right = me.theta - std::f64::consts::FRAC_PI_2;
                let spot = [
                    me.x + PULL_OVER_M * right.cos() + 0.3 * me.theta.cos(),
                    me.y + PULL_OVER_M * right.sin() + 0.3 * me.theta.sin(),
                ];
                self.yielding_to = Some((p.name.clone(), spot, me.theta));
                return Decision::PullOver { spot, heading: me.theta };
            }
            if !p.yielding {
                return Decision::WaitForAnswer;
            }
            let right = me.theta - std::f64::consts::FRAC_PI_2;
            let origin = [me.x + PASS_OFFSET_M * right.cos(), me.y + PASS_OFFSET_M * right.sin()];
            self.passing = Some((p.name.clone(), origin, me.theta));
            return Decision::Pass { origin, heading: me.theta };
        }
        Decision::Go
    }
}

/// Powers that park the chair at `spot` facing `heading`, from pose estimate `me`: turn toward
/// the spot, creep to it, then turn to the heading and stop. Gentle, since it happens a metre
/// from another chair.
pub fn park(me: Pose, spot: [f64; 2], heading: f64) -> [f64; 2] {
    let wrap = |a: f64| (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    let (dx, dy) = (spot[0] - me.x, spot[1] - me.y);
    let dist = dx.hypot(dy);
    if dist > 0.08 {
        // Reverse toward it when it is behind us: parking back-and-to-the-side is shorter.
        let bearing = dy.atan2(dx);
        let forward = wrap(bearing - me.theta).abs() < std::f64::consts::FRAC_PI_2;
        let aim = if forward { bearing } else { wrap(bearing + std::f64::consts::PI) };
        let err = wrap(aim - me.theta);
        if err.abs() > 0.35 {
            let t = (0.6 * err).clamp(-0.25, 0.25);
            return [-t, t];
        }
        let v = (0.6 * dist).clamp(0.08, 0.25) * if forward { 1.0 } else { -1.0 };
        let t = (0.8 * err).clamp(-0.15, 0.15);
        return [v - t, v + t];
    }
    let err = wrap(heading - me.theta);
    if err.abs() > 0.05 {
        let t = (0.6 * err).clamp(-0.2, 0.2);
        let t = if t.abs() < 0.05 { 0.05 * t.signum() } else { t };
        return [-t, t];
    }
    [0.0, 0.0]
}

/// Powers that follow the lane through `origin` along `heading`: steer onto it and along it
/// at a walking pace.
pub fn follow_lane(me: Pose, origin: [f64; 2], heading: f64) -> [f64; 2] {
    let wrap = |a: f64| (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    // Signed distance to the left of the lane, and the heading that closes it within ~1 m.
    let cross = -(me.x - origin[0]) * heading.sin() + (me.y - origin[1]) * heading.cos();
    let want = heading - (1.2 * cross).clamp(-0.5, 0.5);
    let err = wrap(want - me.theta);
    if err.abs() > 0.6 {
        let t = (0.6 * err).clamp(-0.25, 0.25);
        return [-t, t];
    }
    let t = (0.9 * err).clamp(-0.2, 0.2);
    [0.5 - t, 0.5 + t]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, y: f64, deg: f64) -> Pose {
        Pose { x, y, theta: deg.to_radians() }
    }

    #[test]
    fn messages_round_trip_and_junk_is_ignored() {
        let m = encode("chair2", pose(20.0, 6.0, 180.0), true);
        assert_eq!(m, "nav chair2 20.00 6.00 180.0 yield");
        let p = decode(m.as_bytes(), 1.0).expect("decodes");
        assert_eq!((p.name.as_str(), p.yielding, p.pose.x), ("chair2", true, 20.0));
        for junk in
            [&b"door open door1"[..], b"nav", b"nav a 1 2", b"nav a 1 2 NaN go", b"nav a 1 2 3 maybe", b"\xff\xfe"]
        {
            assert_eq!(decode(junk, 0.0), None, "{junk:?}");
        }
    }

    #[test]
    fn the_later_name_yields_and_the_other_waits_for_its_answer() {
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(19.0, 6.0, 180.0));
        let mut one = Traffic::new("chair1");
        let mut two = Traffic::new("chair2");
        one.hear(encode("chair2", b, false).as_bytes(), 0.0);
        two.hear(encode("chair1", a, false).as_bytes(), 0.0);
        assert_eq!(one.decide(a, 0.1), Decision::WaitForAnswer);
        let Decision::PullOver { spot, heading } = two.decide(b, 0.1) else { panic!("chair2 yields") };
        // Its right, facing west, is north: y grows.
        assert!(spot[1] > 6.3 && (heading - std::f64::consts::PI).abs() < 1e-9, "{spot:?}");
        assert!(two.yielding());
        one.hear(encode("chair2", b, true).as_bytes(), 0.2);
        // chair1 passes in a lane 0.45 m to its right (south), then drives on.
        let Decision::Pass { origin, heading } = one.decide(a, 0.3) else { panic!("chair1 passes") };
        assert!((origin[1] - (6.0 - PASS_OFFSET_M)).abs() < 1e-9 && heading == 0.0, "{origin:?}");
        one.hear(encode("chair2", b, true).as_bytes(), 4.0);
        assert!(matches!(one.decide(pose(18.0, 5.55, 0.0), 4.0), Decision::Pass { .. }), "still beside it");
        assert_eq!(one.decide(pose(20.6, 5.55, 0.0), 4.1), Decision::Go, "1.6 m past it");
        // Once chair1 is behind chair2, chair2 goes on.
        two.hear(encode("chair1", pose(18.0, 5.6, 0.0), false).as_bytes(), 5.0);
        assert!(matches!(two.decide(pose(18.8, 6.45, 180.0), 5.0), Decision::PullOver { .. }));
        two.hear(encode("chair1", pose(20.5, 5.6, 0.0), false).as_bytes(), 9.0);
        assert_eq!(two.decide(pose(18.8, 6.45, 180.0), 9.0), Decision::Go);
        assert!(!two.yielding());
    }

    #[test]
    fn chairs_going_the_same_way_or_far_apart_do_not_negotiate() {
        let mut one = Traffic::new("chair1");
        one.hear(encode("chair2", pose(17.0, 6.0, 0.0), false).as_bytes(), 0.0);
        assert_eq!(one.decide(pose(15.0, 6.0, 0.0), 0.0), Decision::Go, "same direction");
        one.hear(encode("chair2", pose(25.0, 6.0, 180.0), false).as_bytes(), 0.0);
        assert_eq!(one.decide(pose(15.0, 6.0, 0.0), 0.0), Decision::Go, "10 m away");
        one.hear(encode("chair2", pose(13.0, 6.0, 180.0), false).as_bytes(), 0.0);
        assert_eq!(one.decide(pose(15.0, 6.0, 0.0), 0.0), Decision::Go, "behind, going away");
        one.hear(encode("chair2", pose(18.0, 6.0, 180.0), false).as_bytes(), 0.0);
        assert_eq!(one.decide(pose(15.0, 6.0, 0.0), 5.0), Decision::Go, "not heard for 5 s");
    }

    #[test]
    fn the_lane_is_joined_and_held() {
        // 0.3 m left of an eastward lane: steer right (left wheel faster).
        let p = follow_lane(pose(0.0, 0.3, 0.0), [0.0, 0.0], 0.0);
        assert!(p[0] > p[1] && p[0] > 0.0, "{p:?}");
        assert_eq!(follow_lane(pose(3.0, 0.0, 0.0), [0.0, 0.0], 0.0), [0.5, 0.5]);
    }

    #[test]
    fn parking_turns_creeps_and_squares_up() {
        let p = park(pose(0.0, 0.0, 0.0), [0.2, 1.0], 0.0);
        assert!(p[1] > 0.0 && p[0] < 0.0, "turn left toward it: {p:?}");
        let p = park(pose(0.0, 0.0, 0.0), [1.0, 0.0], 0.0);
        assert!(p[0] > 0.0 && p[1] > 0.0, "ahead: forward {p:?}");
        let p = park(pose(0.0, 0.0, 0.0), [-1.0, 0.0], 0.0);
        assert!(p[0] < 0.0 && p[1] < 0.0, "behind: reverse {p:?}");
        assert_eq!(park(pose(1.0, 1.0, 30.0), [1.0, 1.0], 30f64.to_radians()), [0.0, 0.0]);
    }
}
