//! Ciber-Rato's challenges: the scoring modes of the real simulator's `--scoring N`, and each
//! robot's state (Running, Returning, Finished) with the LEDs that drive it.
//!
//! The rules are the real simulator's (ciberRatoTools' `cbrobot.cpp`, read for its facts):
//!
//! - Every mode starts a tick with the same collision rule: a contact that begins this tick
//!   (the robot did not collide in the last scored tick) is one event, counted in
//!   `collisions` and charged `CollisionWallPenalty` if it met a wall and
//!   `CollisionRobotPenalty` if it met a robot (both if both). The competitive modes (0, 2, 3:
//!   lower is better) add the penalty; the others subtract it.
//! - **0, competitive** (the default): the score starts at 100 + 100 per target. With
//!   `VisitingLed` on over a target not yet visited, the target is visited (its bit in the
//!   visited mask) and 100 comes off; with `VisitingLed` on over no target, 5 is added per
//!   tick. Until the first visit, the arrival time follows the clock. `ReturningLed` on over a
//!   target once every target is visited starts the return (100 off; the robot becomes
//!   Returning); anywhere else it finishes the robot. While returning the score is the
//!   penalties plus ⌊100 × d / d₀⌋, d the shortest way home (to its start) for a disc of the
//!   robot's size and d₀ that distance when the return began; a returning robot that has not
//!   finished at the time limit pays 15. `EndLed` finishes the robot anywhere (over a target
//!   with every target visited it counts as an arrival).
//! - **1, control**: the lab's 2 m cells give a loop, walked once at the start from the
//!   robot's cell: east first, then at each cell straight on, else right, else left, as far as
//!   no wall (higher than the floor) cuts the way to the next cell's centre. Entering the next
//!   cell of the loop earns 10; `EndLed` finishes the robot and drops those points (the score
//!   is then its penalties).
//! - **2, mapping** and **3, planning**: the competitive score from 0 (penalties only, no
//!   target bonus), and `EndLed` the only way to finish. (The real simulator also writes the
//!   lab's reference map for its offline scripts; iwsim does not.)
//! - **4, line control (2022)**: the loop of lines in 1 m cells centred on whole metres, walked
//!   once from the start: east first, then at each cell right, else straight, else left, as
//!   far as the point half a cell that way lies on a line. Entering the loop's next cell earns
//!   10; each tick in a cell off the loop costs 10; `EndLed` leaves the penalties alone.
//! - **5, line mapping** and **6, line planning**: 10 per tick the robot's centre is more than
//!   0.5 m from every wall and line; `EndLed` finishes it with that score.
//! - **7, line control (2023)**: as 4 in 0.5 m cells, with seven turns (−135° to 135° by 45°,
//!   probed 0.2 m ahead) for the 45° lines; a robot within a cell (0.5 m on both axes) of the
//!   next one earns 10, or of the one after a corner (both counted), and a robot near no cell
//!   of the loop pays 10 a tick.
//!
//! A Finished robot stands still for the rest of the run (it is still an obstacle, and still
//! senses), and its score no longer changes.
//!
//! Where the real simulator finds no loop it exits; here the robot earns nothing.

use nalgebra::Point2;

use crate::map::{ChallengeParams, Lab};
use crate::math::{Pose, Real};

/// The real simulator's robot radius, which its target rule subtracts from a target's radius.
pub const CIBER_RATO_RADIUS_M: Real = 0.5;

/// The competitive modes' base: what a visit or a return is worth, and the score's start per
/// target (the real simulator's `BASESCORE`).
const BASE: i64 = 100;
/// Competitive: added per tick `VisitingLed` is on over no target.
const OFF_TARGET: i64 = 5;
/// Competitive: what a robot still returning at the time limit pays (`NOTFINISH_PENALTY`).
const NOT_FINISHED: i64 = 15;
/// Control and line modes: what a step of progress earns.
const PROGRESS: i64 = 10;
/// The side of a control mode's cells, metres.
const CONTROL_CELL_M: Real = 2.0;
/// Cells a control loop may have before the lab is judged to have none.
const MAX_LOOP_CELLS: usize = 10_000;
/// The distance-home grid's resolution, metres.
const HOME_GRID_M: Real = 0.1;

/// A scoring mode, numbered as the real simulator's `--scoring N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scoring {
    /// 0: visit every target, then return home (lower is better).
    #[default]
    Competitive,
    /// 1: laps of the lab's loop of 2 m cells.
    Control,
    /// 2: mapping (the competitive score with no target bonus).
    Mapping,
    /// 3: planning (as mapping).
    Planning,
    /// 4: line control (2022): laps of the loop of lines, in 1 m cells.
    LineControl2022,
    /// 5: line mapping (ticks spent away from every line).
    LineMapping,
    /// 6: line planning (as line mapping).
    LinePlanning,
    /// 7: line control (2023): laps of the loop of lines, 45° turns included, in 0.5 m cells.
    LineControl2023,
}

/// Why a scoring number was not accepted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ScoringError {
    /// Not a mode of the real simulator.
    #[error("scoring mode {0} does not exist; the real simulator's modes are 0 to 7")]
    Unknown(u32),
}

impl Scoring {
    /// Every mode iwsim has.
    pub const ALL: [Scoring; 8] = [
        Scoring::Competitive,
        Scoring::Control,
        Scoring::Mapping,
        Scoring::Planning,
        Scoring::LineControl2022,
        Scoring::LineMapping,
        Scoring::LinePlanning,
        Scoring::LineControl2023,
    ];

    /// The mode numbered `n` (the real simulator's `--scoring n`).
    pub fn from_number(n: u32) -> Result<Self, ScoringError> {
        match n {
            0 => Ok(Self::Competitive),
            1 => Ok(Self::Control),
            2 => Ok(Self::Mapping),
            3 => Ok(Self::Planning),
            4 => Ok(Self::LineControl2022),
            5 => Ok(Self::LineMapping),
            6 => Ok(Self::LinePlanning),
            7 => Ok(Self::LineControl2023),
            _ => Err(ScoringError::Unknown(n)),
        }
    }

    /// Its number.
    pub fn number(self) -> u32 {
        match self {
            Self::Competitive => 0,
            Self::Control => 1,
            Self::Mapping => 2,
            Self::Planning => 3,
            Self::LineControl2022 => 4,
            Self::LineMapping => 5,
            Self::LinePlanning => 6,
            Self::LineControl2023 => 7,
        }
    }

    /// Its name, in lower case.
    pub fn name(self) -> &'static str {
        match self {
            Self::Competitive => "competitive",
            Self::Control => "control",
            Self::Mapping => "mapping",
            Self::Planning => "planning",
            Self::LineControl2022 => "line control 2022",
            Self::LineMapping => "line mapping",
            Self::LinePlanning => "line planning",
            Self::LineControl2023 => "line control 2023",
        }
    }

    /// Whether a lower score is better (the competitive family adds penalties).
    pub fn lower_is_better(self) -> bool {
        matches!(self, Self::Competitive | Self::Mapping | Self::Planning)
    }

    fn competitive_score(self) -> bool {
        self.lower_is_better()
    }
}

/// A robot's state in the challenge, numbered and named as Ciber-Rato's (its viewers accept
/// exactly these names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u32)]
pub enum Phase {
    /// The run waits or is paused (only ever shown, never kept: see [`Phase::shown`]).
    Stopped = 0,
    /// Going about the challenge.
    #[default]
    Running = 1,
    /// Waiting for the others (the real simulator's cooperative rule, which it no longer runs:
    /// never reached).
    Waiting = 2,
    /// On the way home after visiting every target (competitive mode).
    Returning = 3,
    /// Done: it stands still and its score is final.
    Finished = 4,
    /// Removed from the run.
    Removed = 5,
}

impl Phase {
    /// The phase numbered `n`.
    pub fn from_u32(n: u32) -> Option<Self> {
        Some(match n {
            0 => Self::Stopped,
            1 => Self::Running,
            2 => Self::Waiting,
            3 => Self::Returning,
            4 => Self::Finished,
            5 => Self::Removed,
            _ => return None,
        })
    }

    /// The name Ciber-Rato's viewer datagrams carry.
    pub fn wire_name(self) -> &'static str {
        sim_model::CHALLENGE_PHASES[self as usize]
    }

    /// What a viewer is shown while the run is (`running`) or is not going: as in the real
    /// simulator, a Running or Returning robot shows Stopped while the run waits or is paused;
    /// once the run is over it keeps its state.
    pub fn shown(self, run_waits_or_paused: bool) -> Self {
        match self {
            Self::Running | Self::Returning if run_waits_or_paused => Self::Stopped,
            s => s,
        }
    }
}

/// `Action` LED bits as the challenge reads them (`ipc_types::LED_*`).
pub const LED_END: u32 = 1 << 8;
/// The returning LED.
pub const LED_RETURNING: u32 = 1 << 9;
/// The visiting LED.
pub const LED_VISITING: u32 = 1 << 10;

/// One robot's standing in the challenge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Standing {
    /// Its state.
    pub phase: Phase,
    /// Its score (the real simulator keeps it as an unsigned 32-bit number: a negative score
    /// wraps there, and its viewer datagrams print the wrapped value).
    pub score: i64,
    /// Competitive: the tick of its arrival (follows the clock until the first visit).
    pub arrival_tick: u64,
    /// Competitive: ticks since the return began.
    pub returning_ticks: u64,
    /// Collision events (contacts begun while scored).
    pub collisions: u32,
    /// Bit `k` set when target `k` has been visited (the first 64 targets).
    pub visited: u64,
}

/// What the challenge reads of one robot after a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Turn {
    /// Robot id.
    pub id: u32,
    /// Its centre of movement after the step.
    pub pose: Pose,
    /// Its move was refused by a wall this step.
    pub hit_wall: bool,
    /// Its move was refused by another body this step.
    pub hit_robot: bool,
    /// Its LED bits if its agent answered this step (`None`: they stay as they were).
    pub leds: Option<u32>,
}

#[derive(Debug, Clone)]
struct Contestant {
    standing: Standing,
    leds: u32,
    /// Its start, where the competitive return ends.
    home: Point2<Real>,
    /// What the target rule subtracts from a target's radius (the robot's half size).
    margin: Real,
    penalties: i64,
    progress: i64,
    collided: bool,
    start_returning: u64,
    dist_at_arrival: Real,
    /// Control: the loop of cells and the index of the next one.
    path: Option<Vec<(i64, i64)>>,
    next: usize,
}

/// The challenge of one run: every robot's standing under one scoring mode.
#[derive(Debug, Clone)]
pub struct Challenge {
    scoring: Scoring,
    params: ChallengeParams,
    lab: Lab,
    time_limit: u64,
    /// The contestants in id order (a sorted vector: scored in one pass every tick).
    robots: Vec<(u32, Contestant)>,
    /// Distance-home grids, by the robots' start and half size (built on a first return).
    homes: Vec<(Point2<Real>, Real, HomeGrid)>,
}

impl Challenge {
    /// A challenge on `lab` under `scoring` with `params`; `time_limit` ticks (0: none).
    pub fn new(lab: &Lab, scoring: Scoring, params: ChallengeParams, time_limit: u64) -> Self {
        Self { scoring, params, lab: lab.clone(), time_limit, robots: Vec::new(), homes: Vec::new() }
    }

    /// Its scoring mode.
    pub fn scoring(&self) -> Scoring {
        self.scoring
    }

    /// Enters robot `id`, starting at (`x`, `y`), with half size `margin` (a disc's radius).
    pub fn add(&mut self, id: u32, (x, y): (Real, Real), margin: Real) {
        let home = Point2::new(x, y);
        let penalties = match self.scoring {
            Scoring::Competitive => BASE + BASE * self.lab.targets.len() as i64,
            _ => 0,
        };
        let c = Contestant {
            standing: Standing::default(),
            leds: 0,
            home,
            margin,
            penalties,
            progress: 0,
            collided: false,
            start_returning: 0,
            dist_at_arrival: 0.0,
            path: None,
            next: 1,
        };
        match self.find(id) {
            Ok(k) => self.robots[k].1 = c,
            Err(k) => self.robots.insert(k, (id, c)),
        }
    }

    fn find(&self, id: u32) -> Result<usize, usize> {
        self.robots.binary_search_by_key(&id, |&(i, _)| i)
    }

    fn get(&self, id: u32) -> Option<&Contestant> {
        self.find(id).ok().map(|k| &self.robots[k].1)
    }

    /// Takes robot `id` out.
    pub fn remove(&mut self, id: u32) {
        if let Ok(k) = self.find(id) {
            self.robots.remove(k);
        }
    }

    /// Robot `id`'s standing.
    pub fn standing(&self, id: u32) -> Option<Standing> {
        self.get(id).map(|c| c.standing)
    }

    /// Every robot's standing, in id order.
    pub fn standings(&self) -> impl Iterator<Item = (u32, Standing)> + '_ {
        self.robots.iter().map(|(id, c)| (*id, c.standing))
    }

    /// Whether robot `id` has finished (it must stand still).
    pub fn finished(&self, id: u32) -> bool {
        self.get(id).is_some_and(|c| c.standing.phase == Phase::Finished)
    }

    /// Scores the step that ended on tick `now` (1 after the first step), then moves each
    /// robot's state on. `turns` come in increasing id order (one that does not, or names no
    /// robot of the challenge, is passed over); robots without a turn are left as they were.
    /// `clear` tells whether a straight segment meets no wall higher than the floor (the
    /// control loop's test). Returns the robots that finished in this step.
    pub fn update(&mut self, now: u64, turns: &[Turn], clear: impl Fn(Point2<Real>, Point2<Real>) -> bool) -> Vec<u32> {
        let mut finished = Vec::new();
        // Out of `self` while scoring, which reads the lab and fills the distance grids.
        let mut robots = std::mem::take(&mut self.robots);
        // Turns come in id order, as the robots are kept: one pass over both (a hub of 10,000
        // robots scores every tick).
        let mut contestants = robots.iter_mut().peekable();
        for t in turns {
            while contestants.next_if(|(id, _)| *id < t.id).is_some() {}
            let Some((_, c)) = contestants.next_if(|(id, _)| *id == t.id) else { continue };
            if let Some(leds) = t.leds {
                c.leds = leds;
            }
            self.score(c, t, now, &clear);
            let was = c.standing.phase;
            self.advance(c, t);
            if was != Phase::Finished && c.standing.phase == Phase::Finished {
                finished.push(t.id);
            }
        }
        self.robots = robots;
        finished
    }

    /// The first target whose area holds the whole robot (its centre within the target's
    /// radius less the robot's half size), as Ciber-Rato's target rule.
    fn target_at(&self, p: Point2<Real>, margin: Real) -> Option<usize> {
        self.lab.targets.iter().position(|t| (p - t.pos).norm() <= t.radius_m - margin)
    }

    fn all_visited(&self, c: &Contestant) -> bool {
        let n = self.lab.targets.len().min(64);
        let all = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
        c.standing.visited & all == all
    }

    fn score(&mut self, c: &mut Contestant, t: &Turn, now: u64, clear: &impl Fn(Point2<Real>, Point2<Real>) -> bool) {
        if matches!(c.standing.phase, Phase::Finished | Phase::Removed) {
            return;
        }
        let collided = t.hit_wall || t.hit_robot;
        if collided && !c.collided {
            let p = &self.params;
            let penalty = i64::from(p.collision_wall_penalty) * i64::from(t.hit_wall)
                + i64::from(p.collision_robot_penalty) * i64::from(t.hit_robot);
            c.penalties += if self.scoring.lower_is_better() { penalty } else { -penalty };
            c.standing.collisions += 1;
        }
        c.collided = collided;
        let p = Point2::new(t.pose.x, t.pose.y);
        let (end, returning, visiting) =
            (c.leds & LED_END != 0, c.leds & LED_RETURNING != 0, c.leds & LED_VISITING != 0);
        if self.scoring.competitive_score() {
            let target = self.target_at(p, c.margin);
            let all = self.all_visited(c);
            match c.standing.phase {
                Phase::Running => {
                    c.standing.score = c.penalties;
                    if end && target.is_some() && all {
                        c.dist_at_arrival = self.distance_home(c, p);
                        c.standing.arrival_tick = now;
                        c.start_returning = now;
                        c.standing.returning_ticks = 0;
                        c.standing.score = c.penalties + self.home_term(c, p);
                    } else if returning && target.is_some() && all {
                        c.dist_at_arrival = self.distance_home(c, p);
                        c.start_returning = now;
                        c.standing.returning_ticks = 0;
                        c.penalties -= BASE;
                        c.standing.score = c.penalties + self.home_term(c, p);
                    } else if visiting {
                        Self::visit(c, target);
                        c.standing.score = BASE + c.penalties;
                    }
                    if c.standing.visited == 0 {
                        c.standing.arrival_tick = now;
                    }
                }
                Phase::Returning => {
                    if self.time_limit > 0 && now == self.time_limit && !end {
                        c.penalties += NOT_FINISHED;
                    }
                    c.standing.returning_ticks = now - c.start_returning;
                    c.standing.score = c.penalties + self.home_term(c, p);
                    // A fresh ReturningLed over a target restarts the return (the real
                    // simulator asks that the LED came in this step's actions).
                    if returning && t.leds.is_some() && target.is_some() && all {
                        c.dist_at_arrival = self.distance_home(c, p);
                        c.start_returning = now;
                        c.standing.returning_ticks = 0;
                        c.standing.score = c.penalties + self.home_term(c, p);
                    } else if visiting {
                        Self::visit(c, target);
                        c.standing.score = c.penalties + self.home_term(c, p);
                    }
                }
                _ => {}
            }
            return;
        }
        if c.standing.phase != Phase::Running {
            return;
        }
        match self.scoring {
            Scoring::Control => {
                // Walked once, from the start (the real simulator walks it at the Start, from
                // where the robot stands then).
                let path = c.path.get_or_insert_with(|| control_loop(c.home, clear));
                if path.len() > 1 && path[c.next] == control_cell(p) {
                    c.next = (c.next + 1) % path.len();
                    c.progress += PROGRESS;
                }
            }
            Scoring::LineControl2022 => {
                let lab = &self.lab;
                let path = c.path.get_or_insert_with(|| line_loop_2022(c.home, lab));
                let cell = ((p.x + 0.5) as i64, (p.y + 0.5) as i64);
                if path.len() > 1 && path[c.next] == cell {
                    c.next = (c.next + 1) % path.len();
                    c.progress += PROGRESS;
                }
                if !path.contains(&cell) {
                    c.progress -= PROGRESS;
                }
            }
            Scoring::LineControl2023 => {
                let lab = &self.lab;
                let path = c.path.get_or_insert_with(|| line_loop_2023(c.home, lab));
                let n = path.len();
                // Cells are in half metres: near means within one on both axes.
                let near = |k: usize| {
                    let (cx, cy) = path[k % n];
                    (cx as Real - 2.0 * p.x).abs() < 1.0 && (cy as Real - 2.0 * p.y).abs() < 1.0
                };
                if n > 1 {
                    let (after, before) = (path[(c.next + 1) % n], path[(c.next + n - 1) % n]);
                    if near(c.next) {
                        c.next = if c.next + 1 >= n { 0 } else { c.next + 1 };
                        c.progress += PROGRESS;
                    } else if (after.0 - before.0).abs() + (after.1 - before.1).abs() < 2 && near(c.next + 1) {
                        // A corner cell may be cut: reaching the cell after it counts for both.
                        c.next = if c.next + 2 >= n { 0 } else { c.next + 2 };
                        c.progress += PROGRESS;
                    }
                }
                if !(0..n).any(near) {
                    c.progress -= PROGRESS;
                }
            }
            Scoring::LineMapping | Scoring::LinePlanning => {
                if self.distance_to_walls(p) > CIBER_RATO_RADIUS_M {
                    c.penalties += PROGRESS;
                }
            }
            Scoring::Competitive | Scoring::Mapping | Scoring::Planning => {}
        }
        c.standing.score = c.penalties + c.progress;
        if end {
            c.standing.score = c.penalties;
        }
    }

    fn visit(c: &mut Contestant, target: Option<usize>) {
        match target {
            Some(k) => {
                let bit = if k < 64 { 1u64 << k } else { 0 };
                if c.standing.visited & bit == 0 && bit != 0 {
                    c.standing.visited |= bit;
                    c.penalties -= BASE;
                }
            }
            None => c.penalties += OFF_TARGET,
        }
    }

    fn advance(&self, c: &mut Contestant, t: &Turn) {
        let end = c.leds & LED_END != 0;
        match c.standing.phase {
            Phase::Running if end => c.standing.phase = Phase::Finished,
            Phase::Running if self.scoring == Scoring::Competitive && c.leds & LED_RETURNING != 0 => {
                let p = Point2::new(t.pose.x, t.pose.y);
                c.standing.phase = if self.target_at(p, c.margin).is_some() && self.all_visited(c) {
                    Phase::Returning
                } else {
                    Phase::Finished
                };
            }
            Phase::Returning if end => c.standing.phase = Phase::Finished,
            _ => {}
        }
    }

    /// ⌊100 × d / d₀⌋: how much of the way home is left, in percent.
    fn home_term(&mut self, c: &Contestant, p: Point2<Real>) -> i64 {
        let d = self.distance_home(c, p);
        // The nudge keeps a whole percentage whole (100 × d / d is not always 100 in floats).
        if c.dist_at_arrival > 0.0 && d.is_finite() {
            (BASE as Real * d / c.dist_at_arrival + 1e-9).floor() as i64
        } else {
            0
        }
    }

    /// The shortest way from `p` to the robot's start for a disc of its half size (on a 0.1 m
    /// grid), metres; the straight line when the grid knows no way.
    fn distance_home(&mut self, c: &Contestant, p: Point2<Real>) -> Real {
        let k = match self.homes.iter().position(|(h, m, _)| *h == c.home && *m == c.margin) {
            Some(k) => k,
            None => {
                self.homes.push((c.home, c.margin, HomeGrid::build(&self.lab, c.home, c.margin)));
                self.homes.len() - 1
            }
        };
        self.homes[k].2.distance(p).unwrap_or_else(|| (p - c.home).norm())
    }

    /// The distance from `p` to the nearest wall or line edge, the lab's border included.
    fn distance_to_walls(&self, p: Point2<Real>) -> Real {
        let border = p.x.min(p.y).min(self.lab.width_m - p.x).min(self.lab.height_m - p.y);
        self.lab.walls.iter().map(|w| polygon_edge_distance(&w.corners, p)).fold(border.abs(), Real::min)
    }
}

/// The control mode's cell of a point (2 m cells, truncated as the real simulator's integer
/// conversion does).
fn control_cell(p: Point2<Real>) -> (i64, i64) {
    ((p.x / CONTROL_CELL_M) as i64, (p.y / CONTROL_CELL_M) as i64)
}

/// The control mode's loop from the cell of `start`: east first, then straight on, else
/// right, else left, while `clear` lets the way from a cell's centre to the next one; ends
/// back at the first cell. A lab with no such loop gives a one-cell path (nothing to earn).
fn control_loop(start: Point2<Real>, clear: &impl Fn(Point2<Real>, Point2<Real>) -> bool) -> Vec<(i64, i64)> {
    let first = control_cell(start);
    let mut path = vec![first];
    let mut cell = (first.0 + 1, first.1);
    let mut dir: i64 = 0; // degrees, a multiple of 90
    let step = |d: i64| match d.rem_euclid(360) {
        0 => (1, 0),
        90 => (0, 1),
        180 => (-1, 0),
        _ => (0, -1),
    };
    while cell != first {
        path.push(cell);
        if path.len() > MAX_LOOP_CELLS {
            return vec![first];
        }
        let centre = Point2::new(cell.0 as Real * CONTROL_CELL_M + 1.0, cell.1 as Real * CONTROL_CELL_M + 1.0);
        let Some(turn) = [0, -90, 90].into_iter().find(|&turn| {
            let (dx, dy) = step(dir + turn);
            clear(centre, centre + nalgebra::Vector2::new(dx as Real, dy as Real) * CONTROL_CELL_M)
        }) else {
            return vec![first];
        };
        dir = (dir + turn).rem_euclid(360);
        let (dx, dy) = step(dir);
        cell = (cell.0 + dx, cell.1 + dy);
    }
    path
}

/// Whether `p` lies on a line or in a wall (any wall of the lab but its border), as Ciber-Rato's
/// `isInside`.
fn on_a_wall(lab: &Lab, p: Point2<Real>) -> bool {
    lab.walls.iter().any(|w| point_in_polygon(&w.corners, p))
}

/// Follows the loop of lines from the cell of `start` in cells of `cell` metres, trying the
/// turns `turns` (degrees, relative to the way it goes) in order and taking the first whose
/// probe point, `probe` metres from the cell's centre that way, lies on a line; east first.
/// Ends back at the first cell; a lab with no loop gives a one-cell path.
fn line_loop(start: Point2<Real>, lab: &Lab, cell: Real, turns: &[i64], probe: Real) -> Vec<(i64, i64)> {
    // Cells centred on multiples of `cell`, numbered by the nearest multiple (truncating
    // x / cell + 0.5, as the real simulator's integer conversion does).
    let first = ((start.x / cell + 0.5) as i64, (start.y / cell + 0.5) as i64);
    let mut path = vec![first];
    let mut at = (first.0 + 1, first.1);
    let mut dir: i64 = 0;
    while at != first {
        path.push(at);
        if path.len() > MAX_LOOP_CELLS {
            return vec![first];
        }
        let centre = Point2::new(at.0 as Real * cell, at.1 as Real * cell);
        let Some(&turn) = turns.iter().find(|&&turn| {
            let a = ((dir + turn) as Real).to_radians();
            on_a_wall(lab, centre + nalgebra::Vector2::new(a.cos(), a.sin()) * probe)
        }) else {
            return vec![first];
        };
        dir = (dir + turn).rem_euclid(360);
        let a = (dir as Real).to_radians();
        at = ((at.0 as Real + a.cos()).round() as i64, (at.1 as Real + a.sin()).round() as i64);
    }
    path
}

/// Mode 4's loop: 1 m cells, right, straight or left, probed half a cell ahead.
fn line_loop_2022(start: Point2<Real>, lab: &Lab) -> Vec<(i64, i64)> {
    line_loop(start, lab, 1.0, &[-90, 0, 90], 0.5)
}

/// Mode 7's loop: 0.5 m cells, seven turns from −135° to 135° by 45°, probed 0.2 m ahead.
fn line_loop_2023(start: Point2<Real>, lab: &Lab) -> Vec<(i64, i64)> {
    line_loop(start, lab, 0.5, &[-135, -90, -45, 0, 45, 90, 135], 0.2)
}

/// The distance from `p` to a polygon's boundary.
fn polygon_edge_distance(corners: &[Point2<Real>], p: Point2<Real>) -> Real {
    let n = corners.len();
    (0..n).map(|i| segment_distance(corners[(i + n - 1) % n], corners[i], p)).fold(Real::INFINITY, Real::min)
}

fn segment_distance(a: Point2<Real>, b: Point2<Real>, p: Point2<Real>) -> Real {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let s = if len2 > 0.0 { ((p - a).dot(&ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p - (a + ab * s)).norm()
}

/// Shortest distances to one point over the lab's free floor for a disc of one radius: a
/// grid Dijkstra with 16 move directions (within 2.7 % of the straight line at any angle).
#[derive(Debug, Clone)]
struct HomeGrid {
    nx: usize,
    ny: usize,
    dist: Vec<f32>,
}

impl HomeGrid {
    fn build(lab: &Lab, home: Point2<Real>, radius: Real) -> Self {
        let nx = ((lab.width_m / HOME_GRID_M).ceil() as usize).max(1);
        let ny = ((lab.height_m / HOME_GRID_M).ceil() as usize).max(1);
        let centre =
            |ix: usize, iy: usize| Point2::new((ix as Real + 0.5) * HOME_GRID_M, (iy as Real + 0.5) * HOME_GRID_M);
        let walls: Vec<_> = lab.walls.iter().filter(|w| w.height_m > 0.0).collect();
        let free: Vec<bool> = (0..nx * ny)
            .map(|i| {
                let p = centre(i % nx, i / nx);
                let border = p.x.min(p.y).min(lab.width_m - p.x).min(lab.height_m - p.y);
                border >= radius
                    && walls
                        .iter()
                        .all(|w| !point_in_polygon(&w.corners, p) && polygon_edge_distance(&w.corners, p) >= radius)
            })
            .collect();
        let mut dist = vec![f32::INFINITY; nx * ny];
        let cell_of = |p: Point2<Real>| {
            let ix = ((p.x / HOME_GRID_M).floor().max(0.0) as usize).min(nx - 1);
            let iy = ((p.y / HOME_GRID_M).floor().max(0.0) as usize).min(ny - 1);
            iy * nx + ix
        };
        let start = cell_of(home);
        dist[start] = 0.0;
        let mut heap = std::collections::BinaryHeap::new();
        heap.push(Entry(0.0, start));
        const MOVES: [(i64, i64); 16] = [
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
            (2, 1),
            (2, -1),
            (-2, 1),
            (-2, -1),
            (1, 2),
            (1, -2),
            (-1, 2),
            (-1, -2),
        ];
        while let Some(Entry(d, i)) = heap.pop() {
            if d > dist[i] {
                continue;
            }
            let (x, y) = ((i % nx) as i64, (i / nx) as i64);
            for (dx, dy) in MOVES {
                let (tx, ty) = (x + dx, y + dy);
                if tx < 0 || ty < 0 || tx >= nx as i64 || ty >= ny as i64 {
                    continue;
                }
                let at = |ax: i64, ay: i64| ay as usize * nx + ax as usize;
                let j = at(tx, ty);
                // A long move needs the cells it passes free too.
                let through = if dx.abs() == 2 || dy.abs() == 2 {
                    free[at(x + dx / 2, y + dy / 2)] && free[at(x + (dx + dx.signum()) / 2, y + (dy + dy.signum()) / 2)]
                } else if dx != 0 && dy != 0 {
                    free[at(x + dx, y)] && free[at(x, y + dy)]
                } else {
                    true
                };
                if !free[j] || !through {
                    continue;
                }
                let nd = d + (((dx * dx + dy * dy) as Real).sqrt() * HOME_GRID_M) as f32;
                if nd < dist[j] {
                    dist[j] = nd;
                    heap.push(Entry(nd, j));
                }
            }
        }
        Self { nx, ny, dist }
    }

    /// The way from `p` home, or `None` where the grid knows none (the point's cell and its
    /// neighbours are all closed).
    fn distance(&self, p: Point2<Real>) -> Option<Real> {
        let ix = ((p.x / HOME_GRID_M).floor().max(0.0) as i64).min(self.nx as i64 - 1);
        let iy = ((p.y / HOME_GRID_M).floor().max(0.0) as i64).min(self.ny as i64 - 1);
        // The robot's own cell may be closed by the grid's rounding: take its best neighbour.
        let mut best = Real::INFINITY;
        for (dx, dy) in [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)] {
            let (x, y) = (ix + dx, iy + dy);
            if x < 0 || y < 0 || x >= self.nx as i64 || y >= self.ny as i64 {
                continue;
            }
            let d = Real::from(self.dist[y as usize * self.nx + x as usize]);
            if d.is_finite() {
                let c = Point2::new((x as Real + 0.5) * HOME_GRID_M, (y as Real + 0.5) * HOME_GRID_M);
                best = best.min(d + if (dx, dy) == (0, 0) { 0.0 } else { (p - c).norm() });
            }
        }
        best.is_finite().then_some(best)
    }
}

fn point_in_polygon(corners: &[Point2<Real>], p: Point2<Real>) -> bool {
    let n = corners.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (corners[i], corners[(i + n - 1) % n]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
    }
    inside
}

#[derive(PartialEq)]
struct Entry(f32, usize);
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    // A min-heap on the distance (ties by cell, so the order is total and deterministic).
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other.0.total_cmp(&self.0).then_with(|| other.1.cmp(&self.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::World;
    use crate::map::{Params, Target, Wall};

    fn lab(w: Real, h: Real, walls: Vec<Wall>, targets: Vec<Target>) -> Lab {
        Lab { name: "challenge".into(), width_m: w, height_m: h, walls, beacons: vec![], targets }
    }

    fn turn(id: u32, x: Real, y: Real, leds: u32) -> Turn {
        Turn { id, pose: Pose::new(x, y, 0.0), hit_wall: false, hit_robot: false, leds: Some(leds) }
    }

    fn open(_: Point2<Real>, _: Point2<Real>) -> bool {
        true
    }

    /// One target of radius 1 at (9, 3), the robot's start at (3, 3): the real simulator's
    /// trace of this course (noise off), step for step.
    #[test]
    fn a_competitive_course_scores_as_the_real_simulator_traced_it() {
        let target = Target { pos: Point2::new(9.0, 3.0), radius_m: 1.0 };
        let mut c = Challenge::new(&lab(20.0, 6.0, vec![], vec![target]), Scoring::Competitive, Default::default(), 0);
        c.add(1, (3.0, 3.0), CIBER_RATO_RADIUS_M);
        let score = |c: &Challenge| c.standing(1).expect("in").score;
        // 100 + 100 per target from the first step.
        c.update(1, &[turn(1, 3.0, 3.0, 0)], open);
        assert_eq!(score(&c), 200);
        // VisitingLed over no target: 5 a tick, shown on top of the base 100.
        c.update(2, &[turn(1, 4.0, 3.0, LED_VISITING)], open);
        assert_eq!(score(&c), 305);
        c.update(3, &[turn(1, 4.0, 3.0, LED_VISITING)], open);
        assert_eq!(score(&c), 310);
        c.update(4, &[turn(1, 5.0, 3.0, 0)], open);
        assert_eq!(score(&c), 210);
        // The arrival time follows the clock until the first visit.
        c.update(56, &[turn(1, 8.4, 3.0, 0)], open);
        assert_eq!(c.standing(1).expect("in").arrival_tick, 56);
        // 0.6 m from the centre is outside: a radius-1 target holds a 0.5 m robot within 0.5.
        c.update(57, &[turn(1, 8.4, 3.0, LED_VISITING)], open);
        assert_eq!((score(&c), c.standing(1).expect("in").visited), (315, 0));
        c.update(58, &[turn(1, 8.5, 3.0, LED_VISITING)], open);
        let s = c.standing(1).expect("in");
        // The visit takes 100 off; the score shows the base 100 on top while the LED is on.
        assert_eq!((s.score, s.visited, s.arrival_tick), (100 + 215 - 100, 1, 57));
        c.update(59, &[turn(1, 8.5, 3.0, 0)], open);
        assert_eq!(score(&c), 115);
        // ReturningLed over the target with every target visited: the return begins (100 off,
        // plus the share of the way home still to go, all of it).
        c.update(60, &[turn(1, 9.0, 3.0, LED_RETURNING)], open);
        let s = c.standing(1).expect("in");
        assert_eq!((s.phase, s.score, s.returning_ticks), (Phase::Returning, 15 + 100, 0));
        // Half way home on a straight, open way: half the share.
        c.update(70, &[turn(1, 6.0, 3.0, LED_RETURNING)], open);
        let s = c.standing(1).expect("in");
        assert_eq!(s.returning_ticks, 10);
        assert!((63..=66).contains(&s.score), "{}", s.score);
        // EndLed at home: finished, the score frozen.
        c.update(80, &[turn(1, 3.0, 3.0, LED_END)], open);
        let s = c.standing(1).expect("in");
        assert_eq!(s.phase, Phase::Finished);
        assert!((15..=16).contains(&s.score), "{}", s.score);
        c.update(81, &[Turn { hit_wall: true, ..turn(1, 9.0, 3.0, LED_VISITING) }], open);
        assert_eq!(c.standing(1), Some(s));
    }

    #[test]
    fn returning_anywhere_but_a_visited_course_finishes_the_robot() {
        let target = Target { pos: Point2::new(9.0, 3.0), radius_m: 1.0 };
        let mut c = Challenge::new(&lab(20.0, 6.0, vec![], vec![target]), Scoring::Competitive, Default::default(), 0);
        c.add(1, (3.0, 3.0), 0.5);
        c.add(2, (3.0, 5.0), 0.5);
        // Robot 1 on the target but nothing visited; robot 2 nowhere near it.
        c.update(1, &[turn(1, 9.0, 3.0, LED_RETURNING), turn(2, 3.0, 5.0, LED_RETURNING)], open);
        for id in [1, 2] {
            assert_eq!(c.standing(id).expect("in").phase, Phase::Finished);
            assert!(c.finished(id));
        }
    }

    #[test]
    fn a_returning_robot_pays_for_not_finishing_by_the_time_limit() {
        let target = Target { pos: Point2::new(9.0, 3.0), radius_m: 1.0 };
        let mut c = Challenge::new(&lab(20.0, 6.0, vec![], vec![target]), Scoring::Competitive, Default::default(), 10);
        c.add(1, (3.0, 3.0), 0.5);
        c.update(1, &[turn(1, 9.0, 3.0, LED_VISITING)], open);
        c.update(2, &[turn(1, 9.0, 3.0, LED_RETURNING)], open);
        assert_eq!(c.standing(1).expect("in").score, 100);
        c.update(9, &[turn(1, 9.0, 3.0, LED_RETURNING)], open);
        assert_eq!(c.standing(1).expect("in").score, 100);
        c.update(10, &[turn(1, 9.0, 3.0, LED_RETURNING)], open);
        assert_eq!(c.standing(1).expect("in").score, 115);
    }

    #[test]
    fn a_contact_costs_once_however_long_it_lasts_and_each_kind_its_own_penalty() {
        let params = ChallengeParams { collision_wall_penalty: 5, collision_robot_penalty: 7, ..Default::default() };
        let mut c = Challenge::new(&lab(20.0, 6.0, vec![], vec![]), Scoring::Control, params, 0);
        c.add(1, (3.0, 3.0), 0.5);
        let hit = |wall, robot| Turn { hit_wall: wall, hit_robot: robot, ..turn(1, 3.0, 3.0, 0) };
        for (now, t) in [(1, hit(true, false)), (2, hit(true, false)), (3, hit(true, false))] {
            c.update(now, &[t], open);
        }
        assert_eq!((c.standing(1).expect("in").score, c.standing(1).expect("in").collisions), (-5, 1));
        c.update(4, &[hit(false, false)], open);
        c.update(5, &[hit(true, true)], open);
        assert_eq!((c.standing(1).expect("in").score, c.standing(1).expect("in").collisions), (-17, 2));
        // The competitive family adds what the others subtract.
        let mut c = Challenge::new(&lab(20.0, 6.0, vec![], vec![]), Scoring::Mapping, params, 0);
        c.add(1, (3.0, 3.0), 0.5);
        c.update(1, &[hit(false, true)], open);
        assert_eq!(c.standing(1).expect("in").score, 7);
    }

    /// An 8 × 6 lab with a block over the two middle cells: the 2 m cells ring it.
    fn ring() -> (Lab, World) {
        let l = lab(8.0, 6.0, vec![Wall::rectangle(2.1, 2.1, 5.9, 3.9, 1.0)], vec![]);
        let w = World::new(&l, Params::default(), 1).expect("world");
        (l, w)
    }

    #[test]
    fn the_control_loop_rings_the_lab_and_pays_each_cell_in_order() {
        let (l, w) = ring();
        let clear = |a, b| w.segment_clear(a, b);
        let path = control_loop(Point2::new(1.0, 1.0), &clear);
        assert_eq!(path, vec![(0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (3, 2), (2, 2), (1, 2), (0, 2), (0, 1)]);
        let mut c = Challenge::new(&l, Scoring::Control, Default::default(), 0);
        c.add(1, (1.0, 1.0), 0.5);
        // The start cell, then one cell ahead, back, and ahead again: the loop's next cell pays
        // once, going back pays nothing.
        for (now, x) in [(1, 1.0), (2, 2.5), (3, 3.0), (4, 1.5), (5, 3.5), (6, 5.0)] {
            c.update(now, &[turn(1, x, 1.0, 0)], clear);
        }
        assert_eq!(c.standing(1).expect("in").score, 20);
        // Round the whole ring back to the start: one lap, 10 cells.
        for (k, (x, y)) in
            [(7.0, 1.0), (7.0, 3.0), (7.0, 5.0), (5.0, 5.0), (3.0, 5.0), (1.0, 5.0), (1.0, 3.0), (1.0, 1.0)]
                .into_iter()
                .enumerate()
        {
            c.update(7 + k as u64, &[turn(1, x, y, 0)], clear);
        }
        assert_eq!(c.standing(1).expect("in").score, 100);
        // EndLed drops the lap points: the score is the penalties alone.
        c.update(20, &[turn(1, 1.0, 1.0, LED_END)], clear);
        let s = c.standing(1).expect("in");
        assert_eq!((s.phase, s.score), (Phase::Finished, 0));
    }

    #[test]
    fn a_lab_without_a_loop_pays_nothing() {
        let l = lab(8.0, 2.0, vec![], vec![]);
        let w = World::new(&l, Params::default(), 1).expect("world");
        // One row of cells: east to the wall, then no way straight, right or left.
        assert_eq!(control_loop(Point2::new(1.0, 1.0), &|a, b| w.segment_clear(a, b)), vec![(0, 0)]);
    }

    /// A rectangle of 0.2 m lines round (1, 1)–(5, 4).
    fn line_ring() -> Lab {
        let walls = vec![
            Wall::rectangle(0.9, 0.9, 5.1, 1.1, 0.0),
            Wall::rectangle(0.9, 3.9, 5.1, 4.1, 0.0),
            Wall::rectangle(0.9, 0.9, 1.1, 4.1, 0.0),
            Wall::rectangle(4.9, 0.9, 5.1, 4.1, 0.0),
        ];
        lab(7.0, 6.0, walls, vec![])
    }

    #[test]
    fn the_2022_line_loop_follows_the_lines_in_whole_metres_and_pays_cells_in_order() {
        let l = line_ring();
        let path = line_loop_2022(Point2::new(1.0, 1.0), &l);
        let mut want: Vec<(i64, i64)> = (1..=5).map(|x| (x, 1)).collect();
        want.extend((2..=4).map(|y| (5, y)));
        want.extend((1..=4).rev().map(|x| (x, 4)));
        want.extend((2..=3).rev().map(|y| (1, y)));
        assert_eq!(path, want);
        let mut c = Challenge::new(&l, Scoring::LineControl2022, Default::default(), 0);
        c.add(1, (1.0, 1.0), 0.5);
        // The start cell pays nothing (the next is (2, 1)); each next cell 10, a lap 140.
        let mut now = 1;
        for &(x, y) in path.iter().chain(&path[..1]) {
            c.update(now, &[turn(1, x as Real, y as Real, 0)], open);
            now += 1;
        }
        assert_eq!(c.standing(1).expect("in").score, 140);
        // Off the loop (the middle of the ring): 10 a tick.
        for _ in 0..3 {
            c.update(now, &[turn(1, 3.0, 2.5, 0)], open);
            now += 1;
        }
        assert_eq!(c.standing(1).expect("in").score, 110);
        c.update(now, &[turn(1, 3.0, 2.5, LED_END)], open);
        assert_eq!(c.standing(1).expect("in").score, 0);
    }

    #[test]
    fn the_2023_line_loop_walks_half_metres_and_a_cut_corner_counts_for_both() {
        let l = line_ring();
        let path = line_loop_2023(Point2::new(1.0, 1.0), &l);
        // 9 cells along the bottom, 6 up the right, 8 along the top, 5 down the left.
        assert_eq!(path.len(), 28, "{path:?}");
        assert_eq!((path[0], path[8], path[14], path[22]), ((2, 2), (10, 2), (10, 8), (2, 8)));
        let mut c = Challenge::new(&l, Scoring::LineControl2023, Default::default(), 0);
        c.add(1, (1.0, 1.0), 0.5);
        let mut now = 1;
        // A lap through the cells' centres: 28 cells, 280.
        for &(x, y) in path.iter().skip(1).chain(&path[..1]) {
            c.update(now, &[turn(1, x as Real / 2.0, y as Real / 2.0, 0)], open);
            now += 1;
        }
        assert_eq!(c.standing(1).expect("in").score, 280);
        // Near no cell of the loop: 10 a tick.
        c.update(now, &[turn(1, 3.0, 2.5, 0)], open);
        assert_eq!(c.standing(1).expect("in").score, 270);
        // A sharp turn (the cells before and after the next one touch): reaching the cell
        // after it without passing near it counts for both, at 10.
        let mut c = Challenge::new(&l, Scoring::LineControl2023, Default::default(), 0);
        c.add(1, (0.0, 0.0), 0.5);
        c.robots[0].1.path = Some(vec![(0, 0), (1, 0), (2, 0), (1, 1), (0, 1)]);
        c.update(1, &[turn(1, 0.5, 0.0, 0)], open);
        assert_eq!((c.standing(1).expect("in").score, c.robots[0].1.next), (10, 2));
        // At (0.6, 0.8) in half metres: within one of (1, 1), not of (2, 0).
        c.update(2, &[turn(1, 0.3, 0.4, 0)], open);
        assert_eq!((c.standing(1).expect("in").score, c.robots[0].1.next), (20, 4));
    }

    #[test]
    fn line_mapping_pays_each_tick_away_from_every_line() {
        let line = Wall::rectangle(0.0, 2.9, 10.0, 3.1, 0.0);
        let mut c = Challenge::new(&lab(10.0, 6.0, vec![line], vec![]), Scoring::LineMapping, Default::default(), 0);
        c.add(1, (2.0, 3.0), 0.5);
        // On the line, 0.5 m from it (not more), then 1 m off: only the last pays.
        for (now, y) in [(1, 3.0), (2, 3.6), (3, 4.1)] {
            c.update(now, &[turn(1, 2.0, y, 0)], open);
        }
        assert_eq!(c.standing(1).expect("in").score, 10);
        // Near the border counts as near a wall.
        c.update(4, &[turn(1, 2.0, 5.6, 0)], open);
        assert_eq!(c.standing(1).expect("in").score, 10);
    }

    #[test]
    fn the_way_home_goes_round_walls() {
        // A wall between the robot and home: the way round is longer than the straight line.
        let l = lab(10.0, 10.0, vec![Wall::rectangle(4.0, 0.0, 6.0, 8.0, 1.0)], vec![]);
        let g = HomeGrid::build(&l, Point2::new(2.0, 2.0), 0.5);
        let d = g.distance(Point2::new(8.0, 2.0)).expect("a way");
        // Up to 0.5 m off the wall's top corners, across, and down.
        let shortest = 2.0 * 1.5f64.hypot(6.5) + 3.0;
        assert!(d > 6.0 * 1.5, "{d}");
        assert!((d - shortest).abs() / shortest < 0.05, "{d} vs {shortest}");
        assert!(g.distance(Point2::new(2.0, 2.0)).expect("home") < 0.1);
    }

    #[test]
    fn scoring_numbers_round_trip_and_the_missing_ones_say_so() {
        for s in Scoring::ALL {
            assert_eq!(Scoring::from_number(s.number()), Ok(s));
        }
        assert_eq!(Scoring::ALL.map(Scoring::number), [0, 1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(Scoring::from_number(8), Err(ScoringError::Unknown(8)));
        assert_eq!(Phase::Returning.shown(true), Phase::Stopped);
        assert_eq!(Phase::Finished.shown(true), Phase::Finished);
        assert_eq!(Phase::Returning.shown(false), Phase::Returning);
        assert_eq!(Phase::from_u32(4).map(Phase::wire_name), Some("Finished"));
    }
}
