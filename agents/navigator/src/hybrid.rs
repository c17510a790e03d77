//! The local planner: hybrid A* over (x, y, heading) with the chair's true rectangle.
//!
//! A grid route treats the chair as a disc round its axle, which a rear-wheel-drive chair is
//! not: 0.88 m of it is ahead of the axle, so where a point fits the front may not. This
//! search moves the real rectangle along short arcs (forward, optionally backward) and turns
//! on the spot, checks every pose against the known walls and the sensed obstacles with a
//! margin, and is guided by the grid's cost-to-go, so it explores little where the way is
//! easy and finds S-bends like the slalom's where it is not.

use std::collections::{BinaryHeap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use crate::geom::{BodyFrame, Pose, V2, wrap_rad};
use crate::model::WorldModel;
use crate::plan::{CostToGo, Open};

/// How a pose was reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// The start.
    Start,
    /// Forward along an arc of this curvature (1/m, left positive).
    Forward(f64),
    /// Backward along an arc of this curvature.
    Reverse(f64),
    /// A turn on the spot, counter-clockwise when positive (radians).
    Spin(f64),
}

impl Motion {
    /// 1 forward, −1 backward, 0 on the spot or at the start.
    pub fn direction(&self) -> i8 {
        match self {
            Motion::Forward(_) => 1,
            Motion::Reverse(_) => -1,
            Motion::Start | Motion::Spin(_) => 0,
        }
    }

    /// The curvature of an arc (0 for a spin).
    pub fn curvature(&self) -> f64 {
        match *self {
            Motion::Forward(k) | Motion::Reverse(k) => k,
            Motion::Start | Motion::Spin(_) => 0.0,
        }
    }
}

/// One pose of a planned path and the motion that reached it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPose {
    /// The pose.
    pub pose: Pose,
    /// How it was reached from the previous one.
    pub motion: Motion,
}

/// Where a leg ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// The checkpoint.
    pub pos: V2,
    /// A pose this near ends the search at once.
    pub stop_within: f64,
    /// Poses this near are acceptable ends; the search keeps the one with the least cost
    /// plus `weight` × distance.
    pub accept_within: f64,
    /// Weight of the remaining distance for acceptable ends.
    pub weight: f64,
}

/// The search's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct HybridParams {
    /// Length of one arc, metres.
    pub step_m: f64,
    /// Curvatures of forward arcs, 1/m.
    pub curvatures: Vec<f64>,
    /// Curvatures of backward arcs (empty: never backwards).
    pub reverse_curvatures: Vec<f64>,
    /// Angle of one turn on the spot, radians (0: never turn on the spot).
    pub spin_rad: f64,
    /// Cost of a metre backwards, relative to forwards.
    pub reverse_factor: f64,
    /// Cost of changing between forwards and backwards, metres.
    pub switch_cost: f64,
    /// Cost of a radian turned on the spot, metres.
    pub spin_cost: f64,
    /// Cost of stopping to turn on the spot, metres.
    pub stop_cost: f64,
    /// Extra cost per metre and unit of curvature.
    pub curvature_cost: f64,
    /// Soft margins beyond the hard one: a pose closer to something than the hard margin
    /// plus `comfort[k].0` costs `comfort[k].1` more per metre, so paths keep to the middle
    /// of gaps where they can and come close only where they must (or where the way round
    /// is longer still).
    pub comfort: Vec<(f64, f64)>,
    /// A path may end (at the goal) only where the chair keeps this much more than the hard
    /// margin: it may squeeze past things, but it does not stop pressed against them.
    pub end_clearance_m: f64,
    /// Cost per unit of curvature change between arcs.
    pub curvature_change_cost: f64,
    /// Position resolution of the closed set, metres.
    pub xy_res: f64,
    /// Heading bins of the closed set.
    pub heading_bins: usize,
    /// Nodes expanded at most.
    pub max_expansions: usize,
    /// Weight of the heuristic (above 1: faster, slightly longer paths).
    pub heuristic_weight: f64,
    /// A path that gains this much cost-to-go is long enough; the rest is planned later.
    pub horizon_m: f64,
    /// Poses are checked at most this far apart (the body's farthest corner), metres.
    pub check_step_m: f64,
    /// Cost per metre driven per metre left of the lane's middle, in two-lane passages
    /// ([`crate::grid::StaticRaster::off_lane`]): chairs keep right. 0 (the default) is off.
    pub keep_right: f64,
    /// Heuristic cost per radian that the chair's heading is off the grid's way downhill
    /// ([`CostToGo::downhill`]), beyond [`TURN_SLACK_RAD`]: the cost-to-go knows nothing of
    /// heading, so without it the search fills every pose that faces the wrong way before it
    /// turns (a chair leaving a room through a doorway spent most of its expansions so).
    /// 0 (the default) is off; the navigator's coarse fallback search uses it.
    pub turn_heuristic: f64,
}

/// Heading off the way downhill by less than this costs nothing in the heuristic: the way
/// downhill is quantised to 22.5° and a path curves.
pub const TURN_SLACK_RAD: f64 = 0.35;

impl Default for HybridParams {
    fn default() -> Self {
        Self {
            step_m: 0.1,
            curvatures: vec![0.0, 0.5, -0.5, 1.2, -1.2, 2.5, -2.5],
            reverse_curvatures: vec![0.0, 1.0, -1.0],
            spin_rad: 10f64.to_radians(),
            reverse_factor: 4.0,
            switch_cost: 1.5,
            spin_cost: 0.6,
            stop_cost: 0.3,
            curvature_cost: 0.15,
            curvature_change_cost: 0.25,
            comfort: vec![(0.04, 3.0), (0.12, 0.7)],
            end_clearance_m: 0.04,
            xy_res: 0.05,
            heading_bins: 72,
            max_expansions: 20_000,
            heuristic_weight: 1.25,
            horizon_m: 7.0,
            check_step_m: 0.05,
            keep_right: 0.0,
            turn_heuristic: 0.0,
        }
    }
}

/// What the search found.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanOutcome {
    /// The poses from the start.
    pub path: Vec<PathPose>,
    /// Whether the path ends at the goal; if not, it makes `horizon_m` of progress (or the
    /// most progress found) towards it.
    pub reaches_goal: bool,
    /// Nodes expanded.
    pub expansions: usize,
}

impl PlanOutcome {
    /// The path.
    pub fn path(&self) -> &[PathPose] {
        &self.path
    }

    /// Whether the path ends at the goal.
    pub fn reaches_goal(&self) -> bool {
        self.reaches_goal
    }
}

/// Why [`plan`] found no path.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathSearchError {
    /// The grid's cost-to-go does not reach the start: no way round is known.
    #[error("no way is known from ({x:.2}, {y:.2}) to the goal")]
    NoRoute {
        /// Start x.
        x: f64,
        /// Start y.
        y: f64,
    },
    /// The search ran out of nodes (or of expansions) without progress.
    #[error("no collision-free path found after {expansions} expansions")]
    Exhausted {
        /// Nodes expanded.
        expansions: usize,
    },
}

#[derive(Debug, Clone, Copy)]
struct Node {
    pose: Pose,
    motion: Motion,
    g: f64,
    h: f64,
    /// Distance travelled from the start (for the start's relaxed margin).
    travelled: f64,
    parent: u32,
}

/// The pose after an arc of length `ds` (negative: backwards) and curvature `k`.
pub fn arc(p: &Pose, ds: f64, k: f64) -> Pose {
    let th = p.theta;
    if (k * ds).abs() < 1e-9 {
        let (s, c) = th.sin_cos();
        return Pose::new(p.x + ds * c, p.y + ds * s, th);
    }
    let th2 = th + k * ds;
    Pose::new(p.x + (th2.sin() - th.sin()) / k, p.y + (th.cos() - th2.cos()) / k, th2)
}

/// Plans from `start` towards `goal` with the chair grown by `margin`. Near the start, where
/// the chair may already stand closer than `margin` to something, the margin grows from what
/// the start has to the full value over the first 0.6 m. The whole search at once; see
/// [`Search`] for one spread over several calls.
pub fn plan(
    model: &WorldModel,
    ctg: &CostToGo,
    start: Pose,
    goal: &Goal,
    margin: f64,
    params: &HybridParams,
) -> Result<PlanOutcome, PathSearchError> {
    let mut search = Search::new(model, ctg, start, goal, margin, params)?;
    loop {
        if let Some(result) = search.run(model, ctg, usize::MAX) {
            return result;
        }
    }
}

/// A search under way, which can stop after any number of expansions and go on later (a
/// navigator bounds its work per tick so that a lock-step run does not wait on one long
/// search). Between calls the world model may change; the search goes on with what it then
/// says, as a plan made over a few ticks would.
#[derive(Debug, Clone)]
pub struct Search {
    params: HybridParams,
    goal: Goal,
    margin: f64,
    start_margin: f64,
    h0: f64,
    nodes: Vec<Node>,
    open: BinaryHeap<Open<f64>>,
    closed: HashSet<u64, BuildHasherDefault<KeyHasher>>,
    best_progress: (usize, f64),
    candidate: Option<(usize, f64)>,
    expansions: usize,
    /// Each motion with its length, its turn and its sweep ([`Sample`]s).
    sweeps: Vec<(Motion, f64, f64, Vec<Sample>)>,
}

impl Search {
    /// A search from `start` towards `goal`, not yet begun ([`plan`] says what it looks for).
    pub fn new(
        model: &WorldModel,
        ctg: &CostToGo,
        start: Pose,
        goal: &Goal,
        margin: f64,
        params: &HybridParams,
    ) -> Result<Self, PathSearchError> {
        let Some(h0) = ctg.at(start.pos()) else {
            return Err(PathSearchError::NoRoute { x: start.x, y: start.y });
        };
        let start_margin = model.clearance(&start, margin).min(margin) - 0.005;
        let reach = model.footprint.reach();
        let mut motions: Vec<Motion> = params.curvatures.iter().map(|&k| Motion::Forward(k)).collect();
        motions.extend(params.reverse_curvatures.iter().map(|&k| Motion::Reverse(k)));
        if params.spin_rad > 0.0 {
            motions.push(Motion::Spin(params.spin_rad));
            motions.push(Motion::Spin(-params.spin_rad));
        }
        // Each motion's sweep, as poses in the frame of the pose it starts from: enough that
        // no corner moves more than the check step between two of them; the last is where it
        // ends. Worked out once, they make each successor a few multiplications, not sines.
        let sweeps = motions
            .iter()
            .map(|&m| {
                let (len, turn) = match m {
                    Motion::Forward(kap) | Motion::Reverse(kap) => (params.step_m, (kap * params.step_m).abs()),
                    Motion::Spin(a) => (0.0, a.abs()),
                    Motion::Start => (0.0, 0.0),
                };
                let sweep = len.max(turn * reach);
                let steps = (sweep / params.check_step_m).ceil().max(1.0) as usize;
                let samples = (1..=steps)
                    .map(|s| {
                        let t = s as f64 / steps as f64;
                        let local = match m {
                            Motion::Forward(kap) => arc(&Pose::default(), params.step_m * t, kap),
                            Motion::Reverse(kap) => arc(&Pose::default(), -params.step_m * t, kap),
                            Motion::Spin(a) => Pose { x: 0.0, y: 0.0, theta: a * t },
                            Motion::Start => Pose::default(),
                        };
                        let (sin, cos) = local.theta.sin_cos();
                        Sample { t, x: local.x, y: local.y, theta: local.theta, cos, sin }
                    })
                    .collect();
                (m, len, turn, samples)
            })
            .collect();
        let mut open = BinaryHeap::new();
        open.push(Open { f: params.heuristic_weight * h0, i: 0 });
        Ok(Self {
            params: params.clone(),
            goal: *goal,
            margin,
            start_margin,
            h0,
            nodes: vec![Node { pose: start, motion: Motion::Start, g: 0.0, h: h0, travelled: 0.0, parent: u32::MAX }],
            open,
            closed: HashSet::default(),
            best_progress: (0, h0),
            candidate: None,
            expansions: 0,
            sweeps,
        })
    }

    /// Nodes expanded so far.
    pub fn expansions(&self) -> usize {
        self.expansions
    }

    /// The margin at `travelled` metres from the start.
    fn margin_at(&self, travelled: f64) -> f64 {
        let (margin, start_margin) = (self.margin, self.start_margin);
        if start_margin >= margin {
            margin
        } else {
            start_margin.max(0.0) + (margin - start_margin.max(0.0)) * (travelled / 0.6).min(1.0)
        }
    }

    /// The closed set's key of a pose: its cell and heading bin.
    fn key(&self, p: &Pose) -> u64 {
        let params = &self.params;
        let ix = (p.x / params.xy_res).floor() as i64 as u64 & 0xFFFFF;
        let iy = (p.y / params.xy_res).floor() as i64 as u64 & 0xFFFFF;
        let bins = params.heading_bins as f64;
        let it = ((wrap_rad(p.theta) + std::f64::consts::PI) / std::f64::consts::TAU * bins).round() as u64
            % params.heading_bins as u64;
        (ix << 40) | (iy << 20) | it
    }

    /// What the search orders by besides the cost-to-go: facing away from the way downhill,
    /// the turn still to make (progress is measured on the cost-to-go alone).
    fn turn_of(&self, ctg: &CostToGo, p: &Pose) -> f64 {
        let params = &self.params;
        if params.turn_heuristic <= 0.0 {
            return 0.0;
        }
        ctg.downhill(p.pos())
            .map_or(0.0, |d| params.turn_heuristic * (wrap_rad(p.theta - d).abs() - TURN_SLACK_RAD).max(0.0))
    }

    /// Goes on for at most `allowance` expansions: the outcome once the search has ended,
    /// `None` while it goes on. `ctg` must be the cost-to-go it was made with.
    pub fn run(
        &mut self,
        model: &WorldModel,
        ctg: &CostToGo,
        allowance: usize,
    ) -> Option<Result<PlanOutcome, PathSearchError>> {
        let until = self.expansions.saturating_add(allowance);
        let (goal, h0) = (self.goal, self.h0);
        let weight = self.params.heuristic_weight;
        loop {
            if self.expansions >= until {
                return None;
            }
            let Some(Open { f, i }) = self.open.pop() else { break };
            let n = self.nodes[i as usize];
            if let Some((_, total)) = self.candidate
                && f >= total * weight.max(1.0)
            {
                break;
            }
            if !self.closed.insert(self.key(&n.pose)) {
                continue;
            }
            let dist = (n.pose.pos() - goal.pos).norm();
            let may_end = dist <= goal.accept_within
                && model.free(&n.pose, self.margin_at(n.travelled) + self.params.end_clearance_m);
            if may_end && dist <= goal.stop_within {
                let path = extract(&self.nodes, i as usize);
                return Some(Ok(PlanOutcome { path, reaches_goal: true, expansions: self.expansions }));
            }
            if may_end {
                let total = n.g + goal.weight * dist;
                if self.candidate.is_none_or(|(_, t)| total < t) {
                    self.candidate = Some((i as usize, total));
                }
            }
            if n.h < self.best_progress.1 {
                self.best_progress = (i as usize, n.h);
            }
            if self.candidate.is_none() && h0 - n.h >= self.params.horizon_m {
                let path = extract(&self.nodes, i as usize);
                return Some(Ok(PlanOutcome { path, reaches_goal: false, expansions: self.expansions }));
            }
            self.expansions += 1;
            if self.expansions > self.params.max_expansions {
                break;
            }
            self.expand(model, ctg, &n, i);
        }
        Some(self.end())
    }

    /// Pushes the successors of node `i` (`n`) that are free and not closed.
    fn expand(&mut self, model: &WorldModel, ctg: &CostToGo, n: &Node, i: u32) {
        let params = &self.params;
        let (s0, c0) = n.pose.theta.sin_cos();
        for (m, len, turn, samples) in &self.sweeps {
            let (m, len, turn) = (*m, *len, *turn);
            let at = |q: &Sample| {
                let origin = V2::new(n.pose.x + c0 * q.x - s0 * q.y, n.pose.y + s0 * q.x + c0 * q.y);
                BodyFrame::from_cos_sin(origin, c0 * q.cos - s0 * q.sin, s0 * q.cos + c0 * q.sin)
            };
            let Some(end) = samples.last() else { continue };
            let frame = at(end);
            let pose = Pose::new(frame.origin().x, frame.origin().y, n.pose.theta + end.theta);
            if self.closed.contains(&self.key(&pose)) {
                continue;
            }
            let Some(h) = ctg.at(pose.pos()) else { continue };
            let travelled = n.travelled + len + turn * 0.3;
            let ok = samples.iter().all(|q| {
                let f = if std::ptr::eq(q, end) { frame } else { at(q) };
                model.free_in(&f, self.margin_at(n.travelled + (travelled - n.travelled) * q.t))
            });
            if !ok {
                continue;
            }
            let mut cost = match m {
                Motion::Forward(kap) => len * (1.0 + params.curvature_cost * kap.abs()),
                Motion::Reverse(kap) => len * params.reverse_factor * (1.0 + params.curvature_cost * kap.abs()),
                Motion::Spin(a) => params.spin_cost * a.abs(),
                Motion::Start => 0.0,
            };
            // Soft margins, widest first: a pose free at the widest pays nothing.
            let hard = self.margin_at(travelled);
            for &(extra, per_m) in params.comfort.iter().rev() {
                if model.free_in(&frame, hard + extra) {
                    break;
                }
                cost += per_m * (len + turn * 0.3);
            }
            if params.keep_right > 0.0 && len > 0.0 {
                cost += params.keep_right * len * model.statics.off_lane(&pose);
            }
            let (d0, d1) = (n.motion.direction(), m.direction());
            if d0 != 0 && d1 != 0 && d0 != d1 {
                cost += params.switch_cost;
            }
            if d0 != 0 && matches!(m, Motion::Spin(_)) {
                cost += params.stop_cost;
            }
            if d0 == d1 && d1 != 0 {
                cost += params.curvature_change_cost * (m.curvature() - n.motion.curvature()).abs();
            }
            let g = n.g + cost;
            let f = g + params.heuristic_weight * (h + self.turn_of(ctg, &pose));
            self.nodes.push(Node { pose, motion: m, g, h, travelled, parent: i });
            self.open.push(Open { f, i: (self.nodes.len() - 1) as u32 });
        }
    }

    /// The outcome once the open list is empty, the expansions are spent, or nothing left
    /// can beat the best end found.
    fn end(&self) -> Result<PlanOutcome, PathSearchError> {
        let expansions = self.expansions;
        if let Some((c, _)) = self.candidate {
            return Ok(PlanOutcome { path: extract(&self.nodes, c), reaches_goal: true, expansions });
        }
        // Out of expansions far from the goal: a path that at least gets well on the way is
        // worth driving (the rest is planned from its end); a scrap of progress is not.
        if self.h0 - self.best_progress.1 >= 0.5 * self.params.horizon_m {
            return Ok(PlanOutcome {
                path: extract(&self.nodes, self.best_progress.0),
                reaches_goal: false,
                expansions,
            });
        }
        Err(PathSearchError::Exhausted { expansions })
    }
}

/// A pose along a motion, in the frame of the pose the motion starts from, with its
/// heading's cosine and sine; `t` is how far along (0 to 1).
#[derive(Debug, Clone, Copy)]
struct Sample {
    t: f64,
    x: f64,
    y: f64,
    theta: f64,
    cos: f64,
    sin: f64,
}

/// The closed set's hasher: its keys are packed cell and heading indices, already unique, so
/// one multiplication spreads them (the default SipHash cost a tenth of a search).
#[derive(Debug, Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(self.0 ^ u64::from(b));
        }
    }

    fn write_u64(&mut self, k: u64) {
        let h = k.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = h ^ (h >> 29);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

fn extract(nodes: &[Node], mut i: usize) -> Vec<PathPose> {
    let mut out = Vec::new();
    loop {
        let n = nodes[i];
        out.push(PathPose { pose: n.pose, motion: n.motion });
        if n.parent == u32::MAX {
            break;
        }
        i = n.parent as usize;
    }
    out.reverse();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Footprint;
    use crate::map::{MapWall, NavMap};
    use crate::plan::Costmap;

    #[test]
    fn arcs_end_where_geometry_says() {
        let p = Pose::from_deg(1.0, 2.0, 0.0);
        let q = arc(&p, std::f64::consts::FRAC_PI_2, 1.0);
        assert!((q.x - 2.0).abs() < 1e-12 && (q.y - 3.0).abs() < 1e-12);
        assert!((q.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let back = arc(&p, -0.5, 0.0);
        assert!((back.x - 0.5).abs() < 1e-12 && back.y == 2.0);
    }

    #[test]
    fn a_rear_axle_chair_threads_a_slalom_it_knows() {
        // The LIACC corridor's slalom with both boxes known: below A, then above B.
        let mut map = NavMap::empty(24.0, 9.0);
        map.walls.push(MapWall::rectangle(10.4159, 4.9903, 23.0, 5.1304, false));
        map.walls.push(MapWall::rectangle(10.91, 6.91, 23.0, 7.21, false));
        map.walls.push(MapWall::rectangle(17.0, 6.1, 17.6, 6.4, false));
        map.walls.push(MapWall::rectangle(19.4, 5.5, 20.0, 5.9, false));
        let model = WorldModel::new(map, Footprint::of_body(1.1, 0.65, 0.8));
        let cm = Costmap::build(&model, 0.33, 0.25);
        let goal = V2::new(20.0, 6.1);
        let seeds: Vec<(usize, f32)> = (0..cm.spec.len())
            .filter_map(|i| {
                let (x, y) = cm.spec.coords(i);
                let d = (cm.spec.center(x, y) - goal).norm();
                (d <= 0.5).then_some((i, (4.0 * d) as f32))
            })
            .collect();
        let start = Pose::from_deg(13.0, 6.0, 0.0);
        let start_cell = cm.spec.clamp_cell(start.pos());
        let ctg = CostToGo::new(&cm, &seeds, Some(cm.spec.index(start_cell.0, start_cell.1)), 6.0, 4.0, &[]);
        let g = Goal { pos: goal, stop_within: 0.15, accept_within: 0.5, weight: 4.0 };
        let params =
            HybridParams { horizon_m: 50.0, max_expansions: 60_000, heuristic_weight: 2.0, ..HybridParams::default() };
        let out = plan(&model, &ctg, start, &g, 0.06, &params).expect("a path");
        assert!(out.reaches_goal());
        let path = out.path();
        let end = path.last().expect("poses").pose;
        assert!((end.pos() - goal).norm() <= 0.5);
        for p in path {
            assert!(model.free(&p.pose, 0.059), "{p:?}");
        }
        // Under A the chair is low, above B it is high.
        let y_at =
            |x: f64| path.iter().min_by(|a, b| (a.pose.x - x).abs().total_cmp(&(b.pose.x - x).abs())).map(|p| p.pose.y);
        assert!(y_at(17.3).expect("passes A") < 5.8);
        assert!(y_at(19.7).expect("passes B") > 6.2);
    }

    #[test]
    fn a_start_the_cost_to_go_does_not_reach_has_no_route() {
        // The chair boxed in by four walls; the goal outside.
        let mut map = NavMap::empty(10.0, 10.0);
        for (x0, y0, x1, y1) in [(2.0, 2.0, 5.0, 2.1), (2.0, 4.9, 5.0, 5.0), (2.0, 2.0, 2.1, 5.0), (4.9, 2.0, 5.0, 5.0)]
        {
            map.walls.push(MapWall::rectangle(x0, y0, x1, y1, false));
        }
        let model = WorldModel::new(map, Footprint::of_body(1.1, 0.65, 0.8));
        let cm = Costmap::build(&model, 0.345, 0.26);
        let goal = V2::new(8.0, 8.0);
        let (gx, gy) = cm.spec.clamp_cell(goal);
        let ctg = CostToGo::new(&cm, &[(cm.spec.index(gx, gy), 0.0)], None, 0.0, 4.0, &[]);
        let g = Goal { pos: goal, stop_within: 0.2, accept_within: 0.5, weight: 1.0 };
        let start = Pose::from_deg(3.5, 3.5, 0.0);
        assert_eq!(
            plan(&model, &ctg, start, &g, 0.05, &HybridParams::default()),
            Err(PathSearchError::NoRoute { x: 3.5, y: 3.5 })
        );
    }

    #[test]
    fn a_chair_that_keeps_right_plans_down_its_lane_with_the_lane_aware_cost_to_go() {
        // A 2 m corridor, the chair in its middle bound for its far end. Keeping right costs
        // more than the middle; the plain cost-to-go does not foresee that, so the search
        // spends its expansions on the middle. With the lanes in the cost-to-go it goes
        // straight for the right lane.
        let mut map = NavMap::empty(24.0, 12.0);
        map.walls.push(MapWall::rectangle(0.5, 4.9, 23.5, 5.0, false));
        map.walls.push(MapWall::rectangle(0.5, 7.0, 23.5, 7.1, false));
        let model = WorldModel::new(map, Footprint::of_body(1.1, 0.65, 0.8));
        let cm = Costmap::build(&model, 0.345, 0.26);
        let goal = V2::new(20.0, 6.0);
        let (gx, gy) = cm.spec.clamp_cell(goal);
        let start = Pose::from_deg(3.0, 6.0, 0.0);
        let (sx, sy) = cm.spec.clamp_cell(start.pos());
        let g = Goal { pos: goal, stop_within: 0.2, accept_within: 0.5, weight: 1.0 };
        let params = HybridParams { keep_right: 1.0, ..HybridParams::default() };
        let ctg_of = |lanes| {
            CostToGo::with_lanes(
                &cm,
                &[(cm.spec.index(gx, gy), 0.0)],
                Some(cm.spec.index(sx, sy)),
                6.0,
                4.0,
                &[],
                lanes,
            )
        };
        let aware = plan(&model, &ctg_of(Some((&model.statics, 1.0))), start, &g, 0.05, &params).expect("a path");
        let plain = plan(&model, &ctg_of(None), start, &g, 0.05, &params);
        // A whole horizon of progress, in the right lane (south of the middle, heading east).
        let path = aware.path();
        let end = path.last().expect("poses").pose;
        assert!(end.x - start.x >= params.horizon_m - 0.5, "{end:?}");
        let in_lane: Vec<f64> = path.iter().filter(|p| p.pose.x > 6.0).map(|p| p.pose.y).collect();
        assert!(!in_lane.is_empty() && in_lane.iter().all(|&y| y < 5.85), "{in_lane:?}");
        let plain_expansions = match plain {
            Ok(o) => o.expansions,
            Err(PathSearchError::Exhausted { expansions }) => expansions,
            Err(e) => panic!("{e}"),
        };
        assert!(
            aware.expansions * 4 < plain_expansions,
            "lane-aware {} expansions, plain {plain_expansions}",
            aware.expansions
        );
    }
}
