//! Grids over the lab: the known walls rasterised (with a distance field), and the layer of
//! obstacles found by the proximity sensors (occupancy evidence, so single noisy readings
//! neither create nor erase an obstacle).

use crate::geom::{Cone, Footprint, Pose, V2, point_segment_distance};
use crate::map::NavMap;

/// A uniform grid over `origin + [0, nx·cell] × [0, ny·cell]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    /// The corner of cell (0, 0), lab coordinates (a multiple of `cell`, so grids over
    /// different areas of one lab share their cell boundaries, up to rounding).
    pub origin: V2,
    /// Cell side, metres.
    pub cell: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
}

impl GridSpec {
    /// The grid of `cell`-sized cells that covers a `width` × `height` lab.
    pub fn covering(width: f64, height: f64, cell: f64) -> Self {
        Self::covering_area(&Area::lab(width, height), cell)
    }

    /// The grid of `cell`-sized cells that covers `area`.
    pub fn covering_area(area: &Area, cell: f64) -> Self {
        let origin = V2::new((area.lo.x / cell).floor() * cell, (area.lo.y / cell).floor() * cell);
        let n = |from: f64, to: f64| ((to - from) / cell).ceil().max(1.0) as usize;
        Self { origin, cell, nx: n(origin.x, area.hi.x), ny: n(origin.y, area.hi.y) }
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// Whether the grid has no cells (never, by construction).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cell holding `p`, if inside the grid.
    pub fn cell_of(&self, p: V2) -> Option<(usize, usize)> {
        let (fx, fy) = ((p.x - self.origin.x) / self.cell, (p.y - self.origin.y) / self.cell);
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (ix, iy) = (fx as usize, fy as usize);
        (ix < self.nx && iy < self.ny).then_some((ix, iy))
    }

    /// The cell nearest to `p` (clamped into the grid).
    #[inline]
    pub fn clamp_cell(&self, p: V2) -> (usize, usize) {
        let clamp = |v: f64, n: usize| {
            if v.is_finite() { (v / self.cell).floor().clamp(0.0, (n - 1) as f64) as usize } else { 0 }
        };
        (clamp(p.x - self.origin.x, self.nx), clamp(p.y - self.origin.y, self.ny))
    }

    /// The centre of a cell.
    pub fn center(&self, ix: usize, iy: usize) -> V2 {
        V2::new(self.origin.x + (ix as f64 + 0.5) * self.cell, self.origin.y + (iy as f64 + 0.5) * self.cell)
    }

    /// The linear index of a cell.
    pub fn index(&self, ix: usize, iy: usize) -> usize {
        iy * self.nx + ix
    }

    /// The cell of a linear index.
    pub fn coords(&self, i: usize) -> (usize, usize) {
        (i % self.nx, i / self.nx)
    }

    /// The cells whose centres may lie in the box `lo`–`hi` (inclusive ranges, clamped).
    #[inline]
    pub fn range(&self, lo: V2, hi: V2) -> (std::ops::RangeInclusive<usize>, std::ops::RangeInclusive<usize>) {
        let (x0, y0) = self.clamp_cell(lo);
        let (x1, y1) = self.clamp_cell(hi);
        (x0..=x1, y0..=y1)
    }
}

/// The part of the lab the navigator's grids cover: the whole lab when it is small enough,
/// else the box round the chair's start and checkpoints grown by [`Area::REACH_M`]
/// ([`Area::around`]), so memory grows with where the chair may go, not with the lab.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Area {
    /// Lower-left corner, lab coordinates.
    pub lo: V2,
    /// Upper-right corner.
    pub hi: V2,
}

impl Area {
    /// How far beyond its start and checkpoints a chair may plan, metres.
    pub const REACH_M: f64 = 15.0;
    /// A lab of at most this many square metres is covered whole (1,000,000 cells of 5 cm:
    /// every built-in map, and a building's floor of 50 m × 50 m).
    pub const WHOLE_LAB_M2: f64 = 2_500.0;

    /// The whole of a `width` × `height` lab.
    pub fn lab(width: f64, height: f64) -> Self {
        Self { lo: V2::new(0.0, 0.0), hi: V2::new(width, height) }
    }

    /// The whole lab if it is small, else the box round `points` grown by `reach`, within
    /// the lab.
    pub fn around(width: f64, height: f64, points: impl IntoIterator<Item = V2>, reach: f64) -> Self {
        let lab = Self::lab(width, height);
        if width * height <= Self::WHOLE_LAB_M2 {
            return lab;
        }
        let (mut lo, mut hi) = (V2::new(f64::INFINITY, f64::INFINITY), V2::new(f64::NEG_INFINITY, f64::NEG_INFINITY));
        for p in points.into_iter().filter(|p| p.x.is_finite() && p.y.is_finite()) {
            lo = V2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = V2::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        if lo.x > hi.x {
            // No point to centre on: a box of the reach's size in the lab's corner.
            return Self { lo: lab.lo, hi: V2::new((2.0 * reach).min(width), (2.0 * reach).min(height)) };
        }
        let clip = |v: f64, max: f64| v.clamp(0.0, max);
        Self {
            lo: V2::new(clip(lo.x - reach, width), clip(lo.y - reach, height)),
            hi: V2::new(clip(hi.x + reach, width), clip(hi.y + reach, height)),
        }
    }

    /// Whether `p` lies in the area.
    pub fn contains(&self, p: V2) -> bool {
        p.x >= self.lo.x && p.y >= self.lo.y && p.x <= self.hi.x && p.y <= self.hi.y
    }

    /// Whether the box `lo`–`hi` meets the area.
    pub fn meets(&self, lo: V2, hi: V2) -> bool {
        lo.x <= self.hi.x && lo.y <= self.hi.y && hi.x >= self.lo.x && hi.y >= self.lo.y
    }
}

/// The known walls and the lab's border, rasterised: a cell is occupied when a wall covers its
/// centre or an outline passes through it. Built once per map.
#[derive(Debug, Clone)]
pub struct StaticRaster {
    /// The grid.
    pub spec: GridSpec,
    occ: Vec<bool>,
    /// Distance from each cell's centre to the nearest occupied cell's centre, metres.
    dist: Vec<f32>,
    /// [`StaticRaster::off_lane_at`] per cell and heading, centimetres, and per cell a bit
    /// per heading for [`StaticRaster::in_own_lane`]; made when first asked.
    lanes: std::sync::OnceLock<(Vec<[u8; 8]>, Vec<u8>)>,
    /// [`StaticRaster::distance_to_narrows`] per cell, made when first asked.
    narrows: std::sync::OnceLock<Vec<f32>>,
}

/// A passage narrower than this (metres, wall to wall along one of the four axes of the grid)
/// is a narrow: a doorway, a gap between furniture.
pub const NARROW_PASSAGE_M: f64 = 1.3;

/// The walls as lanes see them: per cell, free cells from it to the first occupied one in each
/// of 8 directions (k·45°, capped at 255), the least of those within [`DOORWAY_BRIDGE_M`] across
/// the direction: the distance to a wall line, doorways in it bridged.
struct LaneWalls<'a> {
    spec: &'a GridSpec,
    occ: &'a [bool],
    runs: Vec<[u8; 8]>,
    /// The free runs before bridging.
    plain: Vec<[u8; 8]>,
}

/// Gaps in a wall up to twice this wide (metres) are bridged when lanes are laid: a doorway off
/// a corridor does not end the corridor's lanes. In the ward (a 1 m doorway every 5 m on both
/// sides) lanes that ended 1.2 m either side of each doorway held on a third of the corridor,
/// and chairs met head-on in the rest.
pub const DOORWAY_BRIDGE_M: f64 = 0.6;

/// Lanes end this far (metres, along the way) from where a passage stops being two lanes wide.
pub const JUNCTION_M: f64 = 1.2;

/// The 8 directions of [`StaticRaster`]'s runs, as cell steps.
const DIRS: [(isize, isize); 8] = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)];

/// Passages between these widths (metres, wall to wall) have two lanes, one each way.
pub const TWO_LANES_M: (f64, f64) = (1.5, 3.2);

/// The length of one step in direction `k` of [`DIRS`], metres (diagonals are √2 cells).
fn step_m(spec: &GridSpec, k: usize) -> f64 {
    if k % 2 == 1 { spec.cell * std::f64::consts::SQRT_2 } else { spec.cell }
}

/// Free runs from each cell in each direction of [`DIRS`]: one linear pass per direction,
/// visiting each cell after its neighbour in that direction.
fn free_runs(spec: &GridSpec, occ: &[bool]) -> Vec<[u8; 8]> {
    let (nx, ny) = (spec.nx, spec.ny);
    let mut runs = vec![[0u8; 8]; nx * ny];
    for (k, &(dx, dy)) in DIRS.iter().enumerate() {
        for j in 0..ny {
            let y = if dy > 0 { ny - 1 - j } else { j };
            for i in 0..nx {
                let x = if dx > 0 { nx - 1 - i } else { i };
                let c = y * nx + x;
                if occ[c] {
                    continue;
                }
                let (px, py) = (x as isize + dx, y as isize + dy);
                let next = if px < 0 || py < 0 || px >= nx as isize || py >= ny as isize {
                    0
                } else {
                    runs[py as usize * nx + px as usize][k]
                };
                runs[c][k] = next.saturating_add(1);
            }
        }
    }
    runs
}

impl LaneWalls<'_> {
    /// The width across heading `k` at cell `i` and the free part of it on the right, metres,
    /// if it is a two-lane passage's.
    fn two_lane_width(&self, i: usize, k: usize) -> Option<(f64, f64)> {
        let runs = &self.runs[i];
        let (right, left) = ((k + 6) % 8, (k + 2) % 8);
        let width = self.width(i, k);
        let two = (TWO_LANES_M.0..=TWO_LANES_M.1).contains(&width) && runs[right] < u8::MAX && runs[left] < u8::MAX;
        two.then_some((f64::from(runs[right]) * step_m(self.spec, right), width))
    }

    /// The width across heading `k` at cell `i`, wall to wall (doorways bridged), metres.
    fn width(&self, i: usize, k: usize) -> f64 {
        let (right, left) = ((k + 6) % 8, (k + 2) % 8);
        f64::from(self.runs[i][right]) * step_m(self.spec, right)
            + f64::from(self.runs[i][left]) * step_m(self.spec, left)
    }

    /// The free run through cell `i` along heading `k`, both ways (nothing bridged), metres.
    fn length(&self, i: usize, k: usize) -> f64 {
        f64::from(self.plain[i][k]) * step_m(self.spec, k)
            + f64::from(self.plain[i][(k + 4) % 8]) * step_m(self.spec, k)
    }

    /// How far left of its lane's middle a chair on cell `i` heading `k`·45° is, metres; zero
    /// within [`JUNCTION_M`] (along the heading) of where the passage stops being two lanes
    /// wide: a chair turning round a corner needs the whole width, and charging it for that
    /// made the search spend its expansions there. (In a doorway, a chair crossing the
    /// corridor's line, heading through it, finds the passage one lane wide: zero too.)
    fn lane_offset(&self, i: usize, k: usize) -> f64 {
        if self.occ[i] {
            return 0.0;
        }
        let Some((r, width)) = self.two_lane_width(i, k) else { return 0.0 };
        let (dx, dy) = DIRS[k];
        let n = (JUNCTION_M / step_m(self.spec, k)).ceil() as isize;
        let (x, y) = self.spec.coords(i);
        for sign in [1isize, -1] {
            for s in 1..=n {
                let (px, py) = (x as isize + sign * s * dx, y as isize + sign * s * dy);
                if px < 0 || py < 0 || px >= self.spec.nx as isize || py >= self.spec.ny as isize {
                    break;
                }
                let j = self.spec.index(px as usize, py as usize);
                if self.occ[j] {
                    break;
                }
                if self.two_lane_width(j, k).is_none() {
                    return 0.0;
                }
            }
        }
        (r - width / 4.0).max(0.0)
    }
}

impl StaticRaster {
    /// Rasterises the map's known walls (scenario obstacles are left out).
    pub fn new(map: &NavMap, cell: f64) -> Self {
        Self::within(map, cell, &Area::lab(map.width_m, map.height_m))
    }

    /// Rasterises the map's known walls within `area`, whose edges count as the lab's border:
    /// the chair plans nowhere beyond them.
    pub fn within(map: &NavMap, cell: f64, area: &Area) -> Self {
        let spec = GridSpec::covering_area(area, cell);
        let mut occ = vec![false; spec.len()];
        let touch = cell * std::f64::consts::FRAC_1_SQRT_2;
        for wall in map.known_walls() {
            let (mut lo, mut hi) =
                (V2::new(f64::INFINITY, f64::INFINITY), V2::new(f64::NEG_INFINITY, f64::NEG_INFINITY));
            for c in &wall.corners {
                lo = V2::new(lo.x.min(c.x), lo.y.min(c.y));
                hi = V2::new(hi.x.max(c.x), hi.y.max(c.y));
            }
            if !area.meets(lo - V2::new(cell, cell), hi + V2::new(cell, cell)) {
                continue;
            }
            let (xs, ys) = spec.range(lo - V2::new(cell, cell), hi + V2::new(cell, cell));
            for iy in ys {
                for ix in xs.clone() {
                    let p = spec.center(ix, iy);
                    if wall.contains(p) || wall.segments().any(|s| point_segment_distance(p, s.a, s.b) <= touch) {
                        occ[spec.index(ix, iy)] = true;
                    }
                }
            }
        }
        // The border: every cell whose centre is within a cell of the area's edge.
        for iy in 0..spec.ny {
            for ix in 0..spec.nx {
                let p = spec.center(ix, iy);
                if p.x < area.lo.x + cell || p.y < area.lo.y + cell || p.x > area.hi.x - cell || p.y > area.hi.y - cell
                {
                    occ[spec.index(ix, iy)] = true;
                }
            }
        }
        let dist = distance_field(&spec, &occ);
        Self { spec, occ, dist, lanes: std::sync::OnceLock::new(), narrows: std::sync::OnceLock::new() }
    }

    /// Whether a chair at `pose` drives in its own lane: in a two-lane passage (as for
    /// [`StaticRaster::off_lane`]), right of its middle line, heading along it: of the 8
    /// directions the nearest to its heading is one along which the free run is more than
    /// twice the passage's width across it (a chair crossing at 45° is in no lane).
    pub fn in_own_lane(&self, pose: &crate::geom::Pose) -> bool {
        let Some((ix, iy)) = self.spec.cell_of(pose.pos()) else { return false };
        let i = self.spec.index(ix, iy);
        let k = (pose.theta / std::f64::consts::FRAC_PI_4).round().rem_euclid(8.0) as usize;
        self.lanes().1[i] & (1 << k) != 0
    }

    /// How far left of its lane a chair at `pose` drives, metres: in a passage two lanes wide
    /// (wall to wall across the heading between 1.5 and 3.2 m, [`TWO_LANES_M`], doorways in its
    /// walls bridged, [`DOORWAY_BRIDGE_M`]), by how much the free width on its right exceeds a
    /// quarter of the passage's (the middle of the right lane). Zero right of that line, in
    /// rooms, halls, doorways, one-lane narrows and near junctions ([`JUNCTION_M`]). Traffic
    /// keeps right, so that chairs meeting in a corridor pass each other without a word.
    pub fn off_lane(&self, pose: &crate::geom::Pose) -> f64 {
        let Some((ix, iy)) = self.spec.cell_of(pose.pos()) else { return 0.0 };
        let heading = (pose.theta / std::f64::consts::FRAC_PI_4).round().rem_euclid(8.0) as usize;
        self.off_lane_at(self.spec.index(ix, iy), heading)
    }

    /// [`StaticRaster::off_lane`] for cell `i` and a heading of `k`·45° (`k` < 8): what the
    /// grid's cost-to-go charges for a step, so that it foresees the lane cost the hybrid
    /// search pays and keeps that search as focused as without lanes. Computed for every cell
    /// and heading the first time it is asked (only a chair that keeps right asks).
    pub fn off_lane_at(&self, i: usize, k: usize) -> f64 {
        f64::from(self.lanes().0[i][k]) / 100.0
    }

    /// The lane offsets per cell and heading, and the own-lane bits per cell, made when first
    /// asked.
    fn lanes(&self) -> &(Vec<[u8; 8]>, Vec<u8>) {
        self.lanes.get_or_init(|| {
            let walls = self.lane_walls();
            let offsets = (0..self.spec.len())
                .map(|i| std::array::from_fn(|k| (walls.lane_offset(i, k) * 100.0).round().min(255.0) as u8))
                .collect();
            let own = (0..self.spec.len())
                .map(|i| {
                    (0..8).fold(0u8, |bits, k| {
                        // Along the passage, not across it at 45°: the free run along the
                        // heading is more than twice the width across it.
                        let along = walls.length(i, k) > 2.0 * walls.width(i, k);
                        let right =
                            !self.occ[i] && along && walls.two_lane_width(i, k).is_some_and(|(r, w)| r < w / 2.0);
                        bits | (u8::from(right) << k)
                    })
                })
                .collect();
            (offsets, own)
        })
    }

    /// The free runs from every cell, each the least within [`DOORWAY_BRIDGE_M`] across its
    /// direction (a sliding minimum along the perpendicular), so that a run through a doorway
    /// counts as far as the wall the doorway is in. (A morphological closing does not bridge a
    /// doorway in a thin wall: discs from both sides cover it.)
    fn lane_walls(&self) -> LaneWalls<'_> {
        let (nx, ny) = (self.spec.nx as isize, self.spec.ny as isize);
        let plain = free_runs(&self.spec, &self.occ);
        let mut runs = plain.clone();
        for k in 0..8 {
            let (px, py) = DIRS[(k + 2) % 8];
            let n = (DOORWAY_BRIDGE_M / step_m(&self.spec, k)).round() as isize;
            for y in 0..ny {
                for x in 0..nx {
                    let i = (y * nx + x) as usize;
                    if self.occ[i] {
                        continue;
                    }
                    let mut least = plain[i][k];
                    for s in -n..=n {
                        let (qx, qy) = (x + s * px, y + s * py);
                        if qx >= 0 && qy >= 0 && qx < nx && qy < ny {
                            least = least.min(plain[(qy * nx + qx) as usize][k]);
                        }
                    }
                    runs[i][k] = least;
                }
            }
        }
        LaneWalls { spec: &self.spec, occ: &self.occ, runs, plain }
    }
    /// The direction index (into the 8 directions of the free runs, `k`·45°) of a step of
    /// `(dx, dy)` cells.
    pub fn direction_of(dx: i64, dy: i64) -> Option<usize> {
        DIRS.iter().position(|&(x, y)| x as i64 == dx.signum() && y as i64 == dy.signum())
    }

    /// Whether a cell is occupied.
    pub fn occupied(&self, i: usize) -> bool {
        self.occ[i]
    }

    /// Whether the cell holding `p` is occupied (outside the lab counts as occupied).
    pub fn occupied_at(&self, p: V2) -> bool {
        self.spec.cell_of(p).is_none_or(|(ix, iy)| self.occ[self.spec.index(ix, iy)])
    }

    /// Distance from the centre of `p`'s cell to the nearest occupied cell's centre.
    pub fn distance_at(&self, p: V2) -> f64 {
        match self.spec.cell_of(p) {
            Some((ix, iy)) => self.dist[self.spec.index(ix, iy)] as f64,
            None => 0.0,
        }
    }

    /// The distance field (per cell).
    pub fn distances(&self) -> &[f32] {
        &self.dist
    }

    /// Distance from the centre of `p`'s cell to the nearest narrow ([`NARROW_PASSAGE_M`]:
    /// a doorway, say), metres; made for every cell the first time it is asked. A chair that
    /// gives way must not stand where the others need to pass.
    pub fn distance_to_narrows(&self, p: V2) -> f64 {
        let field = self.narrows.get_or_init(|| {
            let runs = free_runs(&self.spec, &self.occ);
            let narrow: Vec<bool> = runs
                .iter()
                .zip(&self.occ)
                .map(|(r, &o)| {
                    !o && (0..4).any(|k| {
                        (f64::from(r[k]) + f64::from(r[k + 4]) - 1.0) * step_m(&self.spec, k) < NARROW_PASSAGE_M
                    })
                })
                .collect();
            distance_field(&self.spec, &narrow)
        });
        match self.spec.cell_of(p) {
            Some((ix, iy)) => f64::from(field[self.spec.index(ix, iy)]),
            None => 0.0,
        }
    }
}

/// Exact Euclidean distance transform (Felzenszwalb–Huttenlocher), in metres between cell
/// centres; with nothing occupied every cell gets a large value.
pub fn distance_field(spec: &GridSpec, occ: &[bool]) -> Vec<f32> {
    const FAR: f64 = 1e12;
    let (nx, ny) = (spec.nx, spec.ny);
    let mut g: Vec<f64> = occ.iter().map(|&o| if o { 0.0 } else { FAR }).collect();
    let n = nx.max(ny);
    let (mut f, mut d, mut v, mut z) = (vec![0.0; n], vec![0.0; n], vec![0usize; n], vec![0.0; n + 1]);
    for x in 0..nx {
        for y in 0..ny {
            f[y] = g[y * nx + x];
        }
        edt_1d(&f[..ny], &mut d[..ny], &mut v, &mut z);
        for y in 0..ny {
            g[y * nx + x] = d[y];
        }
    }
    for y in 0..ny {
        f[..nx].copy_from_slice(&g[y * nx..(y + 1) * nx]);
        edt_1d(&f[..nx], &mut d[..nx], &mut v, &mut z);
        g[y * nx..(y + 1) * nx].copy_from_slice(&d[..nx]);
    }
    g.iter().map(|&s| (s.min(FAR).sqrt() * spec.cell) as f32).collect()
}

/// One dimension of the squared distance transform: `d[q] = min_p (q − p)² + f[p]`.
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        let qf = q as f64;
        let mut s;
        loop {
            let p = v[k] as f64;
            s = ((f[q] + qf * qf) - (f[v[k]] + p * p)) / (2.0 * qf - 2.0 * p);
            // z[0] is −∞, so this never steps below the first parabola.
            if s <= z[k] && k > 0 {
                k -= 1;
            } else {
                break;
            }
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, dq) in d.iter_mut().enumerate() {
        let qf = q as f64;
        while z[k + 1] < qf {
            k += 1;
        }
        let p = v[k] as f64;
        *dq = (qf - p) * (qf - p) + f[v[k]];
    }
}

/// How the sensed layer weighs evidence (log-odds units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvidenceParams {
    /// Added to a cell on the arc of a reading that the known walls do not explain.
    pub hit: f32,
    /// Taken from a cell a reading saw through.
    pub miss: f32,
    /// A cell becomes an obstacle at this evidence…
    pub occupied_above: f32,
    /// …and stops being one below this.
    pub free_below: f32,
    /// Evidence is kept within ± this.
    pub clamp: f32,
    /// Cells nearer than `reading − carve_gap` are seen through (the noise's allowance).
    pub carve_gap: f64,
    /// The arc is marked this far behind the reading: a cell straddling the surface is hit
    /// as often as it is seen through, so the estimate sits on the surface rather than a cell
    /// in front of it.
    pub arc_offset: f64,
    /// A reading this much shorter than the known walls explain reveals an obstacle.
    pub unexplained: f64,
    /// Readings within this of the range saw nothing.
    pub nothing_within: f64,
    /// Readings farther than this only clear cells: their arcs are too long to place what
    /// they saw.
    pub hit_range: f64,
    /// A cell updated again from a sensor position within this distance of its last full
    /// update moves only `same_view` as far: the same view repeats its geometric errors (a
    /// cone edge grazing a face marks the same wrong cells), while a true obstacle is seen
    /// alike from everywhere. Hits and misses are weighed alike, so a chair standing still
    /// still builds up what it sees.
    pub new_view_m: f64,
    /// See `new_view_m`.
    pub same_view: f32,
    /// Obstacle cells lose this much evidence per tick, seen or not. Off by default: what
    /// is out of view (an obstacle just passed, beside the chair) must not fade, and what is
    /// in view is confirmed or cleared by the readings themselves.
    pub decay: f32,
}

impl Default for EvidenceParams {
    fn default() -> Self {
        Self {
            hit: 1.0,
            miss: 0.6,
            occupied_above: 1.45,
            free_below: 0.5,
            clamp: 4.0,
            carve_gap: 0.05,
            arc_offset: 0.025,
            unexplained: 0.25,
            nothing_within: 0.2,
            hit_range: 2.2,
            new_view_m: 0.1,
            same_view: 0.3,
            decay: 0.0,
        }
    }
}

/// One proximity reading placed in the lab.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The sensor's cone in the lab frame (from the pose estimate).
    pub cone: Cone,
    /// The distance read, metres.
    pub distance: f64,
    /// The sensor's range, metres.
    pub range: f64,
    /// What the known walls alone would make it read.
    pub expected: f64,
}

/// Obstacles found by the proximity sensors, as occupancy evidence per cell.
#[derive(Debug, Clone)]
pub struct SensedLayer {
    /// The grid.
    pub spec: GridSpec,
    /// The weights.
    pub params: EvidenceParams,
    evidence: Vec<f32>,
    occupied: Vec<bool>,
    /// Per-cell stamp of the last observation that touched it (one vote per reading).
    stamp: Vec<u32>,
    now: u32,
    cells: Vec<u32>,
    changed: bool,
    arc: Vec<u32>,
    /// Where the sensor was at each cell's last full-weight update (NaN: never).
    last_view: Vec<[f32; 2]>,
}

impl SensedLayer {
    /// An empty layer on the grid `spec`.
    pub fn new(spec: GridSpec, params: EvidenceParams) -> Self {
        Self {
            spec,
            params,
            evidence: vec![0.0; spec.len()],
            occupied: vec![false; spec.len()],
            stamp: vec![0; spec.len()],
            now: 0,
            cells: Vec::new(),
            changed: false,
            arc: Vec::new(),
            last_view: vec![[f32::NAN; 2]; spec.len()],
        }
    }

    /// Whether a cell is currently an obstacle.
    pub fn occupied(&self, i: usize) -> bool {
        self.occupied[i]
    }

    /// The evidence of a cell.
    pub fn evidence(&self, i: usize) -> f32 {
        self.evidence[i]
    }

    /// Every obstacle cell (linear indices).
    pub fn cells(&self) -> &[u32] {
        &self.cells
    }

    /// Whether any cell changed state since the last call.
    pub fn take_changes(&mut self) -> bool {
        std::mem::take(&mut self.changed)
    }

    /// Adds one reading: the cells it saw through lose evidence; if the known walls do not
    /// explain it, the cells of its arc gain some. Cells of known walls, and cells inside the
    /// chair (`body`, where nothing can be), are left alone.
    pub fn observe(&mut self, statics: &StaticRaster, obs: &Observation, body: Option<(&Pose, &Footprint)>) {
        let p = self.params;
        let d = obs.distance.clamp(0.0, obs.range);
        if !d.is_finite() {
            return;
        }
        let seen_nothing = d >= obs.range - p.nothing_within;
        let unexplained = !seen_nothing && d <= p.hit_range && obs.expected - d > p.unexplained;
        let carve_to = d - p.carve_gap;
        let reach = if unexplained { d + p.arc_offset + self.spec.cell } else { carve_to };
        if reach <= 0.0 {
            return;
        }
        self.now = self.now.wrapping_add(1);
        if self.now == 0 {
            self.stamp.fill(0);
            self.now = 1;
        }
        let cone = obs.cone;
        let axis = V2::unit(cone.dir);
        let u1 = V2::unit(cone.dir - cone.half);
        let u2 = V2::unit(cone.dir + cone.half);
        // The sector's bounding box: apex, both edge ends and any arc extreme inside.
        let mut lo = cone.apex;
        let mut hi = cone.apex;
        let mut grow = |q: V2| {
            lo = V2::new(lo.x.min(q.x), lo.y.min(q.y));
            hi = V2::new(hi.x.max(q.x), hi.y.max(q.y));
        };
        grow(cone.apex + u1 * reach);
        grow(cone.apex + u2 * reach);
        grow(cone.apex + axis * reach);
        for k in 0..4 {
            let a = k as f64 * std::f64::consts::FRAC_PI_2;
            if cone.contains(cone.apex + V2::unit(a)) {
                grow(cone.apex + V2::unit(a) * reach);
            }
        }
        let half_cell = self.spec.cell / 2.0;
        // Every ray across the arc meets at least one cell centre within this band.
        let arc_band = self.spec.cell * std::f64::consts::FRAC_1_SQRT_2;
        // An arc narrower than a cell still marks the cells it crosses; a wider one marks only
        // cells whose centres are inside the cone, as the carving does.
        let lateral = (half_cell - d * cone.half.sin()).max(0.0);
        let (xs, ys) = self.spec.range(lo - V2::new(half_cell, half_cell), hi + V2::new(half_cell, half_cell));
        let mut arc = std::mem::take(&mut self.arc);
        arc.clear();
        for iy in ys {
            for ix in xs.clone() {
                let i = self.spec.index(ix, iy);
                if statics.occupied(i) || self.stamp[i] == self.now {
                    continue;
                }
                let v = self.spec.center(ix, iy) - cone.apex;
                let r = v.norm();
                if r > reach || v.dot(axis) <= 0.0 {
                    continue;
                }
                // Lateral distance of the centre inside each cone edge.
                let (in1, in2) = (u1.cross(v), v.cross(u2));
                if r < carve_to {
                    if in1 >= 0.0 && in2 >= 0.0 {
                        self.stamp[i] = self.now;
                        let w = self.view_weight(i, cone.apex);
                        self.add(i, -p.miss * w);
                    }
                } else if unexplained && (r - d - p.arc_offset).abs() <= arc_band && in1 >= -lateral && in2 >= -lateral
                {
                    let c = self.spec.center(ix, iy);
                    if !body.is_some_and(|(pose, fp)| fp.contains_body(pose.to_body(c), 0.05)) {
                        self.stamp[i] = self.now;
                        arc.push(i as u32);
                    }
                }
            }
        }
        if !arc.is_empty() {
            // The obstacle is somewhere on the arc. Where the arc crosses cells already
            // believed occupied, those explain the reading and take the hit; otherwise every
            // cell of it shares the hit (cells seen through often are the least likely), and a
            // wide arc says little about each of its cells.
            let explained = 0.6 * p.occupied_above;
            let n_explained = arc.iter().filter(|&&i| self.evidence[i as usize] >= explained).count();
            let clear = -2.0 * p.miss;
            let n_open = arc.iter().filter(|&&i| self.evidence[i as usize] > clear).count();
            let spread = p.hit * (2.5 / (2.0 * cone.half * d / self.spec.cell).max(1.0) as f32).min(1.0);
            let (threshold, hit) = if n_explained > 0 {
                (explained, p.hit)
            } else if n_open > 0 {
                (clear + f32::EPSILON, spread)
            } else {
                (f32::NEG_INFINITY, spread)
            };
            for &i in &arc {
                let i = i as usize;
                if self.evidence[i] >= threshold {
                    let w = self.view_weight(i, cone.apex);
                    self.add(i, hit * w);
                }
            }
        }
        self.arc = arc;
    }

    /// The weight of an update of cell `i` from a sensor at `apex`: full from a new view
    /// (which then becomes the cell's last), `same_view` from near the last one.
    fn view_weight(&mut self, i: usize, apex: V2) -> f32 {
        let [lx, ly] = self.last_view[i];
        let moved = ((lx as f64 - apex.x).powi(2) + (ly as f64 - apex.y).powi(2)).sqrt();
        if lx.is_nan() || moved >= self.params.new_view_m {
            self.last_view[i] = [apex.x as f32, apex.y as f32];
            1.0
        } else {
            self.params.same_view
        }
    }

    /// Lets every obstacle cell lose `decay` of evidence (once per tick).
    pub fn decay(&mut self) {
        self.fade(self.params.decay);
    }

    /// Lets every obstacle cell lose `d` of evidence at once: what the sensors still see comes
    /// back within a few readings, what they do not (a ghost of noise, out of view) goes.
    pub fn fade(&mut self, d: f32) {
        if d <= 0.0 {
            return;
        }
        let cells = std::mem::take(&mut self.cells);
        let mut kept = Vec::with_capacity(cells.len());
        for &c in &cells {
            let i = c as usize;
            self.evidence[i] -= d;
            if self.evidence[i] < self.params.free_below {
                self.occupied[i] = false;
                self.changed = true;
            } else {
                kept.push(c);
            }
        }
        self.cells = kept;
    }

    fn add(&mut self, i: usize, delta: f32) {
        let p = self.params;
        let e = (self.evidence[i] + delta).clamp(-p.clamp, p.clamp);
        self.evidence[i] = e;
        if !self.occupied[i] && e >= p.occupied_above {
            self.occupied[i] = true;
            self.cells.push(i as u32);
            self.changed = true;
        } else if self.occupied[i] && e < p.free_below {
            self.occupied[i] = false;
            if let Some(k) = self.cells.iter().position(|&c| c as usize == i) {
                self.cells.swap_remove(k);
            }
            self.changed = true;
        }
    }
}

/// Points or segments bucketed on a coarse grid, for "what is near this box" queries.
#[derive(Debug, Clone)]
pub struct Buckets {
    spec: GridSpec,
    start: Vec<u32>,
    items: Vec<u32>,
    /// Per bucket, how many buckets away (Chebyshev) the nearest bucket with an item is:
    /// a query whose box lies within that finds nothing without looking.
    empty_around: Vec<u16>,
}

impl Buckets {
    /// Buckets `count` items over `area`, each listed in every bucket its box `(lo, hi)`
    /// meets (an item beyond the area in the edge buckets nearest to it).
    pub fn build(area: &Area, cell: f64, count: usize, bounds: impl Fn(usize) -> (V2, V2)) -> Self {
        let spec = GridSpec::covering_area(area, cell);
        let mut counts = vec![0u32; spec.len() + 1];
        let each = |k: usize, f: &mut dyn FnMut(usize)| {
            let (lo, hi) = bounds(k);
            let (xs, ys) = spec.range(lo, hi);
            for iy in ys {
                for ix in xs.clone() {
                    f(spec.index(ix, iy));
                }
            }
        };
        for k in 0..count {
            each(k, &mut |b| counts[b + 1] += 1);
        }
        for b in 0..spec.len() {
            counts[b + 1] += counts[b];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[spec.len()] as usize];
        for k in 0..count {
            each(k, &mut |b| {
                items[fill[b] as usize] = k as u32;
                fill[b] += 1;
            });
        }
        let empty_around = chebyshev_to_nonempty(&spec, |b| counts[b + 1] > counts[b]);
        Self { spec, start: counts, items, empty_around }
    }

    /// [`Buckets::query`] over the box of half-side `r` round `centre`, which returns at
    /// once, having called `f` for nothing, when no bucket that box meets holds an item.
    #[inline]
    pub fn query_near(&self, centre: V2, r: f64, f: impl FnMut(usize)) {
        let (ix, iy) = self.spec.clamp_cell(centre);
        // The box meets buckets at most ceil(r / cell) away from the centre's, in each axis.
        let reach = (r / self.spec.cell).ceil();
        if f64::from(self.empty_around[self.spec.index(ix, iy)]) > reach {
            return;
        }
        let d = V2::new(r, r);
        self.query(centre - d, centre + d, f);
    }

    /// Calls `f` with every item listed in a bucket that meets the box `lo`–`hi` (an item
    /// may come more than once).
    #[inline]
    pub fn query(&self, lo: V2, hi: V2, mut f: impl FnMut(usize)) {
        let (xs, ys) = self.spec.range(lo, hi);
        for iy in ys {
            for ix in xs.clone() {
                let b = self.spec.index(ix, iy);
                for &k in &self.items[self.start[b] as usize..self.start[b + 1] as usize] {
                    f(k as usize);
                }
            }
        }
    }
}

/// Per cell of `spec`, the Chebyshev distance in cells to the nearest cell where `full`
/// holds (`u16::MAX` when none does): two chamfer passes, exact for this metric.
fn chebyshev_to_nonempty(spec: &GridSpec, full: impl Fn(usize) -> bool) -> Vec<u16> {
    let (nx, ny) = (spec.nx, spec.ny);
    let mut d: Vec<u16> = (0..spec.len()).map(|b| if full(b) { 0 } else { u16::MAX }).collect();
    for iy in 0..ny {
        for ix in 0..nx {
            let mut best = d[iy * nx + ix];
            for (dx, dy) in [(-1i64, 0i64), (-1, -1), (0, -1), (1, -1)] {
                let (x, y) = (ix as i64 + dx, iy as i64 + dy);
                if x >= 0 && y >= 0 && (x as usize) < nx {
                    best = best.min(d[y as usize * nx + x as usize].saturating_add(1));
                }
            }
            d[iy * nx + ix] = best;
        }
    }
    for iy in (0..ny).rev() {
        for ix in (0..nx).rev() {
            let mut best = d[iy * nx + ix];
            for (dx, dy) in [(1i64, 0i64), (1, 1), (0, 1), (-1, 1)] {
                let (x, y) = (ix as i64 + dx, iy as i64 + dy);
                if x >= 0 && (x as usize) < nx && (y as usize) < ny {
                    best = best.min(d[y as usize * nx + x as usize].saturating_add(1));
                }
            }
            d[iy * nx + ix] = best;
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::MapWall;

    #[test]
    fn the_distance_field_is_euclidean() {
        let spec = GridSpec { origin: V2::new(0.0, 0.0), cell: 0.1, nx: 20, ny: 10 };
        let mut occ = vec![false; spec.len()];
        occ[spec.index(5, 5)] = true;
        let d = distance_field(&spec, &occ);
        assert_eq!(d[spec.index(5, 5)], 0.0);
        assert!((d[spec.index(8, 9)] as f64 - 0.5).abs() < 1e-6, "3-4-5 triangle");
        assert!((d[spec.index(15, 5)] as f64 - 1.0).abs() < 1e-6);
    }

    #[test]
    fn walls_and_border_are_rasterised_but_obstacles_are_not() {
        let mut map = NavMap::empty(4.0, 3.0);
        map.walls.push(MapWall::rectangle(1.0, 1.0, 1.1, 2.0, false));
        map.walls.push(MapWall::rectangle(3.0, 1.0, 3.5, 2.0, true));
        let r = StaticRaster::new(&map, 0.05);
        assert!(r.occupied_at(V2::new(1.05, 1.5)));
        assert!(!r.occupied_at(V2::new(1.3, 1.5)));
        assert!(!r.occupied_at(V2::new(3.2, 1.5)), "scenario obstacles are for the sensors to find");
        assert!(r.occupied_at(V2::new(0.01, 1.5)) && r.occupied_at(V2::new(2.0, 2.99)));
        assert!((r.distance_at(V2::new(1.5, 1.5)) - 0.4).abs() < 0.06);
    }

    #[test]
    fn a_large_lab_is_covered_only_round_the_route_and_alike_there() {
        let mut map = NavMap::empty(200.0, 100.0);
        map.walls.push(MapWall::rectangle(120.0, 50.0, 120.3, 52.0, false));
        let small = Area::around(40.0, 50.0, [V2::new(1.0, 1.0)], Area::REACH_M);
        assert_eq!(small, Area::lab(40.0, 50.0), "a small lab is covered whole");
        let area = Area::around(200.0, 100.0, [V2::new(115.0, 51.0), V2::new(125.0, 51.0)], 5.0);
        assert_eq!((area.lo, area.hi), (V2::new(110.0, 46.0), V2::new(130.0, 56.0)));
        let whole = StaticRaster::new(&map, 0.05);
        let part = StaticRaster::within(&map, 0.05, &area);
        assert!(part.spec.len() * 40 < whole.spec.len(), "{} cells of {}", part.spec.len(), whole.spec.len());
        // Inside the area (off its edges) the two rasters agree cell for cell.
        for k in 0..2000 {
            let p = V2::new(110.2 + (k % 50) as f64 * 0.39, 46.2 + (k / 50) as f64 * 0.24);
            assert_eq!(part.occupied_at(p), whole.occupied_at(p), "at {p:?}");
        }
        assert!(part.occupied_at(V2::new(120.1, 51.0)), "the wall");
        // Its edges, and everything beyond, are walls to the planner.
        assert!(part.occupied_at(V2::new(110.01, 51.0)) && part.occupied_at(V2::new(100.0, 51.0)));
        assert!(!whole.occupied_at(V2::new(100.0, 51.0)));
    }

    #[test]
    fn a_short_unexplained_reading_marks_its_arc_and_clears_the_way_to_it() {
        let map = NavMap::empty(6.0, 4.0);
        let statics = StaticRaster::new(&map, 0.05);
        let mut layer = SensedLayer::new(statics.spec, EvidenceParams::default());
        let cone = Cone { apex: V2::new(1.0, 2.0), dir: 0.0, half: 5f64.to_radians() };
        let obs = Observation { cone, distance: 2.0, range: 3.0, expected: 3.0 };
        // The same obstacle at (3, 2) seen while approaching it.
        for k in 0..5 {
            let cone = Cone { apex: V2::new(1.0 + 0.12 * k as f64, 2.0), ..cone };
            layer.observe(&statics, &Observation { cone, distance: 2.0 - 0.12 * k as f64, ..obs }, None);
        }
        let at = |x: f64, y: f64| statics.spec.cell_of(V2::new(x, y)).map(|(ix, iy)| statics.spec.index(ix, iy));
        let i = at(3.0, 2.0).expect("inside");
        assert!(layer.occupied(i), "evidence {}", layer.evidence(i));
        let j = at(2.0, 2.0).expect("inside");
        assert!(layer.evidence(j) < 0.0 && !layer.occupied(j));
        assert!(layer.take_changes() && !layer.cells().is_empty());
        // Readings that now see past it, from wherever, clear it again.
        for k in 0..10 {
            let cone = Cone { apex: V2::new(1.0 - 0.12 * k as f64, 2.0), ..cone };
            layer.observe(&statics, &Observation { cone, distance: 3.0, ..obs }, None);
        }
        assert!(!layer.occupied(i));
        assert!(layer.cells().is_empty());
    }

    #[test]
    fn lanes_keep_right_in_a_corridor_past_its_doorways_and_end_at_a_hall() {
        // A 2 m corridor (y 5 to 7) with a 1 m doorway in its north wall at x 10, opening into a
        // hall at x 14.
        let mut map = NavMap::empty(20.0, 12.0);
        map.walls.push(MapWall::rectangle(0.5, 4.9, 14.0, 5.0, false));
        map.walls.push(MapWall::rectangle(0.5, 7.0, 9.5, 7.1, false));
        map.walls.push(MapWall::rectangle(10.5, 7.0, 14.0, 7.1, false));
        let r = StaticRaster::new(&map, 0.05);
        let at = |x: f64, y: f64, deg: f64| r.off_lane(&crate::geom::Pose::from_deg(x, y, deg));
        // Eastbound: the right lane is the south half; its middle (y 5.5) costs nothing.
        assert!(at(4.0, 5.5, 0.0) < 0.05, "{}", at(4.0, 5.5, 0.0));
        assert!((at(4.0, 6.5, 0.0) - 1.0).abs() < 0.1, "{}", at(4.0, 6.5, 0.0));
        // Westbound the other way round.
        assert!(at(4.0, 6.5, 180.0) < 0.05);
        assert!(at(4.0, 5.5, 180.0) > 0.9);
        // The doorway does not end the lanes: past it, and in front of it, the lanes hold.
        for x in [9.5, 10.0, 10.5, 11.2] {
            assert!((at(x, 6.5, 0.0) - 1.0).abs() < 0.1, "x {x}: {}", at(x, 6.5, 0.0));
            assert!(at(x, 6.5, 180.0) < 0.05, "x {x}: {}", at(x, 6.5, 180.0));
        }
        // In the doorway itself, and in the room beyond, no lanes.
        assert_eq!(at(10.0, 7.05, 90.0), 0.0);
        assert_eq!(at(10.0, 8.0, 0.0), 0.0);
        // Near the hall the lanes end (1.2 m before the bridged walls do, 0.6 m past the
        // real ones): a chair turning there needs the width.
        assert!(at(12.0, 6.5, 0.0) > 0.9);
        assert_eq!(at(13.6, 6.5, 0.0), 0.0);
        // In its own lane: right of the middle line, heading along the corridor (within
        // 22.5°), past the doorway too; not left of it, across it, in the doorway or the hall.
        let own = |x: f64, y: f64, deg: f64| r.in_own_lane(&crate::geom::Pose::from_deg(x, y, deg));
        for (x, y, deg) in [(4.0, 5.6, 0.0), (4.0, 5.9, 15.0), (10.0, 6.4, 180.0), (12.5, 6.3, -170.0)] {
            assert!(own(x, y, deg), "({x}, {y}) heading {deg}°");
        }
        for (x, y, deg) in [(4.0, 6.1, 0.0), (4.0, 5.9, 180.0), (4.0, 5.5, 90.0), (4.0, 5.5, 40.0), (10.0, 7.05, 90.0)]
        {
            assert!(!own(x, y, deg), "({x}, {y}) heading {deg}°");
        }
        assert!(!own(16.0, 6.5, 180.0), "the hall has no lanes");
    }

    #[test]
    fn a_query_near_finds_what_the_whole_query_finds() {
        let area = Area { lo: V2::new(0.0, 0.0), hi: V2::new(20.0, 10.0) };
        // A few clusters of points, and queries everywhere, some beyond the area.
        let pts: Vec<V2> = (0..40)
            .map(|k| {
                let c = [V2::new(3.0, 2.0), V2::new(12.5, 7.3), V2::new(19.9, 0.1)][k % 3];
                c + V2::new((k as f64 * 0.37).sin() * 0.8, (k as f64 * 0.71).cos() * 0.8)
            })
            .collect();
        let b = Buckets::build(&area, 0.5, pts.len(), |k| (pts[k], pts[k]));
        let mut skipped = 0;
        for qy in -4..=44 {
            for qx in -4..=84 {
                let c = V2::new(qx as f64 * 0.25 + 0.01, qy as f64 * 0.25 + 0.02);
                for r in [0.1, 0.6, 1.3] {
                    let d = V2::new(r, r);
                    let (mut all, mut near) = (Vec::new(), Vec::new());
                    b.query(c - d, c + d, |k| all.push(k));
                    b.query_near(c, r, |k| near.push(k));
                    assert_eq!(all, near, "at {c:?}, r {r}");
                    skipped += usize::from(all.is_empty());
                }
            }
        }
        assert!(skipped > 1000, "most queries find nothing here: {skipped}");
        let none = Buckets::build(&area, 0.5, 0, |_| (V2::default(), V2::default()));
        none.query_near(V2::new(5.0, 5.0), 3.0, |_| panic!("no items"));
    }
}
