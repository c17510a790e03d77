//! One-lane zones: the doorways and other narrows of the known map, where two chairs cannot
//! pass each other, found from the walls alone so that every navigator on the same map finds
//! the same ones.
//!
//! The *wide* places are where a disc as wide as two chairs side by side (plus a gap) fits:
//! the cells whose distance to the nearest wall is at least [`Zones::wide_radius`]. Each
//! connected wide place (a room, a corridor of two lanes) is a core. A narrow is where the
//! cores' influence meets: every cell the chair's axle may stand on is labelled with the core
//! nearest to it along the free cells, and a cell beside one of another core is on a passage's
//! *boundary* (a doorway's threshold, the middle of a long narrow corridor). A zone is such a
//! boundary with the cells within reach of it: at least [`MOUTH_M`], and as far as the
//! passage is deep (a long narrow corridor is covered to both mouths); and, on each side,
//! the room a chair needs to turn into or out of it: every cell within the chair's reach (its
//! farthest corner from the axle, plus a little) of the wide place's cell nearest to the
//! passage, where a chair coming out pivots. A doorway onto a 2 m corridor thus takes in the
//! corridor's whole width before it (a chair turning out of it sweeps both lanes), and two
//! doorways face to face are one zone, a junction. Zones that touch are one zone.
//!
//! A room corner is no narrow: however close its walls, only one core reaches it.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::geom::V2;
use crate::grid::{GridSpec, StaticRaster};

/// A zone reaches at least this far from its passage's boundary, metres: a doorway's zone
/// takes in the doorway and the turn out of it, not the far lane of a two-lane corridor.
pub const MOUTH_M: f64 = 0.8;
/// A wide place smaller than this many square metres is not a core (a nook between
/// furniture is no place to pass).
const MIN_CORE_M2: f64 = 0.05;
/// Added to the chair's reach round a passage's pivot, metres.
const PIVOT_SLACK_M: f64 = 0.1;

/// One zone.
#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    /// Where its passage is: the mean of its boundary cells, lab coordinates. Peers name a
    /// zone by this point.
    pub centre: V2,
    /// Its cells' bounding box.
    pub lo: V2,
    /// Its cells' bounding box.
    pub hi: V2,
}

/// The zones of a map.
#[derive(Debug, Clone)]
pub struct Zones {
    spec: GridSpec,
    /// Per cell: 0 = in no zone, k = in zone k − 1.
    label: Vec<u16>,
    /// Per cell: the wide place (room or corridor) nearest along the free cells, or
    /// `u32::MAX` where the axle cannot stand. A path that stays on one side of a zone
    /// passes it by; one whose side changes in it goes through its passage.
    side: Vec<u32>,
    zones: Vec<Zone>,
}

/// A cell's neighbours with the step's cost in hundredths of a cell (8-connected).
const STEPS: [(isize, isize, u32); 8] =
    [(1, 0, 100), (-1, 0, 100), (0, 1, 100), (0, -1, 100), (1, 1, 141), (1, -1, 141), (-1, 1, 141), (-1, -1, 141)];

fn neighbours(spec: &GridSpec, i: usize) -> impl Iterator<Item = (usize, u32)> + '_ {
    let (x, y) = spec.coords(i);
    STEPS.iter().filter_map(move |&(dx, dy, c)| {
        let (nx, ny) = (x.checked_add_signed(dx)?, y.checked_add_signed(dy)?);
        (nx < spec.nx && ny < spec.ny).then(|| (spec.index(nx, ny), c))
    })
}

/// On each side of a passage (each core whose cells are nearest its boundary), the core cell
/// nearest to the boundary: found by a search from the boundary over free cells, at most
/// `limit` (hundredths of a cell) plus a little deep.
fn pivots(spec: &GridSpec, boundary: &[usize], core: &[u32], depth: &[u32], limit: u32) -> Vec<usize> {
    let mut seen: std::collections::HashMap<usize, u32> = boundary.iter().map(|&i| (i, 0)).collect();
    let mut heap: BinaryHeap<Reverse<(u32, usize)>> = boundary.iter().map(|&i| Reverse((0, i))).collect();
    let mut found: Vec<(u32, usize)> = Vec::new();
    while let Some(Reverse((d, i))) = heap.pop() {
        if seen.get(&i).is_some_and(|&s| d > s) {
            continue;
        }
        if core[i] != u32::MAX {
            if !found.iter().any(|&(c, _)| c == core[i]) {
                found.push((core[i], i));
            }
            continue;
        }
        for (j, c) in neighbours(spec, i) {
            let nd = d + c;
            // Free cells only (those with a depth), and not beyond the passage's reach.
            if depth[j] == u32::MAX || nd > limit + 200 {
                continue;
            }
            if seen.get(&j).is_none_or(|&s| nd < s) {
                seen.insert(j, nd);
                heap.push(Reverse((nd, j)));
            }
        }
    }
    found.into_iter().map(|(_, i)| i).collect()
}

fn find(parent: &mut [usize], mut k: usize) -> usize {
    while parent[k] != k {
        parent[k] = parent[parent[k]];
        k = parent[k];
    }
    k
}

/// The cores: connected sets of cells wide enough for two chairs to pass (at least
/// `wide_r` from the walls), of at least [`MIN_CORE_M2`]; each cell's core number, or
/// `u32::MAX` for none.
fn cores(spec: &GridSpec, free: &[bool], dist: &[f32], wide_r: f64) -> Vec<u32> {
    let n = spec.len();
    let mut core = vec![u32::MAX; n];
    let mut cores = 0u32;
    let min_cells = (MIN_CORE_M2 / (spec.cell * spec.cell)).ceil() as usize;
    let mut stack = Vec::new();
    let mut members = Vec::new();
    // By flood fill over wide cells.
    for s in 0..n {
        if core[s] != u32::MAX || !free[s] || f64::from(dist[s]) < wide_r {
            continue;
        }
        members.clear();
        core[s] = cores;
        stack.push(s);
        while let Some(i) = stack.pop() {
            members.push(i);
            for (j, _) in neighbours(spec, i) {
                if core[j] == u32::MAX && free[j] && f64::from(dist[j]) >= wide_r {
                    core[j] = cores;
                    stack.push(j);
                }
            }
        }
        if members.len() < min_cells {
            for &i in &members {
                core[i] = u32::MAX - 1; // wide, but too small to count
            }
        } else {
            cores += 1;
        }
    }
    for c in &mut core {
        if *c == u32::MAX - 1 {
            *c = u32::MAX;
        }
    }
    core
}

/// Each free cell's nearest core along the free cells, and how far it is (Dijkstra from every
/// core at once).
fn nearest_cores(spec: &GridSpec, free: &[bool], core: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let n = spec.len();
    let mut owner = core.to_vec();
    let mut depth = vec![u32::MAX; n];
    let mut heap = BinaryHeap::new();
    for i in 0..n {
        if core[i] != u32::MAX {
            depth[i] = 0;
            heap.push(Reverse((0u32, i)));
        }
    }
    while let Some(Reverse((d, i))) = heap.pop() {
        if d > depth[i] {
            continue;
        }
        for (j, c) in neighbours(spec, i) {
            if free[j] && d + c < depth[j] {
                depth[j] = d + c;
                owner[j] = owner[i];
                heap.push(Reverse((d + c, j)));
            }
        }
    }
    (owner, depth)
}

/// Passages: the boundary cells (sorted) that touch, as sets; each cell's passage number
/// (`u32::MAX`: none) and the sets.
fn passages(spec: &GridSpec, boundary: &[usize]) -> (Vec<u32>, Vec<Vec<usize>>) {
    let mut passage = vec![u32::MAX; spec.len()];
    let mut passages: Vec<Vec<usize>> = Vec::new();
    for &s in boundary {
        if passage[s] != u32::MAX {
            continue;
        }
        let k = passages.len() as u32;
        let mut cells = vec![s];
        passage[s] = k;
        let mut at = 0;
        while at < cells.len() {
            let i = cells[at];
            at += 1;
            for (j, _) in neighbours(spec, i) {
                if passage[j] == u32::MAX && boundary.binary_search(&j).is_ok() {
                    passage[j] = k;
                    cells.push(j);
                }
            }
        }
        passages.push(cells);
    }
    (passage, passages)
}

/// Grows each passage by its depth (at least [`MOUTH_M`]) and round its pivots by `pivot_r`;
/// passages whose growth meets are merged. Each cell's passage grown into it (`u32::MAX`:
/// none), and the union-find parents of the passages.
fn grow(
    spec: &GridSpec,
    free: &[bool],
    core: &[u32],
    depth: &[u32],
    passages: &[Vec<usize>],
    pivot_r: f64,
) -> (Vec<u32>, Vec<usize>) {
    let n = spec.len();
    let mut parent: Vec<usize> = (0..passages.len()).collect();
    let mut reach = vec![u32::MAX; n];
    let mut grown = vec![u32::MAX; n];
    let mut heap = BinaryHeap::new();
    let pivot_limit = (pivot_r / spec.cell * 100.0) as u32;
    for (k, cells) in passages.iter().enumerate() {
        let deepest = cells.iter().map(|&i| depth[i]).max().unwrap_or(0);
        let mouth = ((MOUTH_M / spec.cell * 100.0) as u32).max(deepest);
        // Growth runs to `limit`; each seed starts as far short of it as it reaches.
        let limit = mouth.max(pivot_limit);
        heap.clear();
        for &i in cells {
            reach[i] = limit - mouth;
            heap.push(Reverse((limit - mouth, i)));
        }
        // The pivots: on each side, the core cell nearest the passage. Growing from a
        // pivot starts `limit - pivot_limit` short, so it reaches `pivot_r` round it.
        for p in pivots(spec, cells, core, depth, mouth) {
            let start = limit.saturating_sub(pivot_limit);
            if start < reach[p] {
                reach[p] = start;
                heap.push(Reverse((start, p)));
            }
        }
        let mut touched = Vec::new();
        while let Some(Reverse((d, i))) = heap.pop() {
            if d > reach[i] {
                continue;
            }
            touched.push(i);
            if grown[i] != u32::MAX && grown[i] != k as u32 {
                let (a, b) = (find(&mut parent, k), find(&mut parent, grown[i] as usize));
                parent[a] = b;
            }
            grown[i] = k as u32;
            for (j, c) in neighbours(spec, i) {
                if free[j] && d + c <= limit && d + c < reach[j] {
                    reach[j] = d + c;
                    heap.push(Reverse((d + c, j)));
                }
            }
        }
        for i in touched {
            reach[i] = u32::MAX;
        }
    }
    (grown, parent)
}

/// Numbers the merged zones in the order of their first cell (the same on every chair): each
/// cell's label (zone number + 1; 0 for none) and the zones, each centred on the boundary cell
/// nearest its boundary's mean (two merged doorways' mean may lie between them, outside both).
fn number_zones(spec: &GridSpec, passage: &[u32], grown: &[u32], parent: &mut [usize]) -> (Vec<u16>, Vec<Zone>) {
    let n = spec.len();
    let mut number = vec![u16::MAX; parent.len()];
    let mut label = vec![0u16; n];
    let mut zones: Vec<(V2, usize, V2, V2)> = Vec::new();
    for i in 0..n {
        if grown[i] == u32::MAX {
            continue;
        }
        let root = find(parent, grown[i] as usize);
        if number[root] == u16::MAX {
            if zones.len() >= usize::from(u16::MAX - 1) {
                continue;
            }
            number[root] = zones.len() as u16;
            zones.push((
                V2::new(0.0, 0.0),
                0,
                V2::new(f64::INFINITY, f64::INFINITY),
                V2::new(-f64::INFINITY, -f64::INFINITY),
            ));
        }
        let z = number[root];
        label[i] = z + 1;
        let (ix, iy) = spec.coords(i);
        let p = spec.center(ix, iy);
        let e = &mut zones[usize::from(z)];
        e.2 = V2::new(e.2.x.min(p.x), e.2.y.min(p.y));
        e.3 = V2::new(e.3.x.max(p.x), e.3.y.max(p.y));
        if passage[i] != u32::MAX {
            e.0 = e.0 + p;
            e.1 += 1;
        }
    }
    let mut zones: Vec<Zone> = zones
        .into_iter()
        .map(|(sum, count, lo, hi)| Zone { centre: sum * (1.0 / count.max(1) as f64), lo, hi })
        .collect();
    let mut best = vec![(f64::INFINITY, V2::new(0.0, 0.0)); zones.len()];
    for i in 0..n {
        if passage[i] == u32::MAX || label[i] == 0 {
            continue;
        }
        let z = usize::from(label[i] - 1);
        let (ix, iy) = spec.coords(i);
        let p = spec.center(ix, iy);
        let d = (p - zones[z].centre).norm();
        if d < best[z].0 {
            best[z] = (d, p);
        }
    }
    for (z, (d, p)) in zones.iter_mut().zip(best) {
        if d.is_finite() {
            z.centre = p;
        }
    }
    (label, zones)
}

impl Zones {
    /// No zones at all (the zone rule off): every place is in none.
    pub fn none() -> Zones {
        let spec = GridSpec { origin: V2::new(0.0, 0.0), cell: 1.0, nx: 1, ny: 1 };
        Zones { spec, label: Vec::new(), side: Vec::new(), zones: Vec::new() }
    }

    /// Twice a chair's width plus a gap of 0.3 m, halved: the clearance a cell needs for two
    /// chairs `half` wide each side of the axle to pass there.
    pub fn wide_radius(half: f64) -> f64 {
        2.0 * half + 0.15
    }

    /// The zones of `statics` for chairs of footprint `fp` (whose axle stands only where the
    /// walls are at least `fp.half` away).
    pub fn find(statics: &StaticRaster, fp: &crate::geom::Footprint) -> Zones {
        let half = fp.half;
        let spec = statics.spec;
        let dist = statics.distances();
        let n = spec.len();
        let free: Vec<bool> = (0..n).map(|i| !statics.occupied(i) && f64::from(dist[i]) >= half).collect();
        let core = cores(&spec, &free, dist, Self::wide_radius(half));
        let (owner, depth) = nearest_cores(&spec, &free, &core);
        // Boundary cells: free, owned, beside a cell of another core.
        let boundary: Vec<usize> = (0..n)
            .filter(|&i| {
                owner[i] != u32::MAX
                    && core[i] == u32::MAX
                    && neighbours(&spec, i).any(|(j, _)| owner[j] != u32::MAX && owner[j] != owner[i])
            })
            .collect();
        let (passage, passages) = passages(&spec, &boundary);
        let pivot_r = fp.reach() + PIVOT_SLACK_M;
        let (grown, mut parent) = grow(&spec, &free, &core, &depth, &passages, pivot_r);
        let (label, zones) = number_zones(&spec, &passage, &grown, &mut parent);
        Zones { spec, label, side: owner, zones }
    }

    /// The zones.
    pub fn all(&self) -> &[Zone] {
        &self.zones
    }

    /// The zone holding `p`, if any.
    pub fn at(&self, p: V2) -> Option<usize> {
        let (ix, iy) = self.spec.cell_of(p)?;
        let l = *self.label.get(self.spec.index(ix, iy))?;
        (l > 0).then(|| usize::from(l - 1))
    }

    /// The wide place (room or corridor) nearest to `p` along the free cells, by number:
    /// a path whose side changes within a zone goes through the zone's passage, one whose
    /// side stays the same passes it by. `None` off the map or where the axle cannot stand.
    pub fn side(&self, p: V2) -> Option<u32> {
        let (ix, iy) = self.spec.cell_of(p)?;
        self.side.get(self.spec.index(ix, iy)).copied().filter(|&s| s != u32::MAX)
    }

    /// The zone a peer names by its centre: the zone holding that point.
    pub fn named(&self, centre: V2) -> Option<usize> {
        self.at(centre)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{MapWall, NavMap};
    use crate::model::CELL_M;

    /// The Intellwheels chair: 1.1 m long, 0.65 m wide, axle at 0.8 of its length.
    fn fp() -> crate::geom::Footprint {
        crate::Body::INTELLWHEELS.footprint()
    }

    /// Two 6 m × 6 m rooms side by side, joined by a 1 m doorway in a 0.2 m wall.
    fn two_rooms() -> NavMap {
        let mut map = NavMap::empty(12.2, 6.0);
        map.walls.push(MapWall::rectangle(6.0, 0.0, 6.2, 2.5, false));
        map.walls.push(MapWall::rectangle(6.0, 3.5, 6.2, 6.0, false));
        map
    }

    #[test]
    fn a_doorway_between_two_rooms_is_one_zone_and_the_rooms_corners_are_none() {
        let statics = StaticRaster::new(&two_rooms(), CELL_M);
        let zones = Zones::find(&statics, &fp());
        assert_eq!(zones.all().len(), 1, "{:?}", zones.all());
        let z = &zones.all()[0];
        assert!((z.centre.x - 6.1).abs() < 0.3 && (z.centre.y - 3.0).abs() < 0.2, "{z:?}");
        assert_eq!(zones.at(V2::new(6.1, 3.0)), Some(0), "the doorway");
        assert_eq!(zones.at(V2::new(5.5, 3.0)), Some(0), "its mouth");
        assert_eq!(zones.at(V2::new(3.0, 3.0)), None, "the room");
        assert_eq!(zones.at(V2::new(0.5, 0.5)), None, "a corner");
        assert_eq!(zones.at(V2::new(11.6, 5.5)), None, "a corner");
        assert_eq!(zones.named(z.centre), Some(0));
    }

    #[test]
    fn a_long_narrow_corridor_is_one_zone_from_mouth_to_mouth() {
        // Two rooms joined by a corridor 1.2 m wide and 6 m long.
        let mut map = NavMap::empty(18.0, 6.0);
        map.walls.push(MapWall::rectangle(6.0, 0.0, 12.0, 2.4, false));
        map.walls.push(MapWall::rectangle(6.0, 3.6, 12.0, 6.0, false));
        let zones = Zones::find(&StaticRaster::new(&map, CELL_M), &fp());
        assert_eq!(zones.all().len(), 1, "{:?}", zones.all());
        for x in [6.2, 7.0, 9.0, 11.0, 11.8] {
            assert_eq!(zones.at(V2::new(x, 3.0)), Some(0), "x = {x}");
        }
        assert_eq!(zones.at(V2::new(2.0, 3.0)), None);
        assert_eq!(zones.at(V2::new(16.0, 3.0)), None);
    }

    #[test]
    fn a_two_lane_corridor_is_no_zone_but_its_doorways_are() {
        // The ward's plan (builtin:ward) over 10 m: a corridor 2 m wide (y 6–8), two rooms
        // each side, each with a 1 m doorway, opposite doorways face to face.
        let mut map = NavMap::empty(10.0, 14.0);
        for (y0, y1) in [(5.9, 6.0), (8.0, 8.1)] {
            for (x0, x1) in [(0.0, 2.0), (3.0, 7.0), (8.0, 10.0)] {
                map.walls.push(MapWall::rectangle(x0, y0, x1, y1, false));
            }
        }
        map.walls.push(MapWall::rectangle(4.95, 0.0, 5.05, 5.9, false));
        map.walls.push(MapWall::rectangle(4.95, 8.1, 5.05, 14.0, false));
        let zones = Zones::find(&StaticRaster::new(&map, CELL_M), &fp());
        // Doorways face to face are one junction with the corridor's width between them (a
        // chair turning out of either sweeps both lanes); the corridor between junctions is
        // in none.
        assert_eq!(zones.all().len(), 2, "{:?}", zones.all());
        for x in [2.5, 7.5] {
            let z = zones.at(V2::new(x, 5.95)).unwrap_or_else(|| panic!("the doorway at {x}: {:?}", zones.all()));
            for y in [5.5, 6.4, 7.0, 7.6, 8.05, 8.5] {
                assert_eq!(zones.at(V2::new(x, y)), Some(z), "({x}, {y})");
            }
            let zone = &zones.all()[z];
            assert!(zone.hi.x - zone.lo.x < 2.8, "a junction no wider than a turn needs: {zone:?}");
        }
        for y in [6.4, 7.0, 7.6] {
            assert_eq!(zones.at(V2::new(5.0, y)), None, "the corridor between junctions at y {y}");
        }
        // Each wide place is a side: the corridor's two lanes, by a junction and between
        // junctions, are one; each room is another. A path from lane to lane through a
        // junction stays on one side (it passes the doorways by), one into a room does not.
        let corridor = zones.side(V2::new(5.0, 7.0)).expect("the corridor is a side");
        for (x, y) in [(2.5, 6.4), (2.5, 7.6), (7.5, 6.4), (7.5, 7.6), (0.6, 6.4)] {
            assert_eq!(zones.side(V2::new(x, y)), Some(corridor), "({x}, {y}) is in the corridor");
        }
        let rooms = [(1.0, 3.0), (8.0, 3.0), (1.0, 11.0), (8.0, 11.0)].map(|(x, y)| zones.side(V2::new(x, y)));
        for (k, r) in rooms.iter().enumerate() {
            assert!(r.is_some_and(|r| r != corridor), "room {k}: {rooms:?}");
            assert!(rooms[..k].iter().all(|q| q != r), "each room its own side: {rooms:?}");
        }
        assert_eq!(zones.side(V2::new(2.5, 5.5)), rooms[0], "the doorway's room side");
        assert_eq!(zones.side(V2::new(5.0, 5.0)), None, "inside a wall");
    }
}
