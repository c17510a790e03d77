//! The map as the hub publishes it, decoded once for every client: the hub sends a
//! [`MapHeader`] and a slice of [`MapItem`]s (see `ipc-types`), and [`Map::decode`] checks
//! them and turns them into walls, beacons, targets, checkpoints and grid poses.
//!
//! ```
//! use agent_sdk::map::{Map, MapDecodeError};
//! use ipc_types::{MAP_CHECKPOINT, MapHeader, MapItem};
//!
//! let header = MapHeader { width_m: 10.0, height_m: 8.0, item_count: 1, ..MapHeader::default() };
//! let items = [MapItem { kind: MAP_CHECKPOINT, index: 0, a: 8.0, b: 2.0, c: 0.5 }];
//! let map = Map::decode(&header, &items).expect("a valid map");
//! assert_eq!(map.checkpoints[0].radius, 0.5);
//! let lying = MapHeader { item_count: 2, ..header };
//! assert_eq!(Map::decode(&lying, &items), Err(MapDecodeError::ItemCount { announced: 2, got: 1 }));
//! ```

use ipc_types::{MAP_BEACON, MAP_CHECKPOINT, MAP_CORNER, MAP_GRID, MAP_TARGET, MAP_WALL, MapHeader, MapItem};
use places::Checkpoint;

/// A point on the floor, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
}

impl Point {
    /// The point (x, y).
    pub fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }
}

/// A wall: a polygon standing on the floor.
#[derive(Debug, Clone, PartialEq)]
pub struct Wall {
    /// Height, metres.
    pub height_m: f64,
    /// Corners in order (either orientation), at least three.
    pub corners: Vec<Point>,
    /// A scenario's obstacle: a static body placed by the run, not part of the map file.
    pub obstacle: bool,
}

/// A beacon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beacon {
    /// Where it stands.
    pub pos: Point,
    /// Height, metres.
    pub height_m: f64,
}

/// A target area (seen by the ground sensor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    /// Centre.
    pub pos: Point,
    /// Radius, metres.
    pub radius_m: f64,
}

/// A grid start pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridPose {
    /// Position.
    pub pos: Point,
    /// Heading, degrees.
    pub heading_deg: f64,
}

/// The map as the hub published it, checked and typed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Map {
    /// The header as published: the tick period (`cycle_ms`) and the run's parameters
    /// (`params`) are read from here; its name, size and counts were checked and are decoded
    /// into the fields below.
    pub header: MapHeader,
    /// Lab name (may be empty).
    pub name: String,
    /// Extent along x, metres (the lab is `[0, width] × [0, height]`, bordered by walls).
    pub width_m: f64,
    /// Extent along y, metres.
    pub height_m: f64,
    /// The lab's walls, then the scenario's obstacles.
    pub walls: Vec<Wall>,
    /// Beacons, by index.
    pub beacons: Vec<Beacon>,
    /// Targets, by index.
    pub targets: Vec<Circle>,
    /// The scenario's checkpoints, by index, in the project's one checkpoint type (the hub
    /// publishes its own `places::Checkpoint`s; the radius is passed on as sent).
    pub checkpoints: Vec<Checkpoint>,
    /// Grid start poses, by slot.
    pub grid: Vec<GridPose>,
}

/// What a map item is, as its `kind` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ItemKind {
    /// `MAP_WALL`.
    Wall,
    /// `MAP_CORNER`.
    Corner,
    /// `MAP_BEACON`.
    Beacon,
    /// `MAP_TARGET`.
    Target,
    /// `MAP_GRID`.
    Grid,
    /// `MAP_CHECKPOINT`.
    Checkpoint,
}

impl ItemKind {
    /// The kind of a `MapItem::kind` value, if it is one.
    pub fn from_wire(kind: u32) -> Option<Self> {
        Some(match kind {
            MAP_WALL => Self::Wall,
            MAP_CORNER => Self::Corner,
            MAP_BEACON => Self::Beacon,
            MAP_TARGET => Self::Target,
            MAP_GRID => Self::Grid,
            MAP_CHECKPOINT => Self::Checkpoint,
            _ => return None,
        })
    }
}

impl std::fmt::Display for ItemKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Wall => "wall",
            Self::Corner => "corner",
            Self::Beacon => "beacon",
            Self::Target => "target",
            Self::Grid => "grid pose",
            Self::Checkpoint => "checkpoint",
        })
    }
}

/// Why the hub's map did not decode. `item` is the position in the published slice.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapDecodeError {
    /// The lab's size is not a positive finite number.
    #[error("the lab's size {width} x {height} m is not usable")]
    BadSize {
        /// Width given.
        width: f64,
        /// Height given.
        height: f64,
    },
    /// The lab's name is not UTF-8.
    #[error("the lab's name is not UTF-8")]
    BadName,
    /// The header announces another number of items than the slice holds.
    #[error("the header announces {announced} map items; {got} arrived")]
    ItemCount {
        /// Items announced.
        announced: u32,
        /// Items in the slice.
        got: usize,
    },
    /// The header announces another number of walls, beacons, targets or grid poses than the
    /// items hold.
    #[error("the header announces {announced} of kind {kind}; the items hold {got}")]
    KindCount {
        /// Which kind.
        kind: ItemKind,
        /// How many the header announces.
        announced: u32,
        /// How many the items hold.
        got: usize,
    },
    /// An item's kind is none of `MAP_*`.
    #[error("map item {item}: unknown kind {kind}")]
    UnknownKind {
        /// Position of the item.
        item: usize,
        /// The kind given.
        kind: u32,
    },
    /// An item holds a value that is not a finite number.
    #[error("map item {item} ({kind}) holds a value that is not a finite number")]
    NotFinite {
        /// Position of the item.
        item: usize,
        /// Its kind.
        kind: ItemKind,
    },
    /// An item's index is not the next of its kind (for a corner: not its wall's index).
    #[error("map item {item} ({kind}) has index {index}; {expected} was expected")]
    WrongIndex {
        /// Position of the item.
        item: usize,
        /// Its kind.
        kind: ItemKind,
        /// The index given.
        index: u32,
        /// The index expected.
        expected: u32,
    },
    /// A wall announces a corner count that is not a whole number of at least three.
    #[error("map item {item} (wall) announces {announced} corners; a whole number of at least 3 is needed")]
    BadCornerCount {
        /// Position of the item.
        item: usize,
        /// The count given.
        announced: f64,
    },
    /// A corner came with no wall open: before any wall, after another kind, or past the
    /// corners its wall announced.
    #[error("map item {item}: a corner outside any wall")]
    CornerWithoutWall {
        /// Position of the item.
        item: usize,
    },
    /// A wall ended with fewer corners than it announced.
    #[error("wall {wall} has {got} corners; {announced} were announced")]
    MissingCorners {
        /// The wall's index.
        wall: u32,
        /// Corners announced.
        announced: usize,
        /// Corners received.
        got: usize,
    },
}

/// Walls announce their corner count as an `f64`; anything past this is not a real wall and
/// would only make a hostile count reserve memory.
const MAX_CORNERS: f64 = 1e6;

impl Map {
    /// Decodes and checks the hub's map: the lab's size and name, the item counts the header
    /// announces, every item's kind, index and values, and each wall's corners (`MAP_WALL`
    /// followed by exactly as many `MAP_CORNER` items as it announces, at least three).
    pub fn decode(header: &MapHeader, items: &[MapItem]) -> Result<Self, MapDecodeError> {
        let (width, height) = (header.width_m, header.height_m);
        if !(width.is_finite() && height.is_finite() && width > 0.0 && height > 0.0) {
            return Err(MapDecodeError::BadSize { width, height });
        }
        let name = header.name.as_str().ok_or(MapDecodeError::BadName)?.to_owned();
        if header.item_count as usize != items.len() {
            return Err(MapDecodeError::ItemCount { announced: header.item_count, got: items.len() });
        }
        let mut map = Self { header: *header, name, width_m: width, height_m: height, ..Self::default() };
        // The corners still expected by the wall being read.
        let mut open = 0usize;
        for (i, it) in items.iter().enumerate() {
            let kind = ItemKind::from_wire(it.kind).ok_or(MapDecodeError::UnknownKind { item: i, kind: it.kind })?;
            if !(it.a.is_finite() && it.b.is_finite() && it.c.is_finite()) {
                return Err(MapDecodeError::NotFinite { item: i, kind });
            }
            if kind != ItemKind::Corner {
                map.close_wall(open)?;
                open = 0;
            }
            let expected = match kind {
                ItemKind::Wall => map.walls.len(),
                ItemKind::Corner => map.walls.len().wrapping_sub(1),
                ItemKind::Beacon => map.beacons.len(),
                ItemKind::Target => map.targets.len(),
                ItemKind::Grid => map.grid.len(),
                ItemKind::Checkpoint => map.checkpoints.len(),
            };
            if kind == ItemKind::Corner && open == 0 {
                return Err(MapDecodeError::CornerWithoutWall { item: i });
            }
            if it.index as usize != expected {
                return Err(MapDecodeError::WrongIndex { item: i, kind, index: it.index, expected: expected as u32 });
            }
            let pos = Point::new(it.a, it.b);
            match kind {
                ItemKind::Wall => {
                    if !(it.b >= 3.0 && it.b <= MAX_CORNERS && it.b.fract() == 0.0) {
                        return Err(MapDecodeError::BadCornerCount { item: i, announced: it.b });
                    }
                    open = it.b as usize;
                    map.walls.push(Wall {
                        height_m: it.a,
                        corners: Vec::with_capacity(open.min(64)),
                        obstacle: it.c != 0.0,
                    });
                }
                ItemKind::Corner => {
                    if let Some(wall) = map.walls.last_mut() {
                        wall.corners.push(pos);
                    }
                    open -= 1;
                }
                ItemKind::Beacon => map.beacons.push(Beacon { pos, height_m: it.c }),
                ItemKind::Target => map.targets.push(Circle { pos, radius_m: it.c }),
                ItemKind::Grid => map.grid.push(GridPose { pos, heading_deg: it.c }),
                ItemKind::Checkpoint => map.checkpoints.push(Checkpoint { x: it.a, y: it.b, radius: it.c }),
            }
        }
        map.close_wall(open)?;
        let counts = [
            (ItemKind::Wall, header.wall_count, map.walls.len()),
            (ItemKind::Beacon, header.beacon_count, map.beacons.len()),
            (ItemKind::Target, header.target_count, map.targets.len()),
            (ItemKind::Grid, header.grid_count, map.grid.len()),
        ];
        for (kind, announced, got) in counts {
            if announced as usize != got {
                return Err(MapDecodeError::KindCount { kind, announced, got });
            }
        }
        Ok(map)
    }

    /// Refuses the last wall when `missing` of its announced corners never came.
    fn close_wall(&self, missing: usize) -> Result<(), MapDecodeError> {
        match self.walls.last() {
            Some(w) if missing > 0 => Err(MapDecodeError::MissingCorners {
                wall: (self.walls.len() - 1) as u32,
                announced: w.corners.len() + missing,
                got: w.corners.len(),
            }),
            _ => Ok(()),
        }
    }

    /// The walls of the map file, without the scenario's obstacles.
    pub fn known_walls(&self) -> impl Iterator<Item = &Wall> {
        self.walls.iter().filter(|w| !w.obstacle)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::FixedName;

    fn item(kind: u32, index: u32, a: f64, b: f64, c: f64) -> MapItem {
        MapItem { kind, index, a, b, c }
    }

    /// A header announcing what `items` holds, as `HubCore::map_items` fills it.
    fn header_for(items: &[MapItem]) -> MapHeader {
        let count = |k| items.iter().filter(|i| i.kind == k).count() as u32;
        MapHeader {
            width_m: 10.0,
            height_m: 8.0,
            item_count: items.len() as u32,
            wall_count: count(MAP_WALL),
            beacon_count: count(MAP_BEACON),
            target_count: count(MAP_TARGET),
            grid_count: count(MAP_GRID),
            cycle_ms: 50,
            name: FixedName::new("lab").expect("fits"),
            ..MapHeader::default()
        }
    }

    fn decode(items: &[MapItem]) -> Result<Map, MapDecodeError> {
        Map::decode(&header_for(items), items)
    }

    /// Two walls (the second a scenario obstacle) and one of every other kind.
    fn every_kind() -> Vec<MapItem> {
        let mut items = vec![item(MAP_WALL, 0, 2.5, 4.0, 0.0)];
        for (x, y) in [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)] {
            items.push(item(MAP_CORNER, 0, x, y, 0.0));
        }
        items.push(item(MAP_WALL, 1, 1.0, 3.0, 1.0));
        for (x, y) in [(5.0, 5.0), (6.0, 5.0), (6.0, 6.0)] {
            items.push(item(MAP_CORNER, 1, x, y, 0.0));
        }
        items.push(item(MAP_BEACON, 0, 9.0, 7.0, 2.0));
        items.push(item(MAP_TARGET, 0, 4.0, 4.0, 0.4));
        items.push(item(MAP_GRID, 0, 3.0, 3.0, 90.0));
        items.push(item(MAP_CHECKPOINT, 0, 8.0, 2.0, 0.5));
        items
    }

    #[test]
    fn every_kind_of_item_is_decoded() {
        let map = decode(&every_kind()).expect("valid");
        assert_eq!((map.name.as_str(), map.width_m, map.height_m, map.header.cycle_ms), ("lab", 10.0, 8.0, 50));
        assert_eq!(map.walls.len(), 2);
        assert_eq!(map.walls[0].height_m, 2.5);
        assert_eq!(map.walls[0].corners[2], Point::new(2.0, 2.0));
        assert!(!map.walls[0].obstacle && map.walls[1].obstacle);
        assert_eq!(map.known_walls().count(), 1);
        assert_eq!(map.beacons, [Beacon { pos: Point::new(9.0, 7.0), height_m: 2.0 }]);
        assert_eq!(map.targets, [Circle { pos: Point::new(4.0, 4.0), radius_m: 0.4 }]);
        assert_eq!(map.grid, [GridPose { pos: Point::new(3.0, 3.0), heading_deg: 90.0 }]);
        assert_eq!(map.checkpoints, [Checkpoint { x: 8.0, y: 2.0, radius: 0.5 }]);
    }

    #[test]
    fn an_empty_lab_decodes() {
        let map = decode(&[]).expect("valid");
        assert!(map.walls.is_empty() && map.grid.is_empty());
    }

    #[test]
    fn a_bad_header_is_refused() {
        let items = every_kind();
        let h = header_for(&items);
        let bad = |h: MapHeader| Map::decode(&h, &items).expect_err("refused");
        assert_eq!(bad(MapHeader { width_m: -1.0, ..h }), MapDecodeError::BadSize { width: -1.0, height: 8.0 });
        assert!(matches!(bad(MapHeader { height_m: f64::NAN, ..h }), MapDecodeError::BadSize { .. }));
        assert_eq!(
            bad(MapHeader { name: FixedName { bytes: [0xff; ipc_types::NAME_BYTES] }, ..h }),
            MapDecodeError::BadName
        );
        assert_eq!(bad(MapHeader { item_count: 3, ..h }), MapDecodeError::ItemCount { announced: 3, got: 13 });
        assert_eq!(
            bad(MapHeader { beacon_count: 2, ..h }),
            MapDecodeError::KindCount { kind: ItemKind::Beacon, announced: 2, got: 1 }
        );
        assert_eq!(
            bad(MapHeader { wall_count: 0, ..h }),
            MapDecodeError::KindCount { kind: ItemKind::Wall, announced: 0, got: 2 }
        );
    }

    #[test]
    fn malformed_items_are_refused_with_their_position_and_kind() {
        let corner = item(MAP_CORNER, 0, 1.0, 1.0, 0.0);
        assert_eq!(decode(&[corner]), Err(MapDecodeError::CornerWithoutWall { item: 0 }));
        let wall = item(MAP_WALL, 0, 1.0, 3.0, 0.0);
        assert_eq!(
            decode(&[wall, corner, corner]),
            Err(MapDecodeError::MissingCorners { wall: 0, announced: 3, got: 2 })
        );
        let beacon = item(MAP_BEACON, 0, 1.0, 1.0, 1.0);
        assert_eq!(
            decode(&[wall, corner, corner, beacon]),
            Err(MapDecodeError::MissingCorners { wall: 0, announced: 3, got: 2 }),
            "another kind closes the wall"
        );
        assert_eq!(
            decode(&[wall, corner, corner, corner, corner]),
            Err(MapDecodeError::CornerWithoutWall { item: 4 }),
            "a corner past the announced count"
        );
        for announced in [2.0, 3.5, -4.0, 1e9] {
            let w = item(MAP_WALL, 0, 1.0, announced, 0.0);
            assert_eq!(decode(&[w]), Err(MapDecodeError::BadCornerCount { item: 0, announced }));
        }
        assert_eq!(decode(&[item(9, 0, 0.0, 0.0, 0.0)]), Err(MapDecodeError::UnknownKind { item: 0, kind: 9 }));
        let nan = item(MAP_CHECKPOINT, 0, f64::NAN, 1.0, 0.5);
        assert_eq!(decode(&[beacon, nan]), Err(MapDecodeError::NotFinite { item: 1, kind: ItemKind::Checkpoint }));
        let inf = item(MAP_GRID, 0, 1.0, 1.0, f64::INFINITY);
        assert_eq!(decode(&[inf]), Err(MapDecodeError::NotFinite { item: 0, kind: ItemKind::Grid }));
    }

    #[test]
    fn items_out_of_order_are_refused() {
        let beacon = |i| item(MAP_BEACON, i, 1.0, 1.0, 1.0);
        assert_eq!(
            decode(&[beacon(0), beacon(2)]),
            Err(MapDecodeError::WrongIndex { item: 1, kind: ItemKind::Beacon, index: 2, expected: 1 })
        );
        let mut items = every_kind();
        items[6].index = 0; // a corner of wall 1 naming wall 0
        assert_eq!(
            decode(&items),
            Err(MapDecodeError::WrongIndex { item: 6, kind: ItemKind::Corner, index: 0, expected: 1 })
        );
    }

    #[test]
    fn errors_name_the_item_and_its_kind() {
        let e = MapDecodeError::NotFinite { item: 7, kind: ItemKind::Grid };
        assert_eq!(e.to_string(), "map item 7 (grid pose) holds a value that is not a finite number");
    }
}
