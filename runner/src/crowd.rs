//! Many chairs on any map: `[crowd]` in a scenario (or `iwsim run --chairs N`) places N
//! navigator chairs, each with its own goals, seeded by the run's seed.
//!
//! The floor is sampled on a grid: a cell's clearance is its centre's distance to the nearest
//! wall, scenario obstacle or the lab's border (0 inside one). A chair may start or stop where
//! the clearance lets it turn on the spot ([`Crowd::clearance_m`]); it can pass where the
//! clearance is more than half its width (plus half a cell, what the clearance may drop
//! between two cells' centres), so a start and its goals lie in one region connected by such
//! cells (a flood fill): every trip is one a chair fits through, doorways included. Starts
//! are [`Crowd::min_separation_m`] apart, and so are goals (a chair that has arrived stands
//! there), and each goal is at least [`Crowd::min_trip_m`] from where the chair comes from.

use serde::Deserialize;
use sim_model::PoseDeg;
use world::map::Lab;
use world::rng::Rng;

/// What `[crowd]` asks for.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Crowd {
    /// How many chairs (navigators named chair1, chair2, …).
    pub chairs: usize,
    /// Goals per chair, visited in order (a tour); the last is where it stops.
    #[serde(default = "one")]
    pub tour: usize,
    /// Starts, and goals, at least this far apart, metres.
    #[serde(default = "two")]
    pub min_separation_m: f64,
    /// Free floor at least this far round a start or goal, metres: room to turn on the spot
    /// (the Intellwheels chair's corners are 0.94 m from its centre of movement).
    #[serde(default = "turn_room")]
    pub clearance_m: f64,
    /// A goal at least this far (straight line) from the chair's start or previous goal.
    #[serde(default = "trip")]
    pub min_trip_m: f64,
    /// A checkpoint's radius, metres.
    #[serde(default = "half")]
    pub radius_m: f64,
    /// More options for every chair's navigator, as an agent's `options` (e.g.
    /// `{ zone-claims = true }`); the crowd's own (`name`, `pose`, `checkpoint`) are refused.
    #[serde(default)]
    pub options: toml::Table,
}

fn one() -> usize {
    1
}
fn two() -> f64 {
    2.0
}
fn turn_room() -> f64 {
    1.0
}
fn trip() -> f64 {
    6.0
}
fn half() -> f64 {
    0.5
}

impl Crowd {
    /// `n` chairs with every other choice at its default.
    pub fn of(n: usize) -> Self {
        Self {
            chairs: n,
            tour: one(),
            min_separation_m: two(),
            clearance_m: turn_room(),
            min_trip_m: trip(),
            radius_m: half(),
            options: toml::Table::new(),
        }
    }

    /// The most chairs a crowd may have (the hub's agent limit is per process; each chair is
    /// one navigator process).
    pub const MAX_CHAIRS: usize = 100;

    /// Checks the values; says which is wrong.
    pub fn check(&self) -> Result<(), String> {
        if !(1..=Self::MAX_CHAIRS).contains(&self.chairs) {
            return Err(format!("crowd.chairs = {}: from 1 to {}", self.chairs, Self::MAX_CHAIRS));
        }
        if !(1..=20).contains(&self.tour) {
            return Err(format!("crowd.tour = {}: from 1 to 20 goals", self.tour));
        }
        for (key, v, lo, hi) in [
            ("min_separation_m", self.min_separation_m, 0.0, 100.0),
            ("clearance_m", self.clearance_m, 0.5, 10.0),
            ("min_trip_m", self.min_trip_m, 0.0, 1000.0),
            ("radius_m", self.radius_m, 0.05, 5.0),
        ] {
            if !(v >= lo && v <= hi) {
                return Err(format!("crowd.{key} = {v}: from {lo} to {hi}"));
            }
        }
        for key in ["name", "pose", "checkpoint"] {
            if self.options.contains_key(key) {
                return Err(format!("crowd.options.{key}: the crowd places its chairs itself"));
            }
        }
        crate::scenario::option_flags(&self.options).map(|_| ()).map_err(|e| format!("crowd.options: {e}"))
    }
}

/// One chair's place in a crowd.
#[derive(Debug, Clone, PartialEq)]
pub struct Trip {
    /// Start pose: x, y metres, heading degrees.
    pub start: PoseDeg,
    /// Goals in order: x, y metres.
    pub goals: Vec<[f64; 2]>,
}

/// Half the Intellwheels chair's width (0.325 m) and a little: where the clearance is more
/// (plus half a cell), its centre line can pass (a 1 m doorway has 0.5 m in its middle).
const PASS_M: f64 = 0.34;
/// Starts tried per chair, and goals tried per start, before the crowd is given up.
const START_TRIES: usize = 200;
/// Cells drawn per start or goal looked for.
const TRIES: usize = 5_000;
/// The floor is sampled on at most this many cells (a larger lab on coarser ones).
const MAX_CELLS: f64 = 2.0e6;

/// The sampled floor of a lab.
struct Floor {
    cell: f64,
    nx: usize,
    ny: usize,
    /// Clearance per cell, metres.
    clear: Vec<f32>,
    /// Connected region per cell (cells a chair can pass), `u32::MAX` for none.
    region: Vec<u32>,
}

impl Floor {
    /// The floor of `lab` with `boxes` (x0, y0, x1, y1: the scenario's obstacles) on it.
    fn of(lab: &Lab, boxes: &[[f64; 4]]) -> Self {
        let cell = 0.1f64.max((lab.width_m * lab.height_m / MAX_CELLS).sqrt());
        let nx = (lab.width_m / cell).floor().max(1.0) as usize;
        let ny = (lab.height_m / cell).floor().max(1.0) as usize;
        let mut polygons: Vec<Vec<[f64; 2]>> =
            lab.walls.iter().map(|w| w.corners.iter().map(|c| [c.x, c.y]).collect()).collect();
        polygons.extend(boxes.iter().map(|&[x0, y0, x1, y1]| vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]));
        let mut edges: Vec<([f64; 2], [f64; 2])> = Vec::new();
        for poly in &polygons {
            for (i, &a) in poly.iter().enumerate() {
                edges.push((a, poly[(i + 1) % poly.len()]));
            }
        }
        let mut clear = vec![0f32; nx * ny];
        for iy in 0..ny {
            for ix in 0..nx {
                let p = [(ix as f64 + 0.5) * cell, (iy as f64 + 0.5) * cell];
                let border = p[0].min(p[1]).min(lab.width_m - p[0]).min(lab.height_m - p[1]);
                let c = if polygons.iter().any(|poly| sim_model::point_in_polygon(p, poly)) {
                    0.0
                } else {
                    edges.iter().map(|&(a, b)| sim_model::point_segment_distance(p, a, b)).fold(border, f64::min)
                };
                clear[iy * nx + ix] = c as f32;
            }
        }
        let mut region = vec![u32::MAX; nx * ny];
        let mut next = 0u32;
        let mut stack = Vec::new();
        let pass = PASS_M + cell / 2.0;
        for first in 0..nx * ny {
            if region[first] != u32::MAX || f64::from(clear[first]) <= pass {
                continue;
            }
            region[first] = next;
            stack.push(first);
            while let Some(i) = stack.pop() {
                let (ix, iy) = (i % nx, i / nx);
                let around = [
                    (ix > 0).then(|| i - 1),
                    (ix + 1 < nx).then_some(i + 1),
                    (iy > 0).then(|| i - nx),
                    (iy + 1 < ny).then_some(i + nx),
                ];
                for j in around.into_iter().flatten() {
                    if region[j] == u32::MAX && f64::from(clear[j]) > pass {
                        region[j] = next;
                        stack.push(j);
                    }
                }
            }
            next += 1;
        }
        Self { cell, nx, ny, clear, region }
    }

    fn centre(&self, i: usize) -> [f64; 2] {
        [((i % self.nx) as f64 + 0.5) * self.cell, ((i / self.nx) as f64 + 0.5) * self.cell]
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Places `crowd` on `lab`, with the scenario's obstacles `boxes` (x0, y0, x1, y1) on the
/// floor and the robots already at `taken` kept clear of; the same for the same seed.
///
/// # Errors
/// When the lab has no room for that many chairs and goals as asked (saying how many fit).
pub fn place(lab: &Lab, boxes: &[[f64; 4]], taken: &[[f64; 2]], crowd: &Crowd, seed: u64) -> Result<Vec<Trip>, String> {
    crowd.check()?;
    let floor = Floor::of(lab, boxes);
    let spots: Vec<usize> = (0..floor.nx * floor.ny)
        .filter(|&i| f64::from(floor.clear[i]) >= crowd.clearance_m && floor.region[i] != u32::MAX)
        .collect();
    if spots.is_empty() {
        return Err(format!(
            "no floor of lab {:?} has {} m clear round it for a chair to turn",
            lab.name, crowd.clearance_m
        ));
    }
    // A stream of its own, apart from the world's noise streams for the same seed.
    let mut rng = Rng::seed_from_u64(seed ^ 0x6372_6f77_645f_7631);
    let pick = |rng: &mut Rng| spots[(rng.next_u64() % spots.len() as u64) as usize];
    let mut trips: Vec<Trip> = Vec::with_capacity(crowd.chairs);
    let mut starts: Vec<[f64; 2]> = taken.to_vec();
    let mut stops: Vec<[f64; 2]> = Vec::new();
    let apart = |p: [f64; 2], from: &[[f64; 2]]| from.iter().all(|&q| dist(p, q) >= crowd.min_separation_m);
    for n in 0..crowd.chairs {
        let mut placed = None;
        for _ in 0..START_TRIES {
            let Some(start) = (0..TRIES)
                .map(|_| pick(&mut rng))
                .find(|&i| apart(floor.centre(i), &starts) && apart(floor.centre(i), &stops))
            else {
                break;
            };
            let region = floor.region[start];
            let s = floor.centre(start);
            let mut goals = Vec::with_capacity(crowd.tour);
            let mut from = s;
            for _ in 0..crowd.tour {
                let found = (0..TRIES).map(|_| pick(&mut rng)).find(|&i| {
                    let p = floor.centre(i);
                    floor.region[i] == region
                        && dist(p, from) >= crowd.min_trip_m
                        && apart(p, &starts)
                        && apart(p, &stops)
                        && dist(p, s) >= crowd.min_separation_m
                });
                let Some(g) = found else { break };
                from = floor.centre(g);
                goals.push(from);
            }
            if goals.len() == crowd.tour {
                placed = Some((s, goals));
                break;
            }
        }
        let Some((s, goals)) = placed else {
            return Err(format!(
                "lab {:?} has room for {n} chair(s) of {} with their goals (min_separation_m {}, clearance_m {}, min_trip_m {})",
                lab.name, crowd.chairs, crowd.min_separation_m, crowd.clearance_m, crowd.min_trip_m
            ));
        };
        starts.push(s);
        // Only the last goal is where it stands for good; earlier ones are passed.
        stops.extend(goals.last().copied());
        let heading = (rng.next_u64() % 8) as f64 * 45.0 - 180.0;
        trips.push(Trip { start: [s[0], s[1], heading], goals });
    }
    Ok(trips)
}

#[cfg(test)]
mod tests {
    use super::*;
    use world::map::builtin;

    #[test]
    fn a_crowd_on_the_ward_is_seeded_separated_and_reachable() {
        let lab = builtin::map("ward").expect("built in").lab;
        let crowd = Crowd { tour: 2, ..Crowd::of(20) };
        let a = place(&lab, &[], &[], &crowd, 7).expect("twenty chairs fit the ward");
        assert_eq!(a, place(&lab, &[], &[], &crowd, 7).expect("again"), "the same seed, the same crowd");
        assert_ne!(a, place(&lab, &[], &[], &crowd, 8).expect("another"), "another seed, another crowd");
        let floor = Floor::of(&lab, &[]);
        let at = |p: [f64; 2]| (p[1] / floor.cell) as usize * floor.nx + (p[0] / floor.cell) as usize;
        for (k, t) in a.iter().enumerate() {
            let s = [t.start[0], t.start[1]];
            assert!(f64::from(floor.clear[at(s)]) >= 1.0);
            let mut from = s;
            for &g in &t.goals {
                assert_eq!(floor.region[at(g)], floor.region[at(s)], "chair {k}: goal {g:?} reachable");
                assert!(dist(g, from) >= 6.0 && f64::from(floor.clear[at(g)]) >= 1.0);
                from = g;
            }
            for u in &a[k + 1..] {
                assert!(dist(s, [u.start[0], u.start[1]]) >= 2.0, "starts apart");
                let stop = |t: &Trip| *t.goals.last().expect("a goal");
                assert!(dist(stop(t), stop(u)) >= 2.0, "stops apart");
            }
        }
        // The ward's rooms and corridor are one region: its doorways let a chair through.
        let regions: std::collections::BTreeSet<u32> =
            floor.region.iter().copied().filter(|&r| r != u32::MAX).collect();
        assert_eq!(regions.len(), 1, "{regions:?}");
    }

    #[test]
    fn a_crowd_too_large_for_the_lab_is_refused_saying_how_many_fit() {
        let lab = builtin::map("thesis").expect("built in").lab;
        let crowd = Crowd { min_separation_m: 6.0, ..Crowd::of(30) };
        let err = place(&lab, &[], &[], &crowd, 1).expect_err("thirty chairs 6 m apart do not fit 28 m x 14 m");
        assert!(err.contains("has room for") && err.contains("of 30"), "{err}");
        let err = place(&lab, &[], &[], &Crowd::of(0), 1).expect_err("no chairs");
        assert!(err.contains("crowd.chairs = 0"), "{err}");
    }

    #[test]
    fn obstacles_and_robots_already_there_are_kept_clear_of() {
        let lab = builtin::map("ward").expect("built in").lab;
        // A box filling the west half of the corridor, and a robot in every south room.
        let boxes = [[0.0, 6.0, 20.0, 8.0]];
        let taken: Vec<[f64; 2]> = (0..8).map(|k| [k as f64 * 5.0 + 2.5, 3.0]).collect();
        let trips = place(&lab, &boxes, &taken, &Crowd::of(8), 3).expect("the north rooms and the corridor's east");
        for t in &trips {
            for p in std::iter::once([t.start[0], t.start[1]]).chain(t.goals.iter().copied()) {
                assert!(!(p[0] < 21.0 && (5.0..=9.0).contains(&p[1])), "{p:?} on or beside the box");
                assert!(taken.iter().all(|&q| dist(p, q) >= 2.0), "{p:?} near a robot already there");
            }
        }
    }
}
