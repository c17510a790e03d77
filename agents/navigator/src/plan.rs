//! Global planning on the grid: a cost map (walls and sensed obstacles grown by the chair's
//! half-width), A* (8-connected) with line-of-sight smoothing for the route of a leg, and a
//! Dijkstra cost-to-go field that guides the local planner around whatever stands in the way.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::geom::V2;
use crate::grid::{GridSpec, StaticRaster};
use crate::model::WorldModel;

/// Cost of a cell that a wall or a sensed obstacle occupies.
const HARD: u8 = 255;
/// Cost of a cell nearer to an obstacle than the inflation radius.
const SOFT: u8 = 1;
/// Cost of a cell so near an obstacle that the axle cannot be there with the chair passing
/// by (see [`Costmap::build`]).
const NARROW: u8 = 2;

/// Cells the centre of movement may use: 0 free, `SOFT` (1) too near an obstacle for the chair
/// to sit there aligned with a passage, `HARD` (255) occupied.
#[derive(Debug, Clone)]
pub struct Costmap {
    /// The grid.
    pub spec: GridSpec,
    cost: Vec<u8>,
}

impl Costmap {
    /// The cost map of the model: its known walls and sensed obstacles, each grown by
    /// `inflate` metres (cells the centre of movement should avoid) and by `narrow` metres
    /// (cells where it cannot be unless the chair is turning on the spot or leaving a tight
    /// place: the chair's rectangle holds the disc of that radius round its axle).
    pub fn build(model: &WorldModel, inflate: f64, narrow: f64) -> Self {
        let spec = model.spec();
        let dist = model.statics.distances();
        let mut cost: Vec<u8> = (0..spec.len())
            .map(|i| {
                let d = dist[i] as f64;
                if model.statics.occupied(i) {
                    HARD
                } else if d < narrow {
                    NARROW
                } else if d < inflate {
                    SOFT
                } else {
                    0
                }
            })
            .collect();
        let r = (inflate.max(narrow) / spec.cell).ceil() as i64;
        for (c, _) in model.planning_points() {
            let (cx, cy) = spec.coords(c);
            cost[c] = HARD;
            for dy in -r..=r {
                for dx in -r..=r {
                    let (x, y) = (cx as i64 + dx, cy as i64 + dy);
                    if x < 0 || y < 0 || x >= spec.nx as i64 || y >= spec.ny as i64 {
                        continue;
                    }
                    let d = ((dx * dx + dy * dy) as f64).sqrt() * spec.cell;
                    let i = spec.index(x as usize, y as usize);
                    if d < narrow && cost[i] != HARD {
                        cost[i] = NARROW;
                    } else if d < inflate && cost[i] == 0 {
                        cost[i] = SOFT;
                    }
                }
            }
        }
        Self { spec, cost }
    }

    /// Whether the centre of movement may not stand in cell `i` (too near or inside).
    pub fn blocked(&self, i: usize) -> bool {
        self.cost[i] != 0
    }

    /// Whether cell `i` is occupied.
    pub fn hard(&self, i: usize) -> bool {
        self.cost[i] == HARD
    }

    /// Whether the straight line `a`–`b` crosses no blocked cell.
    pub fn line_free(&self, a: V2, b: V2) -> bool {
        let len = (b - a).norm();
        let n = (len / (self.spec.cell * 0.5)).ceil().max(1.0) as usize;
        (0..=n).all(|k| {
            let p = a + (b - a) * (k as f64 / n as f64);
            self.spec.cell_of(p).is_some_and(|(x, y)| !self.blocked(self.spec.index(x, y)))
        })
    }

    /// The free cell nearest to `p` within `radius` metres (breadth first), if any.
    pub fn nearest_free(&self, p: V2, radius: f64) -> Option<(usize, usize)> {
        let (cx, cy) = self.spec.clamp_cell(p);
        let r = (radius / self.spec.cell).ceil() as i64;
        let mut best: Option<((usize, usize), f64)> = None;
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (cx as i64 + dx, cy as i64 + dy);
                if x < 0 || y < 0 || x >= self.spec.nx as i64 || y >= self.spec.ny as i64 {
                    continue;
                }
                let (x, y) = (x as usize, y as usize);
                let d = (self.spec.center(x, y) - p).norm();
                if d <= radius && !self.blocked(self.spec.index(x, y)) && best.is_none_or(|(_, b)| d < b) {
                    best = Some(((x, y), d));
                }
            }
        }
        best.map(|(c, _)| c)
    }
}

/// An entry of an A* or Dijkstra open list: a node index `i` and its key `f` (`f32` on the
/// grid, `f64` in the hybrid search). The grid and hybrid planners share it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Open<F> {
    pub(crate) f: F,
    pub(crate) i: u32,
}

/// Keys an open list can order totally (NaN included), so the heap never panics or wobbles.
pub(crate) trait TotalKey: Copy + PartialEq {
    fn total_cmp(&self, other: &Self) -> Ordering;
}

impl TotalKey for f32 {
    fn total_cmp(&self, other: &Self) -> Ordering {
        f32::total_cmp(self, other)
    }
}

impl TotalKey for f64 {
    fn total_cmp(&self, other: &Self) -> Ordering {
        f64::total_cmp(self, other)
    }
}

impl<F: TotalKey> Eq for Open<F> {}

impl<F: TotalKey> Ord for Open<F> {
    fn cmp(&self, o: &Self) -> Ordering {
        // BinaryHeap is a max-heap: the smallest f first, ties by index for determinism.
        o.f.total_cmp(&self.f).then_with(|| o.i.cmp(&self.i))
    }
}

impl<F: TotalKey> PartialOrd for Open<F> {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The 8 neighbours: (dx, dy, length in cells).
const NEIGHBOURS: [(i64, i64, f32); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, std::f32::consts::SQRT_2),
    (1, -1, std::f32::consts::SQRT_2),
    (-1, 1, std::f32::consts::SQRT_2),
    (-1, -1, std::f32::consts::SQRT_2),
];

/// Calls `f(j, step)` for each neighbour `j` of cell `i` that `passable` admits; a diagonal
/// step needs both cells beside it passable (no cutting corners of walls).
fn neighbours(spec: &GridSpec, i: usize, passable: impl Fn(usize) -> bool, mut f: impl FnMut(usize, f32)) {
    let (x, y) = spec.coords(i);
    for (dx, dy, step) in NEIGHBOURS {
        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
        if nx < 0 || ny < 0 || nx >= spec.nx as i64 || ny >= spec.ny as i64 {
            continue;
        }
        let j = spec.index(nx as usize, ny as usize);
        if !passable(j) {
            continue;
        }
        if dx != 0 && dy != 0 {
            let (a, b) = (spec.index(nx as usize, y), spec.index(x, ny as usize));
            if !passable(a) || !passable(b) {
                continue;
            }
        }
        f(j, step);
    }
}

/// A* from `start` to `goal` over the free cells (8-connected, octile distance). The start
/// cell may be blocked (the chair may stand close to a wall); the goal may not. Returns the
/// cells from start to goal.
pub fn astar(cm: &Costmap, start: (usize, usize), goal: (usize, usize)) -> Option<Vec<(usize, usize)>> {
    let spec = &cm.spec;
    let (s, g) = (spec.index(start.0, start.1), spec.index(goal.0, goal.1));
    if cm.blocked(g) {
        return None;
    }
    let h = |i: usize| {
        let (x, y) = spec.coords(i);
        let (dx, dy) = ((x as f32 - goal.0 as f32).abs(), (y as f32 - goal.1 as f32).abs());
        dx.max(dy) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dy)
    };
    let mut best = vec![f32::INFINITY; spec.len()];
    let mut parent = vec![u32::MAX; spec.len()];
    let mut open = BinaryHeap::new();
    best[s] = 0.0;
    open.push(Open { f: h(s), i: s as u32 });
    while let Some(Open { f, i }) = open.pop() {
        let i = i as usize;
        if i == g {
            let mut cells = vec![spec.coords(g)];
            let mut k = g;
            while k != s {
                k = parent[k] as usize;
                cells.push(spec.coords(k));
            }
            cells.reverse();
            return Some(cells);
        }
        if f > best[i] + h(i) + 1e-4 {
            continue;
        }
        let gi = best[i];
        neighbours(
            spec,
            i,
            |j| !cm.blocked(j),
            |j, step| {
                let gj = gi + step;
                if gj < best[j] {
                    best[j] = gj;
                    parent[j] = i as u32;
                    open.push(Open { f: gj + h(j), i: j as u32 });
                }
            },
        );
    }
    None
}

/// Shortens a cell path by line-of-sight shortcuts: from each kept point, the farthest later
/// cell in view is kept next. Returns the points (cell centres, start and goal included).
pub fn smooth(cm: &Costmap, cells: &[(usize, usize)]) -> Vec<V2> {
    let pts: Vec<V2> = cells.iter().map(|&(x, y)| cm.spec.center(x, y)).collect();
    let Some(&first) = pts.first() else { return Vec::new() };
    let mut out = vec![first];
    let mut i = 0;
    while i + 1 < pts.len() {
        let mut j = i + 1;
        while j + 1 < pts.len() && cm.line_free(pts[i], pts[j + 1]) {
            j += 1;
        }
        out.push(pts[j]);
        i = j;
    }
    out
}

/// A route of one leg: the smoothed polyline and its length.
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    /// Points from the start to the goal.
    pub points: Vec<V2>,
    /// Length, metres.
    pub length_m: f64,
}

/// The route from `from` to `to` for a chair of half-width `half_width`: A* on the cost map
/// grown by it, smoothed. The goal may be moved to the nearest free cell within `goal_slack`.
pub fn route(cm: &Costmap, from: V2, to: V2, goal_slack: f64) -> Option<Route> {
    let start = cm.spec.clamp_cell(from);
    let goal = cm.nearest_free(to, goal_slack.max(cm.spec.cell))?;
    let cells = astar(cm, start, goal)?;
    let mut points = smooth(cm, &cells);
    if let Some(p) = points.first_mut() {
        *p = from;
    }
    let length_m = points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    Some(Route { points, length_m })
}

/// Cost (metres, with detours near obstacles weighed up) from every cell to a goal region.
#[derive(Debug, Clone)]
pub struct CostToGo {
    spec: GridSpec,
    cost: Vec<f32>,
}

impl CostToGo {
    /// Dijkstra from `seeds` (cell, starting cost) over every cell not occupied and not
    /// narrow (narrow cells count only within the discs `open`: round the start and the
    /// goal); cells within the inflation cost `1 + soft_penalty` per metre. When `start` is
    /// reached, the search goes on only `slack` metres further (the local planner needs a
    /// band around the route, not the whole lab).
    pub fn new(
        cm: &Costmap,
        seeds: &[(usize, f32)],
        start: Option<usize>,
        slack: f32,
        soft_penalty: f32,
        open: &[(V2, f64)],
    ) -> Self {
        Self::with_lanes(cm, seeds, start, slack, soft_penalty, open, None)
    }

    /// [`CostToGo::new`] that also charges, per metre, `keep_right` times how far left of its
    /// lane a step drives ([`StaticRaster::off_lane_at`], in the step's direction towards the
    /// goal): the cost-to-go of a chair that keeps right. The hybrid search charges the same
    /// for its arcs, so its heuristic foresees the lane cost; without it the search spends
    /// its expansions proving that no cheaper way exists and gives up.
    pub fn with_lanes(
        cm: &Costmap,
        seeds: &[(usize, f32)],
        start: Option<usize>,
        slack: f32,
        soft_penalty: f32,
        open: &[(V2, f64)],
        lanes: Option<(&StaticRaster, f64)>,
    ) -> Self {
        let spec = cm.spec;
        // The raster must be the costmap's own grid for its cells to be the same.
        let lanes = lanes.filter(|(raster, k)| raster.spec == spec && *k > 0.0);
        let passable = |j: usize| {
            let c = cm.cost[j];
            c != HARD
                && (c != NARROW || {
                    let (x, y) = spec.coords(j);
                    let p = spec.center(x, y);
                    open.iter().any(|&(o, r)| (p - o).norm() <= r)
                })
        };
        // Dijkstra with a bucket queue (Dial's): every step costs at least one cell's length
        // (weights are 1 or more), so with buckets one cell wide a cell taken from bucket k
        // can only improve cells of later buckets, and each cell's cost is final when its
        // bucket is taken, as with a heap, at a fraction of a heap's cost over 200,000 cells.
        let cell = spec.cell as f32;
        let bucket_of = |c: f32| (c / cell) as usize;
        let mut cost = vec![f32::INFINITY; spec.len()];
        let mut buckets: Vec<Vec<u32>> = Vec::new();
        let push = |buckets: &mut Vec<Vec<u32>>, c: f32, i: usize| {
            let b = bucket_of(c);
            if b >= buckets.len() {
                buckets.resize_with(b + 1, Vec::new);
            }
            buckets[b].push(i as u32);
        };
        for &(i, c) in seeds {
            if i < cost.len() && passable(i) && c < cost[i] {
                cost[i] = c;
                push(&mut buckets, c, i);
            }
        }
        let mut limit = f32::INFINITY;
        let mut b = 0;
        'search: while b < buckets.len() {
            while let Some(i) = buckets[b].pop() {
                let i = i as usize;
                let f = cost[i];
                // Stale: the cell was improved into an earlier bucket and taken there.
                if bucket_of(f) != b {
                    continue;
                }
                if f > limit {
                    break 'search;
                }
                if Some(i) == start {
                    limit = f + slack;
                }
                neighbours(&spec, i, passable, |j, step| {
                    let mut w = if cm.blocked(j) { 1.0 + soft_penalty } else { 1.0 };
                    if let Some((raster, keep_right)) = lanes {
                        // The search runs from the goal: a chair on cell j steps towards cell i.
                        let ((xi, yi), (xj, yj)) = (spec.coords(i), spec.coords(j));
                        if let Some(k) = StaticRaster::direction_of(xi as i64 - xj as i64, yi as i64 - yj as i64) {
                            w += (keep_right * raster.off_lane_at(j, k)) as f32;
                        }
                    }
                    let c = f + step * cell * w;
                    if c < cost[j] {
                        cost[j] = c;
                        push(&mut buckets, c, j);
                    }
                });
            }
            b += 1;
        }
        Self { spec, cost }
    }

    /// The way downhill at `p`: the direction (radians) to the cheapest cell on the ring of
    /// cells two away (16 directions, 22.5° apart), which is the way the grid's route
    /// leaves `p`. `None` where the search did not reach or nothing on the ring is cheaper.
    pub fn downhill(&self, p: V2) -> Option<f64> {
        const RING: [(i64, i64); 16] = [
            (2, 0),
            (2, 1),
            (2, 2),
            (1, 2),
            (0, 2),
            (-1, 2),
            (-2, 2),
            (-2, 1),
            (-2, 0),
            (-2, -1),
            (-2, -2),
            (-1, -2),
            (0, -2),
            (1, -2),
            (2, -2),
            (2, -1),
        ];
        let (x, y) = self.spec.cell_of(p)?;
        let here = self.cost[self.spec.index(x, y)];
        if !here.is_finite() {
            return None;
        }
        let mut best: Option<(f32, (i64, i64))> = None;
        for (dx, dy) in RING {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx < 0 || ny < 0 || nx >= self.spec.nx as i64 || ny >= self.spec.ny as i64 {
                continue;
            }
            let c = self.cost[self.spec.index(nx as usize, ny as usize)];
            if c < here && best.is_none_or(|(b, _)| c < b) {
                best = Some((c, (dx, dy)));
            }
        }
        best.map(|(_, (dx, dy))| (dy as f64).atan2(dx as f64))
    }

    /// The cost at a point; `None` where the search did not reach.
    pub fn at(&self, p: V2) -> Option<f64> {
        let (x, y) = self.spec.cell_of(p)?;
        let c = self.cost[self.spec.index(x, y)];
        c.is_finite().then_some(c as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Footprint;
    use crate::map::{MapWall, NavMap};

    /// Two rooms side by side, 10 m × 6 m each, with a wall at x = 10 that has a 1.2 m door at
    /// y 4–5.2.
    fn two_rooms(door: bool) -> NavMap {
        let mut map = NavMap::empty(20.0, 6.0);
        if door {
            map.walls.push(MapWall::rectangle(9.9, 0.0, 10.1, 4.0, false));
            map.walls.push(MapWall::rectangle(9.9, 5.2, 10.1, 6.0, false));
        } else {
            map.walls.push(MapWall::rectangle(9.9, 0.0, 10.1, 6.0, false));
        }
        map
    }

    fn costmap(map: NavMap) -> Costmap {
        Costmap::build(&WorldModel::new(map, Footprint::of_body(1.1, 0.65, 0.8)), 0.35, 0.25)
    }

    #[test]
    fn astar_finds_the_way_through_the_door() {
        let cm = costmap(two_rooms(true));
        let r = route(&cm, V2::new(3.0, 1.0), V2::new(17.0, 1.0), 0.1).expect("a route through the door");
        // It passes the wall at the door's height, and it is not much longer than needed.
        let through = r.points.windows(2).any(|w| {
            let (a, b) = (w[0], w[1]);
            (a.x - 10.0) * (b.x - 10.0) <= 0.0 && {
                let t = (10.0 - a.x) / (b.x - a.x);
                let y = a.y + t * (b.y - a.y);
                (4.3..=4.9).contains(&y)
            }
        });
        assert!(through, "{:?}", r.points);
        let direct = 2.0 * (7.0f64.powi(2) + 3.6f64.powi(2)).sqrt();
        assert!(r.length_m < direct + 0.5, "{} m", r.length_m);
        assert!(r.points.len() <= 6, "smoothed to a few corners: {:?}", r.points);
        for w in r.points.windows(2) {
            assert!(cm.line_free(w[0], w[1]) || w[0] == r.points[0]);
        }
    }

    #[test]
    fn astar_finds_nothing_when_the_goal_is_walled_in() {
        let cm = costmap(two_rooms(false));
        assert_eq!(route(&cm, V2::new(3.0, 1.0), V2::new(17.0, 1.0), 0.1), None);
        let mut boxed = two_rooms(true);
        for (x0, y0, x1, y1) in
            [(15.0, 0.5, 19.0, 0.6), (15.0, 3.4, 19.0, 3.5), (15.0, 0.5, 15.1, 3.5), (18.9, 0.5, 19.0, 3.5)]
        {
            boxed.walls.push(MapWall::rectangle(x0, y0, x1, y1, false));
        }
        let cm = costmap(boxed);
        assert_eq!(route(&cm, V2::new(3.0, 1.0), V2::new(17.0, 2.0), 0.1), None);
        let start = cm.spec.clamp_cell(V2::new(3.0, 1.0));
        let goal = cm.spec.clamp_cell(V2::new(17.0, 2.0));
        assert_eq!(astar(&cm, start, goal), None);
    }

    #[test]
    fn the_cost_to_go_rises_away_from_the_goal_and_around_walls() {
        let cm = costmap(two_rooms(true));
        let goal = cm.spec.clamp_cell(V2::new(17.0, 1.0));
        let seeds = [(cm.spec.index(goal.0, goal.1), 0.0)];
        let ctg = CostToGo::new(&cm, &seeds, None, 0.0, 3.0, &[]);
        let near = ctg.at(V2::new(16.0, 1.0)).expect("reached");
        let far = ctg.at(V2::new(3.0, 1.0)).expect("reached through the door");
        assert!(near < 1.1 && far > 14.0, "{near} {far}");
        // Behind the wall, the way round through the door is what counts.
        let behind = ctg.at(V2::new(9.5, 1.0)).expect("reached");
        assert!(behind > 7.0, "{behind}");
        assert_eq!(ctg.at(V2::new(10.0, 1.0)), None, "inside the wall");
    }

    #[test]
    fn the_bucket_queue_gives_the_costs_a_heap_dijkstra_gives() {
        let cm = costmap(two_rooms(true));
        let spec = cm.spec;
        let goal = spec.clamp_cell(V2::new(17.0, 1.0));
        // Several seeds with uneven starting costs, as a checkpoint's disc gives.
        let seeds: Vec<(usize, f32)> =
            (0..5).map(|k| (spec.index(goal.0 + k, goal.1 + k % 2), 0.013 * (k * k) as f32)).collect();
        let soft = 3.0;
        let ctg = CostToGo::new(&cm, &seeds, None, 0.0, soft, &[]);
        // The reference: the same graph (no narrow cells open, no lanes) with a binary heap.
        let passable = |j: usize| cm.cost[j] != HARD && cm.cost[j] != NARROW;
        let mut cost = vec![f32::INFINITY; spec.len()];
        let mut open = BinaryHeap::new();
        for &(i, c) in &seeds {
            if passable(i) && c < cost[i] {
                cost[i] = c;
                open.push(Open { f: c, i: i as u32 });
            }
        }
        while let Some(Open { f, i }) = open.pop() {
            let i = i as usize;
            if f > cost[i] {
                continue;
            }
            neighbours(&spec, i, passable, |j, step| {
                let w = if cm.blocked(j) { 1.0 + soft } else { 1.0 };
                let c = f + step * spec.cell as f32 * w;
                if c < cost[j] {
                    cost[j] = c;
                    open.push(Open { f: c, i: j as u32 });
                }
            });
        }
        let mut reached = 0;
        for (a, b) in ctg.cost.iter().zip(&cost) {
            assert_eq!(a.is_finite(), b.is_finite());
            if a.is_finite() {
                reached += 1;
                assert!((a - b).abs() <= 1e-4 * b.max(1.0), "{a} against {b}");
            }
        }
        assert!(reached > spec.len() / 2, "most of both rooms is reached: {reached}");
    }
}
