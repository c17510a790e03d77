//! Spatial indexes: a static uniform grid over the walls (edges for sensors and lines of sight,
//! triangles for collisions) and a loose uniform grid over the robots, rebuilt every tick.
//!
//! Why grids and not a BVH: robots are of one size class and spread fairly evenly, walls are
//! few and long, and the dynamic grid rebuilds in O(n) with a counting sort and no allocation,
//! which keeps a 10,000-robot tick linear in the robot count.

use nalgebra::{Point2, Vector2};

use crate::map::Lab;
use crate::math::{Real, cross};

/// Thickness of the wall the world puts around the lab's rectangle.
pub(crate) const BORDER_THICKNESS_M: Real = 1.0;

/// A uniform grid's extent and resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GridSpec {
    pub min: Point2<Real>,
    pub cell: Real,
    pub inv_cell: Real,
    pub nx: usize,
    pub ny: usize,
}

/// Most cells the wall index may have (its two start arrays take 4 bytes a cell each).
pub(crate) const MAX_WALL_CELLS: u64 = 1 << 20;
/// Most (cell, item) entries the wall index may hold: cells plus every edge and triangle
/// counted once per cell of its bounding box (8 bytes each while building).
pub(crate) const MAX_WALL_ENTRIES: u64 = 1 << 22;

impl GridSpec {
    /// How many entries an index over this grid would hold for these items, counting the cells
    /// themselves; `None` when the cells alone exceed [`MAX_WALL_CELLS`] or the count overflows.
    fn entries(&self, edges: &[Edge], triangles: &[WallTriangle]) -> Option<u64> {
        let cells = u64::try_from(self.nx).ok()?.checked_mul(u64::try_from(self.ny).ok()?)?;
        if cells > MAX_WALL_CELLS {
            return None;
        }
        let mut boxes = edges
            .iter()
            .map(|e| {
                let (a, b) = (e.seg.a, e.seg.b());
                (Point2::new(a.x.min(b.x), a.y.min(b.y)), Point2::new(a.x.max(b.x), a.y.max(b.y)))
            })
            .chain(triangles.iter().map(|t| (t.min, t.max)));
        boxes.try_fold(cells, |total, (lo, hi)| {
            let (x0, y0, x1, y1) = self.cell_range(lo, hi);
            let n = u64::try_from((x1 - x0 + 1).checked_mul(y1 - y0 + 1)?).ok()?;
            total.checked_add(n)
        })
    }

    pub(crate) fn covering(min: Point2<Real>, max: Point2<Real>, cell: Real) -> Self {
        let nx = (((max.x - min.x) / cell).ceil() as usize).max(1);
        let ny = (((max.y - min.y) / cell).ceil() as usize).max(1);
        Self { min, cell, inv_cell: 1.0 / cell, nx, ny }
    }

    // Truncation is floor for the non-negative values that reach it, and avoids a libm call
    // on the baseline x86-64 target. NaN maps to cell 0.
    #[inline]
    fn clamp_ix(&self, x: Real) -> usize {
        let i = (x - self.min.x) * self.inv_cell;
        if i > 0.0 { (i as usize).min(self.nx - 1) } else { 0 }
    }

    #[inline]
    fn clamp_iy(&self, y: Real) -> usize {
        let i = (y - self.min.y) * self.inv_cell;
        if i > 0.0 { (i as usize).min(self.ny - 1) } else { 0 }
    }

    /// The cell holding a point; points outside the grid go to the nearest edge cell, so
    /// inserting and querying agree for anything that strays off the map.
    #[inline]
    pub(crate) fn cell_of(&self, p: Point2<Real>) -> usize {
        self.clamp_iy(p.y) * self.nx + self.clamp_ix(p.x)
    }

    /// Inclusive cell ranges (x0, y0, x1, y1) overlapping an axis-aligned box.
    #[inline]
    pub(crate) fn cell_range(&self, min: Point2<Real>, max: Point2<Real>) -> (usize, usize, usize, usize) {
        (self.clamp_ix(min.x), self.clamp_iy(min.y), self.clamp_ix(max.x), self.clamp_iy(max.y))
    }
}

/// A segment with what the sensor loops need precomputed: its direction `d = b − a`, `1/|d|²`,
/// and its outward normal (the solid is on the left of a→b, polygons being counter-clockwise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Segment {
    pub a: Point2<Real>,
    pub d: Vector2<Real>,
    pub normal: Vector2<Real>,
    pub inv_len2: Real,
}

impl Segment {
    /// The segment a→b of a counter-clockwise outline; `None` when a = b.
    #[inline]
    pub(crate) fn new(a: Point2<Real>, b: Point2<Real>) -> Option<Self> {
        let d = b - a;
        let len2 = d.norm_squared();
        (len2 > 0.0).then(|| {
            let inv_len = 1.0 / len2.sqrt();
            Segment { a, d, normal: Vector2::new(d.y * inv_len, -d.x * inv_len), inv_len2: 1.0 / len2 }
        })
    }

    /// The segment a→b with a known unit outward normal.
    #[inline]
    pub(crate) fn with_normal(a: Point2<Real>, b: Point2<Real>, normal: Vector2<Real>, inv_len2: Real) -> Self {
        Segment { a, d: b - a, normal, inv_len2 }
    }

    /// The end point.
    #[inline]
    pub(crate) fn b(&self) -> Point2<Real> {
        self.a + self.d
    }
}

/// A wall edge and the height of its wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Edge {
    pub seg: Segment,
    pub height: Real,
}

/// A triangle of a wall's triangulation, with its bounding box for the broad phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WallTriangle {
    pub p: [Point2<Real>; 3],
    pub min: Point2<Real>,
    pub max: Point2<Real>,
}

/// Compressed lists of item indices per cell.
#[derive(Debug, Clone, Default)]
struct CellLists<T> {
    start: Vec<u32>,
    items: Vec<T>,
}

impl<T: Copy + Ord> CellLists<T> {
    /// Lists from (cell, item) pairs; within a cell, items in their order.
    fn build(n_cells: usize, pairs: &mut [(u32, T)]) -> Self {
        pairs.sort_unstable();
        let mut start = vec![0u32; n_cells + 1];
        for &(cell, _) in pairs.iter() {
            start[cell as usize + 1] += 1;
        }
        for i in 0..n_cells {
            start[i + 1] += start[i];
        }
        Self { start, items: pairs.iter().map(|&(_, item)| item).collect() }
    }

    #[inline]
    fn cell(&self, cell: usize) -> &[T] {
        &self.items[self.start[cell] as usize..self.start[cell + 1] as usize]
    }
}

/// An edge's entry in a cell's list: its index, and whether this cell is in the first column
/// and the first row of the cells the edge is listed in. A query over a box of cells takes
/// an edge only in the first of its cells inside the box, and these two bits decide that from
/// the list alone, without loading the edge (at 10,000 chairs that load missed the cache
/// often enough to be a tenth of sensing).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct EdgeEntry(u32);

// Entries sort by edge index, so a cell lists its edges in the order they were built.
impl Ord for EdgeEntry {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (self.0 & EDGE_INDEX_MASK).cmp(&(other.0 & EDGE_INDEX_MASK)).then(self.0.cmp(&other.0))
    }
}

impl PartialOrd for EdgeEntry {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// The entry bits that hold the edge index ([`MAX_WALL_ENTRIES`] bounds the edges far below).
const EDGE_INDEX_MASK: u32 = (1 << 30) - 1;
const EDGE_FIRST_COL: u32 = 1 << 31;
const EDGE_FIRST_ROW: u32 = 1 << 30;
const _: () = assert!(MAX_WALL_ENTRIES <= EDGE_INDEX_MASK as u64);

impl EdgeEntry {
    fn new(index: usize, first_col: bool, first_row: bool) -> Self {
        debug_assert!(index as u64 <= EDGE_INDEX_MASK as u64);
        let flag = |f: bool, bit: u32| if f { bit } else { 0 };
        Self(index as u32 | flag(first_col, EDGE_FIRST_COL) | flag(first_row, EDGE_FIRST_ROW))
    }

    /// The edge's index in [`StaticIndex::edges`].
    #[inline]
    pub(crate) fn index(self) -> usize {
        (self.0 & EDGE_INDEX_MASK) as usize
    }

    /// Whether a query over cells `x0..`, `y0..` takes this entry, listed in cell (`ix`, `iy`):
    /// when that cell is the first of the edge's cells inside the query, so each edge is
    /// taken once.
    #[inline]
    pub(crate) fn first_in(self, ix: usize, iy: usize, x0: usize, y0: usize) -> bool {
        (ix == x0 || self.0 & EDGE_FIRST_COL != 0) && (iy == y0 || self.0 & EDGE_FIRST_ROW != 0)
    }
}

/// Why a lab could not be turned into a world.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StaticBuildError {
    /// A wall is not a simple polygon with area (ear clipping found no ear).
    #[error("wall {wall} is not a simple polygon with a non-zero area")]
    DegenerateWall {
        /// Index of the wall in the lab.
        wall: usize,
    },
    /// The lab's size is not a positive finite number of at most [`crate::MAX_LAB_SIZE_M`].
    #[error("lab size {width} × {height} is out of range: expected sides greater than 0 and at most 10000 m")]
    BadLabSize {
        /// Width given.
        width: Real,
        /// Height given.
        height: Real,
    },
}

/// A line on the floor: a wall of height 0, as Ciber-Rato's line labs draw their paths. Robots
/// drive over it and proximity sensors do not see it; the line sensor does.
#[derive(Debug, Clone)]
pub(crate) struct FloorLine {
    corners: Vec<Point2<Real>>,
    min: Point2<Real>,
    max: Point2<Real>,
}

impl FloorLine {
    /// Whether `p` lies on the line, by the crossing rule (a point on a lower edge is on it, one
    /// on an upper edge is not, as Ciber-Rato's line sensor reads it).
    fn contains(&self, p: Point2<Real>) -> bool {
        if p.x < self.min.x || p.x > self.max.x || p.y < self.min.y || p.y > self.max.y {
            return false;
        }
        let n = self.corners.len();
        let mut inside = false;
        for i in 0..n {
            let (a, b) = (self.corners[i], self.corners[(i + 1) % n]);
            if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y) {
                inside = !inside;
            }
        }
        inside
    }
}

/// The walls of a lab (its border included), indexed for the queries a tick makes.
#[derive(Debug, Clone)]
pub(crate) struct StaticIndex {
    pub spec: GridSpec,
    /// The lab's walls of height 0: lines on the floor, not walls.
    pub lines: Vec<FloorLine>,
    pub edges: Vec<Edge>,
    pub triangles: Vec<WallTriangle>,
    edge_cells: CellLists<EdgeEntry>,
    tri_cells: CellLists<u32>,
}

impl StaticIndex {
    pub(crate) fn build(lab: &Lab, cell: Real) -> Result<Self, StaticBuildError> {
        let (w, h) = (lab.width_m, lab.height_m);
        let side_ok = |v: Real| v.is_finite() && v > 0.0 && v <= crate::MAX_LAB_SIZE_M;
        if !(side_ok(w) && side_ok(h)) {
            return Err(StaticBuildError::BadLabSize { width: w, height: h });
        }
        let t = BORDER_THICKNESS_M;
        let rect = |x0: Real, y0: Real, x1: Real, y1: Real| {
            vec![Point2::new(x0, y0), Point2::new(x1, y0), Point2::new(x1, y1), Point2::new(x0, y1)]
        };
        // The border: four slabs just outside the rectangle, as high as anything can be.
        let mut polygons: Vec<(Vec<Point2<Real>>, Real, Option<usize>)> = vec![
            (rect(-t, -t, w + t, 0.0), Real::INFINITY, None),
            (rect(-t, h, w + t, h + t), Real::INFINITY, None),
            (rect(-t, 0.0, 0.0, h), Real::INFINITY, None),
            (rect(w, 0.0, w + t, h), Real::INFINITY, None),
        ];
        let mut lines = Vec::new();
        for (i, wall) in lab.walls.iter().enumerate() {
            let mut corners = wall.corners.clone();
            if signed_area(&corners) < 0.0 {
                corners.reverse();
            }
            if wall.height_m <= 0.0 {
                let min = corners.iter().fold(corners[0], |m, c| Point2::new(m.x.min(c.x), m.y.min(c.y)));
                let max = corners.iter().fold(corners[0], |m, c| Point2::new(m.x.max(c.x), m.y.max(c.y)));
                lines.push(FloorLine { corners, min, max });
                continue;
            }
            polygons.push((corners, wall.height_m, Some(i)));
        }

        let mut edges = Vec::new();
        let mut triangles = Vec::new();
        for (poly, height, wall) in &polygons {
            let tris = triangulate(poly).ok_or(StaticBuildError::DegenerateWall { wall: wall.unwrap_or(0) })?;
            for [i, j, k] in tris {
                let p = [poly[i], poly[j], poly[k]];
                let min = Point2::new(p[0].x.min(p[1].x).min(p[2].x), p[0].y.min(p[1].y).min(p[2].y));
                let max = Point2::new(p[0].x.max(p[1].x).max(p[2].x), p[0].y.max(p[1].y).max(p[2].y));
                triangles.push(WallTriangle { p, min, max });
            }
            for i in 0..poly.len() {
                if let Some(seg) = Segment::new(poly[i], poly[(i + 1) % poly.len()]) {
                    edges.push(Edge { seg, height: *height });
                }
            }
        }

        let spec = Self::spec_within_budget(Point2::new(-t, -t), Point2::new(w + t, h + t), cell, &edges, &triangles);
        let n_cells = spec.nx * spec.ny;
        let mut pairs = Vec::new();
        // Edges are listed in every cell of their bounding box (not only the cells they cross),
        // so that the first cell of any query box that holds an edge lists it.
        for (i, e) in edges.iter().enumerate() {
            let (a, b) = (e.seg.a, e.seg.b());
            let (x0, y0, x1, y1) =
                spec.cell_range(Point2::new(a.x.min(b.x), a.y.min(b.y)), Point2::new(a.x.max(b.x), a.y.max(b.y)));
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    pairs.push(((iy * spec.nx + ix) as u32, EdgeEntry::new(i, ix == x0, iy == y0)));
                }
            }
        }
        let edge_cells = CellLists::build(n_cells, &mut pairs);
        let mut pairs = Vec::new();
        for (i, tri) in triangles.iter().enumerate() {
            let (x0, y0, x1, y1) = spec.cell_range(tri.min, tri.max);
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    pairs.push(((iy * spec.nx + ix) as u32, i as u32));
                }
            }
        }
        let tri_cells = CellLists::build(n_cells, &mut pairs);
        Ok(Self { spec, lines, edges, triangles, edge_cells, tri_cells })
    }

    /// Whether `p` lies on a line on the floor.
    pub(crate) fn on_line(&self, p: Point2<Real>) -> bool {
        self.lines.iter().any(|l| l.contains(p))
    }

    /// The grid over [min, max] with the smallest cell, from `cell` doubling, whose cell count
    /// and (cell, item) entries stay within [`MAX_WALL_CELLS`] and [`MAX_WALL_ENTRIES`].
    ///
    /// The index is sized by what the walls need rather than by the lab's area alone: a huge
    /// lab, or walls whose bounding boxes span many cells, get coarser cells instead of an
    /// allocation the machine cannot make. Once a cell covers the whole lab every item sits in
    /// at most 4 cells, so the loop always ends within budget for any lab a file can hold.
    fn spec_within_budget(
        min: Point2<Real>,
        max: Point2<Real>,
        cell: Real,
        edges: &[Edge],
        triangles: &[WallTriangle],
    ) -> GridSpec {
        let extent = (max.x - min.x).max(max.y - min.y);
        let mut spec = GridSpec::covering(min, max, cell);
        // 64 doublings take any cell past any finite extent.
        for _ in 0..64 {
            if spec.cell >= extent || spec.entries(edges, triangles).is_some_and(|n| n <= MAX_WALL_ENTRIES) {
                break;
            }
            spec = GridSpec::covering(min, max, spec.cell * 2.0);
        }
        spec
    }

    /// How many (cell, edge) entries the index holds.
    #[cfg(test)]
    pub(crate) fn edges_in_all(&self) -> usize {
        self.edge_cells.items.len()
    }

    /// How many (cell, triangle) entries the index holds.
    #[cfg(test)]
    pub(crate) fn triangles_in_all(&self) -> usize {
        self.tri_cells.items.len()
    }

    /// Edges listed in one cell.
    #[inline]
    pub(crate) fn edges_in(&self, cell: usize) -> &[EdgeEntry] {
        self.edge_cells.cell(cell)
    }

    /// Triangle indices listed in one cell.
    #[inline]
    pub(crate) fn triangles_in(&self, cell: usize) -> &[u32] {
        self.tri_cells.cell(cell)
    }

    /// Whether the segment a→b properly crosses a wall edge higher than `min_height`
    /// (walks the cells along the segment).
    pub(crate) fn segment_blocked(&self, a: Point2<Real>, b: Point2<Real>, min_height: Real) -> bool {
        let mut blocked = false;
        self.walk_cells(a, b, |cell| {
            for &e in self.edges_in(cell) {
                let edge = &self.edges[e.index()];
                if edge.height > min_height && segments_cross(a, b, edge.seg.a, edge.seg.b()) {
                    blocked = true;
                    return false;
                }
            }
            true
        });
        blocked
    }

    /// Visits the cells a segment passes through, in order, until `f` returns false
    /// (Amanatides & Woo's grid traversal).
    fn walk_cells(&self, a: Point2<Real>, b: Point2<Real>, mut f: impl FnMut(usize) -> bool) {
        let s = &self.spec;
        let to_cell = |p: Point2<Real>| ((p.x - s.min.x) * s.inv_cell, (p.y - s.min.y) * s.inv_cell);
        let (ax, ay) = to_cell(a);
        let (bx, by) = to_cell(b);
        let clamp = |v: Real, n: usize| (v.floor().max(0.0) as usize).min(n - 1);
        let (mut ix, mut iy) = (clamp(ax, s.nx), clamp(ay, s.ny));
        let (ex, ey) = (clamp(bx, s.nx), clamp(by, s.ny));
        let (dx, dy) = (bx - ax, by - ay);
        let step_x: isize = if dx > 0.0 { 1 } else { -1 };
        let step_y: isize = if dy > 0.0 { 1 } else { -1 };
        let t_delta_x = if dx != 0.0 { 1.0 / dx.abs() } else { Real::INFINITY };
        let t_delta_y = if dy != 0.0 { 1.0 / dy.abs() } else { Real::INFINITY };
        let next_boundary = |v: Real, i: usize, d: Real| if d > 0.0 { i as Real + 1.0 - v } else { v - i as Real };
        let mut t_max_x = if dx != 0.0 { next_boundary(ax, ix, dx).max(0.0) * t_delta_x } else { Real::INFINITY };
        let mut t_max_y = if dy != 0.0 { next_boundary(ay, iy, dy).max(0.0) * t_delta_y } else { Real::INFINITY };
        // Bounded: a segment crosses at most nx + ny cells.
        for _ in 0..(s.nx + s.ny + 2) {
            if !f(iy * s.nx + ix) || (ix == ex && iy == ey) {
                return;
            }
            if t_max_x < t_max_y {
                let n = ix as isize + step_x;
                if n < 0 || n as usize >= s.nx {
                    return;
                }
                ix = n as usize;
                t_max_x += t_delta_x;
            } else {
                let n = iy as isize + step_y;
                if n < 0 || n as usize >= s.ny {
                    return;
                }
                iy = n as usize;
                t_max_y += t_delta_y;
            }
        }
    }
}

/// Twice the signed area of a polygon (positive when counter-clockwise).
pub(crate) fn signed_area(poly: &[Point2<Real>]) -> Real {
    let n = poly.len();
    (0..n).map(|i| cross(poly[i].coords, poly[(i + 1) % n].coords)).sum()
}

/// Ear-clipping triangulation of a simple counter-clockwise polygon; `None` when it is
/// degenerate (no area) or not simple enough to clip.
pub(crate) fn triangulate(poly: &[Point2<Real>]) -> Option<Vec<[usize; 3]>> {
    if poly.len() < 3 || signed_area(poly) <= 0.0 {
        return None;
    }
    let mut idx: Vec<usize> = (0..poly.len()).collect();
    let mut out = Vec::with_capacity(poly.len() - 2);
    while idx.len() > 3 {
        let n = idx.len();
        let mut clipped = false;
        for i in 0..n {
            let (ip, ic, inx) = (idx[(i + n - 1) % n], idx[i], idx[(i + 1) % n]);
            let (a, b, c) = (poly[ip], poly[ic], poly[inx]);
            if cross(b - a, c - b) <= 0.0 {
                continue; // reflex or collinear: not an ear
            }
            let blocked = idx.iter().any(|&j| j != ip && j != ic && j != inx && point_in_triangle(poly[j], a, b, c));
            if !blocked {
                out.push([ip, ic, inx]);
                idx.remove(i);
                clipped = true;
                break;
            }
        }
        if !clipped {
            // Only collinear vertices left, or the polygon crosses itself.
            let before = idx.len();
            idx.retain({
                let snapshot = idx.clone();
                let m = snapshot.len();
                let mut k = 0;
                move |&v| {
                    let p = snapshot[(k + m - 1) % m];
                    let q = snapshot[(k + 1) % m];
                    k += 1;
                    cross(poly[v] - poly[p], poly[q] - poly[v]) != 0.0
                }
            });
            if idx.len() == before || idx.len() < 3 {
                return None;
            }
        }
    }
    let (a, b, c) = (poly[idx[0]], poly[idx[1]], poly[idx[2]]);
    if cross(b - a, c - b) > 0.0 {
        out.push([idx[0], idx[1], idx[2]]);
    }
    if out.is_empty() { None } else { Some(out) }
}

fn point_in_triangle(p: Point2<Real>, a: Point2<Real>, b: Point2<Real>, c: Point2<Real>) -> bool {
    cross(b - a, p - a) >= 0.0 && cross(c - b, p - b) >= 0.0 && cross(a - c, p - c) >= 0.0
}

/// Whether segments p1p2 and q1q2 cross or touch.
pub(crate) fn segments_cross(p1: Point2<Real>, p2: Point2<Real>, q1: Point2<Real>, q2: Point2<Real>) -> bool {
    let d1 = cross(q2 - q1, p1 - q1);
    let d2 = cross(q2 - q1, p2 - q1);
    let d3 = cross(p2 - p1, q1 - p1);
    let d4 = cross(p2 - p1, q2 - p1);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return true;
    }
    let on = |a: Point2<Real>, b: Point2<Real>, p: Point2<Real>, d: Real| {
        d == 0.0 && p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
    };
    on(q1, q2, p1, d1) || on(q1, q2, p2, d2) || on(p1, p2, q1, d3) || on(p1, p2, q2, d4)
}

/// A loose grid over moving bodies: each body is listed once, in the cell of its centre, and
/// queries widen their box by the largest body half-extent seen in this build.
///
/// Two layouts, chosen at each rebuild: dense (a start index per cell, O(cells) to build) when
/// bodies are many for the map, and sorted (bodies ordered by cell, found by binary search per
/// row, O(n log n)) when a large map holds few bodies, so 100 robots on a 400 m lab do not pay
/// for 40,000 cells every tick.
#[derive(Debug, Clone)]
pub(crate) struct DynGrid {
    pub spec: GridSpec,
    dense: bool,
    start: Vec<u32>,
    fill: Vec<u32>,
    items: Vec<u32>,
    /// Sorted layout: (cell, item) pairs ordered by cell, then by insertion.
    keyed: Vec<(u32, u32)>,
    /// Sorted layout: where each row's pairs start in `keyed` (one more than rows).
    row_start: Vec<u32>,
    cell_of_item: Vec<u32>,
    max_half: Real,
}

impl DynGrid {
    pub(crate) fn new(spec: GridSpec) -> Self {
        Self {
            spec,
            dense: false,
            start: Vec::new(),
            fill: Vec::new(),
            items: Vec::new(),
            keyed: Vec::new(),
            row_start: Vec::new(),
            cell_of_item: Vec::new(),
            max_half: 0.0,
        }
    }

    /// Rebuilds from (item, centre, half-extent) triples; no allocation once warm.
    pub(crate) fn rebuild(&mut self, entries: impl Iterator<Item = (u32, Point2<Real>, Real)> + Clone) {
        self.rebuild_as(entries, None);
    }

    /// [`Self::rebuild`] in the layout `dense` names, or (`None`) the one that suits the count:
    /// cell starts for every cell while the bodies are at least one per 16 cells, else rows.
    fn rebuild_as(&mut self, entries: impl Iterator<Item = (u32, Point2<Real>, Real)> + Clone, dense: Option<bool>) {
        let n_cells = self.spec.nx * self.spec.ny;
        self.cell_of_item.clear();
        self.max_half = 0.0;
        for (_, centre, half) in entries.clone() {
            self.cell_of_item.push(self.spec.cell_of(centre) as u32);
            self.max_half = self.max_half.max(half);
        }
        let count = self.cell_of_item.len();
        self.dense = dense.unwrap_or(n_cells <= 16 * count.max(1));
        if self.dense {
            self.start.clear();
            self.start.resize(n_cells + 1, 0);
            for &c in &self.cell_of_item {
                self.start[c as usize + 1] += 1;
            }
            for i in 0..n_cells {
                self.start[i + 1] += self.start[i];
            }
            self.items.clear();
            self.items.resize(count, 0);
            // Each cell keeps its items in insertion order (deterministic).
            self.fill.clear();
            self.fill.extend_from_slice(&self.start);
            for (k, (item, _, _)) in entries.enumerate() {
                let cell = self.cell_of_item[k] as usize;
                self.items[self.fill[cell] as usize] = item;
                self.fill[cell] += 1;
            }
        } else {
            // Bucketed by row with a counting sort, then each row sorted by cell: a query
            // looks a row up directly and searches only that row's few entries, where one
            // search of the whole list missed the cache at every step. Both sorts are stable,
            // so equal cells keep insertion order.
            let (nx, ny) = (self.spec.nx, self.spec.ny);
            self.row_start.clear();
            self.row_start.resize(ny + 1, 0);
            for &c in &self.cell_of_item {
                self.row_start[c as usize / nx + 1] += 1;
            }
            for i in 0..ny {
                self.row_start[i + 1] += self.row_start[i];
            }
            self.fill.clear();
            self.fill.extend_from_slice(&self.row_start);
            self.keyed.clear();
            self.keyed.resize(count, (0, 0));
            for (k, (item, _, _)) in entries.enumerate() {
                let cell = self.cell_of_item[k];
                let row = cell as usize / nx;
                self.keyed[self.fill[row] as usize] = (cell, item);
                self.fill[row] += 1;
            }
            for row in 0..ny {
                let (s, e) = (self.row_start[row] as usize, self.row_start[row + 1] as usize);
                if e - s > 1 {
                    self.keyed[s..e].sort_by_key(|&(cell, _)| cell);
                }
            }
        }
    }

    /// Calls `f` for every body whose box may overlap [min, max].
    #[inline]
    pub(crate) fn query(&self, min: Point2<Real>, max: Point2<Real>, mut f: impl FnMut(u32)) {
        let m = Vector2::new(self.max_half, self.max_half);
        let (x0, y0, x1, y1) = self.spec.cell_range(min - m, max + m);
        for iy in y0..=y1 {
            let row = iy * self.spec.nx;
            if self.dense {
                let (s, e) = (self.start[row + x0] as usize, self.start[row + x1 + 1] as usize);
                for &item in &self.items[s..e] {
                    f(item);
                }
            } else {
                let (lo, hi) = ((row + x0) as u32, (row + x1) as u32);
                let in_row = &self.keyed[self.row_start[iy] as usize..self.row_start[iy + 1] as usize];
                let first = in_row.partition_point(|&(c, _)| c < lo);
                for &(c, item) in &in_row[first..] {
                    if c > hi {
                        break;
                    }
                    f(item);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::Wall;

    fn lab(walls: Vec<Wall>) -> Lab {
        Lab { name: "t".into(), width_m: 20.0, height_m: 10.0, walls, beacons: vec![], targets: vec![] }
    }

    #[test]
    fn an_l_shaped_wall_triangulates_into_four_triangles_covering_its_area() {
        let l = [(16.5, 10.0), (16.5, 5.5), (21.0, 5.5), (21.0, 6.5), (17.5, 6.5), (17.5, 10.0)];
        let poly: Vec<Point2<Real>> = l.iter().map(|&(x, y)| Point2::new(x, y)).collect();
        assert!(signed_area(&poly) > 0.0, "thesis Annex A lists it counter-clockwise");
        let tris = triangulate(&poly).expect("simple polygon");
        assert_eq!(tris.len(), 4);
        let area: Real = tris.iter().map(|t| signed_area(&[poly[t[0]], poly[t[1]], poly[t[2]]])).sum();
        assert!((area - signed_area(&poly)).abs() < 1e-9);
        let mut cw = poly.clone();
        cw.reverse();
        assert!(triangulate(&cw).is_none(), "clockwise input is re-ordered before triangulation");
    }

    #[test]
    fn degenerate_polygons_do_not_triangulate() {
        let line = [Point2::new(0.0, 0.0), Point2::new(1.0, 0.0), Point2::new(2.0, 0.0)];
        assert!(triangulate(&line).is_none());
    }

    #[test]
    fn lines_of_sight_stop_at_high_walls_only() {
        let wall = Wall {
            height_m: 2.0,
            corners: vec![Point2::new(9.0, 2.0), Point2::new(10.0, 2.0), Point2::new(10.0, 8.0), Point2::new(9.0, 8.0)],
        };
        let s = StaticIndex::build(&lab(vec![wall]), 2.0).expect("valid");
        let (a, b) = (Point2::new(3.0, 5.0), Point2::new(17.0, 5.5));
        assert!(s.segment_blocked(a, b, 1.0));
        assert!(!s.segment_blocked(a, b, 2.0), "a beacon as high as the wall is seen over it");
        assert!(!s.segment_blocked(Point2::new(3.0, 9.0), Point2::new(17.0, 9.0), 1.0));
        // Backwards and steep segments walk the grid too.
        assert!(s.segment_blocked(b, a, 1.0));
        assert!(s.segment_blocked(Point2::new(9.5, 0.5), Point2::new(9.6, 9.5), 1.0));
    }

    #[test]
    fn the_loose_grid_finds_every_body_near_a_query() {
        let spec = GridSpec::covering(Point2::new(0.0, 0.0), Point2::new(50.0, 50.0), 2.0);
        let mut g = DynGrid::new(spec);
        // 200 bodies on 625 cells builds the dense layout, 20 the sorted one.
        for n in [200u32, 20] {
            let pts: Vec<(u32, Point2<Real>, Real)> = (0..n)
                .map(|i| (i, Point2::new((i * 7 % 50) as Real + 0.3, (i * 13 % 50) as Real + 0.6), 0.7))
                .collect();
            g.rebuild(pts.iter().copied());
            assert_eq!(g.dense, n == 200);
            let (lo, hi) = (Point2::new(10.0, 10.0), Point2::new(20.0, 14.0));
            let mut found = Vec::new();
            g.query(lo, hi, |i| found.push(i));
            for (i, c, h) in &pts {
                let overlaps = c.x + h >= lo.x && c.x - h <= hi.x && c.y + h >= lo.y && c.y - h <= hi.y;
                if overlaps {
                    assert!(found.contains(i), "body {i} at {c} missed");
                }
            }
        }
    }

    proptest::proptest! {
        /// Both layouts of the robot grid answer a query with the same bodies in the same
        /// order (by cell, then as inserted), bodies off the grid included.
        #[test]
        fn both_robot_grid_layouts_answer_alike(
            bodies in proptest::collection::vec((-5.0f64..45.0, -5.0f64..35.0, 0.1f64..1.5), 0..120),
            (qx, qy, qw, qh) in (-5.0f64..45.0, -5.0f64..35.0, 0.0f64..12.0, 0.0f64..12.0),
        ) {
            let spec = GridSpec::covering(Point2::new(0.0, 0.0), Point2::new(40.0, 30.0), 2.0);
            let pts: Vec<(u32, Point2<Real>, Real)> =
                bodies.iter().enumerate().map(|(i, &(x, y, h))| (i as u32, Point2::new(x, y), h)).collect();
            let (lo, hi) = (Point2::new(qx, qy), Point2::new(qx + qw, qy + qh));
            let mut answers = Vec::new();
            for dense in [true, false] {
                let mut g = DynGrid::new(spec);
                g.rebuild_as(pts.iter().copied(), Some(dense));
                let mut found = Vec::new();
                g.query(lo, hi, |i| found.push(i));
                answers.push(found);
            }
            proptest::prop_assert_eq!(&answers[0], &answers[1]);
        }

        /// A query over a box of wall cells takes every edge listed in those cells exactly
        /// once, from the entries alone.
        #[test]
        fn a_box_of_wall_cells_takes_each_of_its_edges_once(
            walls in proptest::collection::vec((1.0f64..38.0, 1.0f64..28.0, 0.2f64..14.0, 0.2f64..9.0), 1..8),
            (qx, qy, qw, qh) in (-2.0f64..42.0, -2.0f64..32.0, 0.0f64..20.0, 0.0f64..20.0),
        ) {
            let walls: Vec<Wall> = walls
                .iter()
                .map(|&(x, y, w, h)| Wall {
                    corners: vec![
                        Point2::new(x, y),
                        Point2::new((x + w).min(39.5), y),
                        Point2::new((x + w).min(39.5), (y + h).min(29.5)),
                        Point2::new(x, (y + h).min(29.5)),
                    ],
                    height_m: 1.0,
                })
                .collect();
            let mut l = lab(walls);
            (l.width_m, l.height_m) = (40.0, 30.0);
            let s = StaticIndex::build(&l, 4.0).expect("valid");
            let (x0, y0, x1, y1) = s.spec.cell_range(Point2::new(qx, qy), Point2::new(qx + qw, qy + qh));
            let (mut taken, mut listed) = (Vec::new(), std::collections::BTreeSet::new());
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    for &e in s.edges_in(iy * s.spec.nx + ix) {
                        listed.insert(e.index());
                        if e.first_in(ix, iy, x0, y0) {
                            taken.push(e.index());
                        }
                    }
                }
            }
            taken.sort_unstable();
            proptest::prop_assert_eq!(taken, listed.into_iter().collect::<Vec<_>>());
        }
    }
}
