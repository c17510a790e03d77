//! The metrics of multi-robot navigation, measured from the hub's record (true poses, the
//! world's contact counts): per robot its clearances, what its contacts were with, and how
//! long it stood still short of its goal; per run the success rate, makespan, sum of times,
//! deadlocks and throughput ([`run_records::summary::TrafficSummary`]).

use run_records::summary::{RobotSummary, TrafficSummary};
use sim_model::{point_in_polygon, point_segment_distance};

/// A robot slower than this, m/s, stands still.
const STILL_MPS: f64 = 0.02;
/// Robots that all stand still short of their goals for this long, each within
/// [`DEADLOCK_NEAR_M`] of another of them, are deadlocked, seconds.
pub const DEADLOCK_S: f64 = 20.0;
/// How near (body to body, metres) robots must stand to block each other.
pub const DEADLOCK_NEAR_M: f64 = 1.5;

/// A convex or simple polygon's corners, and its bounding box.
#[derive(Debug, Clone)]
pub struct Shape {
    corners: Vec<[f64; 2]>,
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Shape {
    /// The shape with these corners.
    pub fn new(corners: impl IntoIterator<Item = [f64; 2]>) -> Self {
        let corners: Vec<[f64; 2]> = corners.into_iter().collect();
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for c in &corners {
            lo = [lo[0].min(c[0]), lo[1].min(c[1])];
            hi = [hi[0].max(c[0]), hi[1].max(c[1])];
        }
        Self { corners, lo, hi }
    }

    fn edges(&self) -> impl Iterator<Item = ([f64; 2], [f64; 2])> + '_ {
        let n = self.corners.len();
        (0..n).map(move |i| (self.corners[i], self.corners[(i + 1) % n]))
    }

    /// How far apart the boxes are (a lower bound of the shapes' distance).
    fn box_gap(&self, other: &Shape) -> f64 {
        let dx = (other.lo[0] - self.hi[0]).max(self.lo[0] - other.hi[0]).max(0.0);
        let dy = (other.lo[1] - self.hi[1]).max(self.lo[1] - other.hi[1]).max(0.0);
        dx.hypot(dy)
    }

    /// The distance between two shapes, 0 when they overlap.
    pub fn distance(&self, other: &Shape) -> f64 {
        let overlap = self.corners.iter().any(|&c| point_in_polygon(c, &other.corners))
            || other.corners.iter().any(|&c| point_in_polygon(c, &self.corners))
            || self.edges().any(|(a, b)| other.edges().any(|(c, d)| crosses(a, b, c, d)));
        if overlap {
            return 0.0;
        }
        let one = self.corners.iter().flat_map(|&p| other.edges().map(move |(a, b)| point_segment_distance(p, a, b)));
        let two = other.corners.iter().flat_map(|&p| self.edges().map(move |(a, b)| point_segment_distance(p, a, b)));
        one.chain(two).fold(f64::INFINITY, f64::min)
    }
}

/// Whether segments a–b and c–d cross.
fn crosses(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let side = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]);
    let (d1, d2) = (side(c, d, a), side(c, d, b));
    let (d3, d4) = (side(a, b, c), side(a, b, d));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// The fixed things of the lab a robot can touch.
#[derive(Debug, Clone)]
pub struct Fixed {
    walls: Vec<Shape>,
    obstacles: Vec<Shape>,
    width: f64,
    height: f64,
}

impl Fixed {
    /// The lab's walls (the first `obstacle_from`) and the scenario's obstacles (the rest),
    /// inside a `width` × `height` border.
    pub fn new(walls: Vec<Shape>, obstacle_from: usize, width: f64, height: f64) -> Self {
        let mut walls = walls;
        let obstacles = walls.split_off(obstacle_from.min(walls.len()));
        Self { walls, obstacles, width, height }
    }

    /// Distances from `body` to the nearest wall (the border included) and the nearest
    /// obstacle (infinite without any).
    fn clearances(&self, body: &Shape) -> (f64, f64) {
        let border = body
            .corners
            .iter()
            .map(|c| c[0].min(c[1]).min(self.width - c[0]).min(self.height - c[1]))
            .fold(f64::INFINITY, f64::min)
            .max(0.0);
        let nearest = |shapes: &[Shape], start: f64| {
            shapes.iter().fold(start, |best, s| if body.box_gap(s) >= best { best } else { best.min(body.distance(s)) })
        };
        (nearest(&self.walls, border), nearest(&self.obstacles, f64::INFINITY))
    }
}

/// One robot at one tick of the record.
#[derive(Debug, Clone)]
pub struct Seen {
    /// Which robot: the same number for it at every tick.
    pub index: usize,
    /// Its body in the world.
    pub body: Shape,
    /// Where its centre of movement is.
    pub pos: [f64; 2],
    /// The world's contact count for it.
    pub contacts: u64,
    /// Whether it has finished its route (robots without one never have).
    pub arrived: bool,
    /// Whether it has a route at all.
    pub routed: bool,
}

/// The traffic measures of one robot, gathered tick by tick.
#[derive(Debug, Clone, Default)]
pub struct RobotMetrics {
    contacts: u64,
    min_wall: f64,
    min_chair: f64,
    contacts_chair: u64,
    contacts_wall: u64,
    contacts_obstacle: u64,
    still_s: f64,
    last: Option<(f64, [f64; 2])>,
    /// Since when it has stood still short of its goal, seconds.
    still_since: Option<f64>,
}

impl RobotMetrics {
    fn new() -> Self {
        Self { min_wall: f64::INFINITY, min_chair: f64::INFINITY, ..Default::default() }
    }
}

/// Measures every robot of a run, tick by tick, and the run's traffic.
#[derive(Debug, Clone)]
pub struct Traffic {
    fixed: Fixed,
    robots: Vec<RobotMetrics>,
    /// Deadlocks found.
    deadlocks: u64,
    /// The robots (their indices) in a deadlock at the last tick: a group counts once, when it
    /// forms.
    deadlocked: Vec<usize>,
    last_t: f64,
}

impl Traffic {
    /// A run in a lab of these fixed things.
    pub fn new(fixed: Fixed) -> Self {
        Self { fixed, robots: Vec::new(), deadlocks: 0, deadlocked: Vec::new(), last_t: 0.0 }
    }

    /// The robots in the world at `t` seconds.
    pub fn observe(&mut self, t: f64, seen: &[Seen]) {
        let n = seen.iter().map(|s| s.index + 1).max().unwrap_or(0);
        while self.robots.len() < n {
            self.robots.push(RobotMetrics::new());
        }
        self.last_t = t;
        for (k, s) in seen.iter().enumerate() {
            let (wall, obstacle) = self.fixed.clearances(&s.body);
            // The nearest other robot (a box farther than the nearest so far cannot be nearer).
            let chair = seen.iter().enumerate().filter(|&(j, _)| j != k).fold(f64::INFINITY, |best, (_, o)| {
                if s.body.box_gap(&o.body) >= best { best } else { best.min(s.body.distance(&o.body)) }
            });
            let m = &mut self.robots[s.index];
            m.min_wall = m.min_wall.min(wall);
            m.min_chair = m.min_chair.min(chair);
            if s.contacts > m.contacts {
                // What it touched: the nearest thing as it stands now.
                let new = s.contacts - m.contacts;
                if chair <= wall.min(obstacle) {
                    m.contacts_chair += new;
                } else if obstacle < wall {
                    m.contacts_obstacle += new;
                } else {
                    m.contacts_wall += new;
                }
                m.contacts = s.contacts;
            }
            let moving = m
                .last
                .is_none_or(|(t0, p)| t <= t0 || (s.pos[0] - p[0]).hypot(s.pos[1] - p[1]) / (t - t0) >= STILL_MPS);
            if let Some((t0, _)) = m.last
                && !moving
                && s.routed
                && !s.arrived
            {
                m.still_s += t - t0;
            }
            m.still_since = if moving || !s.routed || s.arrived { None } else { m.still_since.or(Some(t)) };
            m.last = Some((t, s.pos));
        }
        // A deadlock: robots standing still short of their goals for DEADLOCK_S, each near
        // another of them.
        let stuck: Vec<usize> = (0..seen.len())
            .filter(|&k| self.robots[seen[k].index].still_since.is_some_and(|t0| t - t0 >= DEADLOCK_S))
            .collect();
        // Groups of them, each robot within reach of another of its group.
        let mut group: Vec<usize> = (0..stuck.len()).collect();
        fn root(group: &mut [usize], mut a: usize) -> usize {
            while group[a] != a {
                group[a] = group[group[a]];
                a = group[a];
            }
            a
        }
        for a in 0..stuck.len() {
            for b in a + 1..stuck.len() {
                if seen[stuck[a]].body.distance(&seen[stuck[b]].body) <= DEADLOCK_NEAR_M {
                    let (ra, rb) = (root(&mut group, a), root(&mut group, b));
                    group[ra] = rb;
                }
            }
        }
        let mut now = Vec::new();
        for r in 0..stuck.len() {
            let members: Vec<usize> =
                (0..stuck.len()).filter(|&m| root(&mut group, m) == r).map(|m| seen[stuck[m]].index).collect();
            if members.len() < 2 {
                continue;
            }
            if members.iter().all(|m| !self.deadlocked.contains(m)) {
                self.deadlocks += 1;
            }
            now.extend(members);
        }
        self.deadlocked = now;
    }

    /// Writes the measures of robot `k` (its [`Seen::index`]) into its summary.
    pub fn fill(&self, k: usize, r: &mut RobotSummary) {
        let Some(m) = self.robots.get(k) else { return };
        r.arrived = r.finished_route();
        r.min_clearance_wall_m = m.min_wall.is_finite().then_some(m.min_wall);
        r.min_clearance_chair_m = m.min_chair.is_finite().then_some(m.min_chair);
        r.contacts_chair = m.contacts_chair;
        r.contacts_wall = m.contacts_wall;
        r.contacts_obstacle = m.contacts_obstacle;
        r.still_s = m.still_s;
    }

    /// The run's traffic, over the robots that have a route; `None` with fewer than two.
    pub fn summary(&self, robots: &[RobotSummary]) -> Option<TrafficSummary> {
        let routed: Vec<&RobotSummary> = robots.iter().filter(|r| !r.route.is_empty()).collect();
        if routed.len() < 2 {
            return None;
        }
        let arrived: Vec<f64> = routed.iter().filter(|r| r.arrived).filter_map(|r| r.time_s).collect();
        let n = routed.len();
        let all = arrived.len() == n;
        Some(TrafficSummary {
            chairs: n,
            arrived: arrived.len(),
            success_rate: arrived.len() as f64 / n as f64,
            makespan_s: all.then(|| arrived.iter().copied().fold(0.0, f64::max)),
            // A chair that did not arrive counts the whole run.
            sum_of_times_s: arrived.iter().sum::<f64>() + (n - arrived.len()) as f64 * self.last_t,
            deadlocks: self.deadlocks,
            throughput_per_min: if self.last_t > 0.0 { arrived.len() as f64 * 60.0 / self.last_t } else { 0.0 },
            contacts_chair: routed.iter().map(|r| r.contacts_chair).sum(),
            contacts_wall: routed.iter().map(|r| r.contacts_wall).sum(),
            contacts_obstacle: routed.iter().map(|r| r.contacts_obstacle).sum(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x: f64, y: f64, side: f64) -> Shape {
        Shape::new(vec![[x, y], [x + side, y], [x + side, y + side], [x, y + side]])
    }

    #[test]
    fn shapes_measure_their_gap_and_overlap() {
        assert_eq!(square(0.0, 0.0, 1.0).distance(&square(3.0, 0.0, 1.0)), 2.0);
        assert_eq!(square(0.0, 0.0, 1.0).distance(&square(0.5, 0.5, 1.0)), 0.0, "overlapping");
        // A cross: no corner inside the other, edges crossing.
        let bar = Shape::new(vec![[-2.0, -0.1], [2.0, -0.1], [2.0, 0.1], [-2.0, 0.1]]);
        let post = Shape::new(vec![[-0.1, -2.0], [0.1, -2.0], [0.1, 2.0], [-0.1, 2.0]]);
        assert_eq!(bar.distance(&post), 0.0);
    }

    fn seen(index: usize, x: f64, contacts: u64, arrived: bool) -> Seen {
        Seen { index, body: square(x, 1.0, 1.0), pos: [x + 0.5, 1.5], contacts, arrived, routed: true }
    }

    #[test]
    fn contacts_are_told_apart_and_two_still_chairs_side_by_side_are_one_deadlock() {
        let fixed = Fixed::new(vec![square(0.0, 5.0, 1.0), square(8.4, 1.0, 1.0)], 1, 20.0, 10.0);
        let mut t = Traffic::new(fixed);
        // Two chairs 0.1 m apart, one of them 0.5 m from the obstacle at x 8.4.
        t.observe(0.0, &[seen(0, 5.8, 0, false), seen(1, 6.9, 0, false)]);
        t.observe(0.1, &[seen(0, 5.8, 1, false), seen(1, 6.9, 1, false)]);
        // Both stand still 25 s: one deadlock, counted once however long it lasts.
        for k in 2..300 {
            t.observe(k as f64 * 0.1, &[seen(0, 5.8, 1, false), seen(1, 6.9, 1, false)]);
        }
        let mut r = vec![
            RobotSummary { route: vec![1], checkpoints_total: 1, ..Default::default() },
            RobotSummary { route: vec![2], checkpoints_total: 1, ..Default::default() },
        ];
        t.fill(0, &mut r[0]);
        t.fill(1, &mut r[1]);
        assert_eq!((r[0].contacts_chair, r[0].contacts_wall, r[0].contacts_obstacle), (1, 0, 0), "{:?}", r[0]);
        assert!((r[0].min_clearance_chair_m.expect("a chair") - 0.1).abs() < 1e-9);
        assert!((r[0].still_s - 29.9).abs() < 1e-6, "{}", r[0].still_s);
        let s = t.summary(&r).expect("two routed chairs");
        assert_eq!((s.chairs, s.arrived, s.deadlocks, s.makespan_s), (2, 0, 1, None));
        assert_eq!((s.contacts_chair, s.contacts_obstacle), (2, 0));
        assert!((r[1].min_clearance_wall_m.expect("walls") - 1.0).abs() < 1e-9, "the border below, 1 m off");
        // Moving apart ends it; a chair that arrived is never stuck.
        t.observe(30.0, &[seen(0, 3.0, 1, true), seen(1, 6.9, 1, false)]);
        assert!(t.deadlocked.is_empty());
        // Two jams apart from each other, one forming while the other lasts: two more.
        for k in 0..300 {
            let mut all = vec![seen(2, 1.0, 0, false), seen(3, 2.1, 0, false)];
            if k >= 50 {
                all.extend([seen(4, 11.0, 0, false), seen(5, 12.1, 0, false)]);
            }
            t.observe(40.0 + k as f64 * 0.1, &all);
        }
        assert_eq!(t.deadlocks, 3);
    }
}
