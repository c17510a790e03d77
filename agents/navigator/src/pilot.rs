//! A navigator that keeps to the traffic rule: each tick it hears the other chairs, lets the
//! rule ([`crate::traffic`]) decide whether to drive, wait, or pull over, has the navigator
//! carry that out, and says where it is. Without I/O: the agent feeds it from a hub, the
//! tests from the world model in-process.

use crate::geom::{Footprint, Pose, V2};
use crate::manoeuvre;
use crate::navigator::{NavEvent, Navigator};
use crate::sensors::Input;
use crate::traffic::{self, Decision, MAX_CLAIM_ZONES, MEET_M, State, Traffic};
use crate::zones::Zones;

/// Speed of the pull-over, m/s: a little below cruising, a few metres from another chair.
const PULL_OVER_SPEED: f64 = 0.25;
/// A chair that has stood this long (seconds) is planned round whatever it says.
const STANDING_S: f64 = 2.0;
/// Say where we are every this many ticks (twice a second at 100 ms) when no other chair is
/// near...
const SAY_EVERY_FAR: u64 = 5;
/// ...and every tick when one is within this distance, metres (its readings of us are
/// matched to what we say).
const NEAR_M: f64 = MEET_M + 3.0;
/// One-lane zones this far ahead on the path are claimed, metres: far enough that the claim
/// has settled before the chair must stop for it.
const CLAIM_AHEAD_M: f64 = 3.0;
/// Zones on the path with less than this between them (path length, metres) are claimed
/// together: there is no room to wait between them out of both.
const WAIT_ROOM_M: f64 = 2.0;
/// A chair waiting for a zone stops with its front this far short of it, metres: out of the
/// way of a chair turning out of it.
const STOP_SHORT_M: f64 = 0.8;
/// The way out of a zone must be clear of waiting chairs for this far (path length, metres)
/// before the chair goes in: a chair never stands in a zone waiting for room beyond it.
const EXIT_ROOM_M: f64 = 1.6;
/// A chair that has not moved for this long (seconds) while it has somewhere to go is stuck.
const STUCK_S: f64 = 5.0;
/// A yielder whose own path turns off by this much (radians) within [`TURN_OFF_M`] of path,
/// keeping [`TURN_OFF_GAP_M`] from the other where it stands, goes on instead of pulling over:
/// it is leaving the other's way (swinging out to turn into a doorway).
const TURN_OFF_RAD: f64 = 1.0;
/// See [`TURN_OFF_RAD`], metres.
const TURN_OFF_M: f64 = 3.0;
/// See [`TURN_OFF_RAD`], metres.
const TURN_OFF_GAP_M: f64 = 0.15;
/// A chair in a negotiation (waiting for another to pull over, parked for it, passing it)
/// that has not moved for this long (seconds) is stuck all the same: the other is held up
/// by a third (ward, 6 chairs, seed 4: five chairs stood two minutes, each waiting on one
/// of the others, and none said it was stuck).
const STUCK_NEGOTIATING_S: f64 = 15.0;
/// A chair queued for a doorway behind a chair that is not stuck is not stuck for this long
/// (seconds): a few chairs' passages through it.
const ZONE_QUEUE_S: f64 = 60.0;
/// Stuck chairs this near each other (axle to axle, metres) settle who backs off.
const BACKOFF_NEAR_M: f64 = 4.5;
/// A chair backs off this far along the way it came (metres), at this speed (m/s)...
const BACKOFF_M: f64 = 2.0;
/// See [`BACKOFF_M`].
const BACKOFF_SPEED: f64 = 0.15;
/// The way back ends where the chair's heading then differs from its heading now by more
/// than this, radians.
const BACKOFF_TURN_RAD: f64 = 0.5;
/// ...and then stands this long (seconds), so that the others go through first.
const BACKOFF_HOLD_S: f64 = 6.0;
/// A chair backing off or giving way that has not moved for this long (seconds) stops
/// trying to.
const STALLED_S: f64 = 4.0;
/// A chair that has heard this many others within [`CROWD_RADIUS_M`] may not hear them all
/// (a tick's inbox holds 400 bytes, about eight messages): it backs off rather than drive to
/// a refuge.
const CROWD_PEERS: usize = 7;
/// See [`CROWD_PEERS`]: the hub's default message range, metres.
const CROWD_RADIUS_M: f64 = 8.0;
/// A chair giving way drives to its refuge at this speed (m/s)...
const REFUGE_SPEED: f64 = 0.2;
/// ...and stands there this long (seconds): long enough for the others to get past.
const REFUGE_HOLD_S: f64 = 15.0;
/// Where the chair has been is kept every this many metres...
const TRAIL_STEP_M: f64 = 0.1;
/// ...for this many points.
const TRAIL_LEN: usize = 60;

/// Giving way out of a deadlock: to a refuge, or back along the way the chair came (known to
/// be free of walls and what it has seen), then standing a while.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Backoff {
    /// Driving back (or to a refuge) until it is driven or this time (seconds) is up, then
    /// standing for the given seconds.
    Driving { until: f64, hold_s: f64 },
    /// Standing until this time, seconds.
    Holding(f64),
}

/// What a tick produced.
#[derive(Debug, Clone, PartialEq)]
pub struct PilotOutput {
    /// Wheel powers, left and right.
    pub powers: [f64; 2],
    /// What to say this tick, if anything.
    pub say: Option<String>,
    /// What the navigator reported.
    pub events: Vec<NavEvent>,
    /// What the traffic rule did, for the user.
    pub notes: Vec<String>,
}

/// The navigator and its side of the traffic rule.
#[derive(Debug)]
pub struct Pilot {
    name: String,
    nav: Navigator,
    traffic: Traffic,
    said: Option<State>,
    /// What this meeting asks of us as the yielder was noted ("no room to pull over", or
    /// "turning off"), once per meeting.
    no_room_said: bool,
    /// The map's one-lane zones: none unless the zone rule is on ([`Pilot::with_zone_claims`]).
    zones: Zones,
    /// Zones ahead that we wait for: their centres, and how far ahead along the path the first
    /// one began when we stopped.
    zone_wait: Option<Vec<V2>>,
    /// A zone ahead that the path only passes by but another chair holds (it is turning out
    /// of or into a doorway there): its centre, while we stand short of it.
    pass_wait: Option<V2>,
    /// "Cannot say the claim" was logged.
    claim_too_long_said: bool,
    /// Where the chair has been, oldest first, [`TRAIL_STEP_M`] apart.
    trail: Vec<Pose>,
    /// Where the chair stands, and since when (seconds).
    still: Option<(Pose, f64)>,
    /// Backing off out of a deadlock.
    backoff: Option<Backoff>,
}

impl Pilot {
    /// A pilot called `name` (as it registered with the hub) for `nav`.
    pub fn new(name: &str, nav: Navigator) -> Self {
        let traffic = Traffic::new(name);
        let traffic = if nav.config().keep_right > 0.0 { traffic.keeping_right() } else { traffic };
        Self {
            name: name.to_owned(),
            traffic,
            nav,
            said: None,
            no_room_said: false,
            zones: Zones::none(),
            zone_wait: None,
            pass_wait: None,
            claim_too_long_said: false,
            trail: Vec::new(),
            still: None,
            backoff: None,
        }
    }

    /// Keeps where the chair has been, and since when it has stood.
    fn note_motion(&mut self, me: Pose, now: f64) {
        // Backing off retraces the trail: it adds nothing to it.
        if self.backoff.is_none() && self.trail.last().is_none_or(|p| (p.pos() - me.pos()).norm() >= TRAIL_STEP_M) {
            if self.trail.len() == TRAIL_LEN {
                self.trail.remove(0);
            }
            self.trail.push(me);
        }
        let moved = self.still.is_none_or(|(p, _)| {
            (p.pos() - me.pos()).norm() > traffic::STILL_M
                || crate::geom::wrap_rad(p.theta - me.theta).abs() > traffic::STILL_RAD
        });
        if moved {
            self.still = Some((me, now));
        }
    }

    /// Whether the chair has not moved for `s` seconds.
    fn stood_for(&self, now: f64, s: f64) -> bool {
        self.still.is_some_and(|(_, since)| now - since >= s)
    }

    /// Whether the chair is stuck: it has somewhere to go and has not moved for [`STUCK_S`]
    /// (in no negotiation going its way) or for [`STUCK_NEGOTIATING_S`] (in one).
    ///
    /// A chair queued for a doorway ([`Pilot::zone_gate`]) behind a chair that is not stuck
    /// itself is not stuck either, for up to [`ZONE_QUEUE_S`]: the queue moves. (Before, it
    /// said `stuck` after 5 s, which let its claim go; with no claim it drove on, claimed
    /// again at the back of the queue and stopped, every other tick for minutes.)
    fn stuck(&self, now: f64) -> bool {
        !self.nav.finished()
            && (!self.queued(now) || self.stood_for(now, ZONE_QUEUE_S))
            && ((self.traffic.may_be_stuck() && self.stood_for(now, STUCK_S))
                || (self.traffic.negotiating() && self.stood_for(now, STUCK_NEGOTIATING_S)))
    }

    /// Whether it waits for a doorway that a chair not stuck has (or wanted first).
    fn queued(&self, now: f64) -> bool {
        if let Some(centre) = self.pass_wait {
            let z = self.zones.named(centre);
            return z.and_then(|z| self.holder(z, now)).is_some_and(|p| p.state != State::Stuck);
        }
        if self.zone_wait.is_none() {
            return false;
        }
        let zones = &self.zones;
        let Some(by) = self.traffic.zone_blocker(|c| zones.named(c)) else { return false };
        self.traffic.peers().iter().any(|p| p.name == by && p.state != State::Stuck)
    }

    /// Of the chairs stuck near each other, all but the one whose name sorts first back
    /// off; each side decides from what it heard, so two never wait for each other.
    fn should_back_off(&self, me: Pose) -> bool {
        self.traffic.peers().iter().any(|p| {
            p.state == State::Stuck && (p.pose.pos() - me.pos()).norm() <= BACKOFF_NEAR_M && p.name < self.name
        })
    }

    /// Whether [`CROWD_PEERS`] or more other chairs have been heard within
    /// [`CROWD_RADIUS_M`]: then some may go unheard.
    fn in_crowd(&self, me: Pose) -> bool {
        let near = self.traffic.peers().iter().filter(|p| (p.pose.pos() - me.pos()).norm() <= CROWD_RADIUS_M);
        near.count() >= CROWD_PEERS
    }

    /// The way back along the trail, [`BACKOFF_M`] of it (reversing, the chair's heading as
    /// it drove there), from where it stands.
    fn way_back(&self, me: Pose) -> Vec<crate::hybrid::PathPose> {
        use crate::hybrid::{Motion, PathPose};
        let mut path = vec![PathPose { pose: me, motion: Motion::Start }];
        let mut along = 0.0;
        let mut last = me.pos();
        for p in self.trail.iter().rev() {
            let d = (p.pos() - last).norm();
            if d < 0.5 * TRAIL_STEP_M {
                continue;
            }
            // Only as far back as the chair drove with about the heading it has: a turn on
            // the way is not retraced well in reverse (it swung a corner into a wall).
            if crate::geom::wrap_rad(p.theta - me.theta).abs() > BACKOFF_TURN_RAD {
                break;
            }
            along += d;
            last = p.pos();
            path.push(PathPose { pose: *p, motion: Motion::Reverse(0.0) });
            if along >= BACKOFF_M {
                break;
            }
        }
        path
    }

    /// The deadlock breaker, after the traffic rule: a stuck chair says so; if another stuck
    /// chair near it goes first, it gives way in a refuge (a room near by), or backs off
    /// along the way it came, and stands aside a while. Whether it is giving way (the
    /// traffic rule's decision is then set aside).
    fn back_off(&mut self, me: Pose, now: f64, notes: &mut Vec<String>) -> bool {
        match self.backoff {
            // Driving back or to a refuge ends where the chair is once it takes much longer
            // than the way should (off its line), or once the chair has stood STALLED_S (its
            // safety layer holds it short of a chair or a wall).
            Some(Backoff::Driving { until, .. })
                if self.nav.manoeuvring() && now < until && !self.stood_for(now, STALLED_S) =>
            {
                true
            }
            Some(Backoff::Driving { hold_s, .. }) => {
                self.backoff = Some(Backoff::Holding(now + hold_s));
                self.nav.hold();
                // Driven back: the trail now ends at its point nearest where the chair stands.
                if let Some(k) = self
                    .trail
                    .iter()
                    .enumerate()
                    .min_by(|a, b| (a.1.pos() - me.pos()).norm().total_cmp(&(b.1.pos() - me.pos()).norm()))
                    .map(|(k, _)| k)
                {
                    self.trail.truncate(k + 1);
                }
                notes.push(format!("backed off at t {now:.1} s; letting the others through"));
                true
            }
            Some(Backoff::Holding(until)) if now < until => {
                self.nav.hold();
                true
            }
            Some(Backoff::Holding(_)) => {
                self.backoff = None;
                self.still = Some((me, now));
                self.traffic.set_stuck(false);
                self.nav.resume();
                notes.push(format!("going on at t {now:.1} s after backing off"));
                false
            }
            None => {
                let stuck = self.stuck(now);
                self.traffic.set_stuck(stuck);
                if !stuck || !self.should_back_off(me) {
                    return false;
                }
                // Best out of the way altogether: into a room or a hall near by. Not in a
                // crowd, though: a chair hears at most 400 bytes a tick, so among this many
                // others some go unheard, and a long manoeuvre among chairs it does not know
                // of swings its corners into them (the ward with 20 chairs: two chairs bound
                // for refuges in one room, one unheard by the other, touched 120 times).
                let others: Vec<V2> = self.traffic.peers().iter().map(|p| p.pose.pos()).collect();
                let refuge = if self.in_crowd(me) { None } else { self.nav.path_to_refuge(&others) };
                if let Some(path) = refuge {
                    let to = path.last().map_or(me.pos(), |p| p.pose.pos());
                    let length: f64 = path.windows(2).map(|w| (w[1].pose.pos() - w[0].pose.pos()).norm()).sum();
                    notes.push(format!(
                        "stuck at t {now:.1} s near another stuck chair; giving way in a refuge at {}",
                        place(to)
                    ));
                    self.traffic.release_zones();
                    self.zone_wait = None;
                    self.nav.manoeuvre(&path, REFUGE_SPEED);
                    self.still = Some((me, now));
                    let until = now + 10.0 + 3.0 * length / REFUGE_SPEED;
                    self.backoff = Some(Backoff::Driving { until, hold_s: REFUGE_HOLD_S });
                    return true;
                }
                let path = self.way_back(me);
                // Less than half a metre back makes no room.
                if path.len() < 6 {
                    return false;
                }
                notes.push(format!("stuck at t {now:.1} s near another stuck chair; backing off"));
                self.traffic.release_zones();
                self.zone_wait = None;
                self.nav.manoeuvre(&path, BACKOFF_SPEED);
                self.still = Some((me, now));
                let until = now + 3.0 * BACKOFF_M / BACKOFF_SPEED;
                self.backoff = Some(Backoff::Driving { until, hold_s: BACKOFF_HOLD_S });
                true
            }
        }
    }

    /// Turns the zone rule on: doorways and other one-lane zones of the map
    /// ([`crate::zones`]) are claimed by message before they are entered ([`Traffic::want_zones`]).
    pub fn with_zone_claims(mut self) -> Self {
        self.zones = Zones::find(&self.nav.model().statics, &self.nav.model().footprint);
        self
    }

    /// The map's one-lane zones (none while the zone rule is off).
    pub fn zones(&self) -> &Zones {
        &self.zones
    }

    /// The zones the chair's body is in, at `pose`.
    fn zones_under(&self, pose: Pose) -> Vec<usize> {
        let fp = self.nav.model().footprint;
        let (c, s) = (pose.theta.cos(), pose.theta.sin());
        let mut out = Vec::new();
        for (a, b) in [(0.0, 0.0), (fp.front, fp.half), (fp.front, -fp.half), (-fp.rear, fp.half), (-fp.rear, -fp.half)]
        {
            let p = V2::new(pose.x + a * c - b * s, pose.y + a * s + b * c);
            if let Some(z) = self.zones.at(p)
                && !out.contains(&z)
            {
                out.push(z);
            }
        }
        out
    }

    /// Whether the way out of `ids` along the path (the first [`EXIT_ROOM_M`] after the last
    /// of them) is clear of chairs that stand waiting. A waiting chair that wants the same
    /// zones is in the queue behind us and is no obstacle to wait for.
    fn way_out_clear(&self, ids: &[usize]) -> bool {
        let own = self.nav.model().footprint;
        let zones = &self.zones;
        let waiting: Vec<_> = self
            .traffic
            .peers()
            .iter()
            .filter(|p| p.state == State::Wait)
            .filter(|p| {
                !p.claim
                    .as_ref()
                    .is_some_and(|c| c.zones.iter().any(|&z| zones.named(z).is_some_and(|k| ids.contains(&k))))
            })
            .collect();
        if waiting.is_empty() {
            return true;
        }
        let mut out_for: Option<f64> = None;
        let mut last = None::<V2>;
        for p in self.nav.path() {
            let in_ids = zones.at(p.pos()).is_some_and(|k| ids.contains(&k));
            if let (Some(d), Some(l)) = (out_for.as_mut(), last) {
                *d += (p.pos() - l).norm();
            }
            last = Some(p.pos());
            if in_ids {
                out_for = Some(0.0);
                continue;
            }
            let Some(d) = out_for else { continue };
            if d > EXIT_ROOM_M {
                break;
            }
            if waiting.iter().any(|w| (w.pose.pos() - p.pos()).norm() < own.half + w.footprint.half + 0.3) {
                return false;
            }
        }
        true
    }

    /// The zones to claim on the path ahead: the first within [`CLAIM_AHEAD_M`] and those
    /// that follow it closer than [`WAIT_ROOM_M`]; and how far ahead the first begins. Only
    /// zones the path goes through count ([`Pilot::zones_through`]): one it passes by along
    /// the corridor is the corridor, where the lanes and the two-chair rule keep chairs apart.
    fn zones_ahead(&self, me: Pose, path: &[Pose], through: &[usize]) -> Option<(Vec<usize>, f64)> {
        let mut group: Vec<usize> = self.zones_under(me).into_iter().filter(|z| through.contains(z)).collect();
        let mut first_at = if group.is_empty() { None } else { Some(0.0) };
        let mut along = 0.0;
        let mut last = me.pos();
        let mut gap_from = if group.is_empty() { None } else { Some(0.0) };
        for p in path {
            along += (p.pos() - last).norm();
            last = p.pos();
            if first_at.is_none() && along > CLAIM_AHEAD_M {
                return None;
            }
            match self.zones.at(p.pos()).filter(|z| through.contains(z)) {
                Some(z) => {
                    if group.len() < MAX_CLAIM_ZONES && !group.contains(&z) {
                        group.push(z);
                    }
                    first_at.get_or_insert(along);
                    gap_from = Some(along);
                }
                None => {
                    if gap_from.is_some_and(|g| along - g > WAIT_ROOM_M) {
                        break;
                    }
                }
            }
        }
        first_at.map(|at| (group, at))
    }

    /// The peer that holds zone `z` by a claim heard lately.
    fn holder(&self, z: usize, now: f64) -> Option<&traffic::Peer> {
        let zones = &self.zones;
        self.traffic.peers().iter().find(|p| {
            now - p.heard_s <= traffic::CLAIM_FRESH_S
                && p.claim.as_ref().is_some_and(|c| c.hold && c.zones.iter().any(|&q| zones.named(q) == Some(z)))
        })
    }

    /// A zone the path only passes by is not claimed ([`Pilot::zones_ahead`]), but it is not
    /// driven into while another chair holds it: that chair is in its doorway or turning out
    /// of it across both lanes (a chair passing by drove into a junction while another
    /// turned into its doorway, and the two shut each other in for good: ward, 6 chairs,
    /// seed 1). Stand short of it until it is let go. Whether the chair may drive on.
    fn pass_by_gate(&mut self, me: Pose, now: f64, path: &[Pose], through: &[usize], notes: &mut Vec<String>) -> bool {
        if let Some(centre) = self.pass_wait {
            if self.zones.named(centre).is_some_and(|z| self.holder(z, now).is_some()) {
                self.traffic.set_zone_waiting(true);
                self.nav.hold();
                return false;
            }
            self.pass_wait = None;
            self.traffic.set_zone_waiting(false);
            return true;
        }
        if path.is_empty() {
            return true;
        }
        let under = self.zones_under(me);
        let stop_at = self.nav.model().footprint.front + STOP_SHORT_M;
        let (mut along, mut last) = (0.0, me.pos());
        for p in path {
            along += (p.pos() - last).norm();
            last = p.pos();
            if along > stop_at {
                break;
            }
            let Some(z) = self.zones.at(p.pos()).filter(|z| !through.contains(z) && !under.contains(z)) else {
                continue;
            };
            if let Some(by) = self.holder(z, now).map(|p| p.name.clone()) {
                let centre = self.zones.all()[z].centre;
                notes.push(format!("waiting at t {now:.1} s by the doorway at {} ({by} is using it)", place(centre)));
                self.pass_wait = Some(centre);
                self.traffic.set_zone_waiting(true);
                self.nav.hold();
                return false;
            }
        }
        true
    }

    /// The zones that `path` from `me` goes through: its side ([`Zones::side`]) changes
    /// within them (out of a room into the corridor, or across a junction into the room
    /// opposite), or it ends in them (what lies beyond is not known yet), or there is no
    /// path (waiting where it stands, the zones under it count).
    fn zones_through(&self, me: Pose, path: &[Pose]) -> Vec<usize> {
        let Some(end) = path.last() else { return self.zones_under(me) };
        let mut sides: Vec<(usize, Option<u32>)> = Vec::new();
        let mut through: Vec<usize> = self.zones.at(end.pos()).into_iter().collect();
        let mine = self.zones.side(me.pos());
        for z in self.zones_under(me) {
            sides.push((z, mine));
        }
        for p in path {
            let Some(z) = self.zones.at(p.pos()) else { continue };
            if through.contains(&z) {
                continue;
            }
            let side = self.zones.side(p.pos());
            match sides.iter().find(|(k, _)| *k == z) {
                Some(&(_, s)) if s != side => through.push(z),
                Some(_) => {}
                None => sides.push((z, side)),
            }
        }
        through
    }

    /// The name it goes by.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The navigator.
    pub fn navigator(&self) -> &Navigator {
        &self.nav
    }

    /// The navigator, to change its settings between ticks.
    pub fn navigator_mut(&mut self) -> &mut Navigator {
        &mut self.nav
    }

    /// The traffic rule's state.
    pub fn traffic(&self) -> &Traffic {
        &self.traffic
    }

    /// One tick: this tick's readings and the messages heard in it, in; powers and what to
    /// say, out.
    pub fn tick<'a>(&mut self, input: &Input, heard: impl IntoIterator<Item = &'a [u8]>) -> PilotOutput {
        let now = input.time_s;
        for m in heard {
            self.traffic.hear(m, now);
        }
        let peers = self.traffic.peers();
        let all: Vec<(Pose, Footprint)> = peers.iter().map(|p| (p.pose, p.footprint)).collect();
        // Chairs that say they stand still are obstacles to plan round, and so are those
        // that have stood for a while whatever they say (waiting for a way, or stopped by
        // their safety layer): planning through them only makes both stop again.
        let parked: Vec<(Pose, Footprint)> = peers
            .iter()
            .filter(|p| p.state.stands() || p.state == State::Wait || p.standing_for(now, STANDING_S))
            .map(|p| (p.pose, p.footprint))
            .collect();
        self.nav.set_peers(all, &parked);
        self.nav.perceive(input);
        let me = self.nav.pose();
        let own = self.nav.model().footprint;
        let mut notes = Vec::new();
        self.note_motion(me, now);
        // A chair at its last checkpoint stands for good (and says `park`): it negotiates
        // nothing.
        let decision = if self.nav.finished() {
            Decision::Go
        } else {
            let statics = &self.nav.model().statics;
            let lanes = self.nav.config().keep_right > 0.0;
            self.traffic.decide_in_lanes(me, &own, now, &|p| lanes && statics.in_own_lane(&p))
        };
        if !matches!(decision, Decision::PullOver(_)) {
            self.no_room_said = false;
        }
        // A chair that yields to another head-on goes nowhere until the other has passed: its
        // claim on zones would make the other wait for it (the two rules would then wait for
        // each other), so it lets them go and claims again when it drives on.
        // A chair done for good lets its zones go too, though it may stand partly in one:
        // it is an obstacle to plan round from now on, and a claim it kept would stop the
        // queue at that doorway (and the one facing it) for the rest of the run.
        // A chair stuck in the queue for a doorway keeps its place: it holds nothing, and
        // with no claim it drove on, claimed again at the back of the queue and stopped,
        // every other tick (backing off lets go).
        let stuck_outside = self.traffic.state() == State::Stuck && self.zone_wait.is_none();
        if (self.nav.finished() || stuck_outside || matches!(self.traffic.state(), State::Pull | State::Park))
            && self.traffic.claim().is_some()
        {
            self.traffic.release_zones();
            self.zone_wait = None;
        }
        if !matches!(decision, Decision::Go) {
            self.pass_wait = None;
        }
        let backing = self.back_off(me, now, &mut notes);
        match decision {
            _ if backing => {}
            Decision::Go => {
                if self.zone_gate(me, now, &mut notes) {
                    if !self.nav.manoeuvring() && self.nav.holding() {
                        notes.push(format!("going on at t {now:.1} s"));
                    }
                    self.nav.resume();
                }
            }
            Decision::Hold => {
                let pulling = self.traffic.state() == State::Pull;
                if pulling && self.nav.manoeuvring() && self.stood_for(now, STUCK_S) {
                    // The pull-over makes no headway (its safety layer holds it): give it up
                    // and stand where it is; standing, it soon counts as stuck, and the other
                    // plans round it.
                    self.nav.hold();
                    self.traffic.pull_lost();
                    notes.push(format!("pulling over got nowhere by t {now:.1} s; standing"));
                } else if pulling && self.nav.manoeuvring() {
                    // The pull-over is under way.
                } else if pulling && self.nav.manoeuvre_lost() {
                    // Strayed from the curve: not parked where it should be; look again.
                    self.traffic.pull_lost();
                    notes.push(format!("lost the way pulling over at t {now:.1} s; looking again"));
                } else if pulling {
                    self.traffic.parked();
                    notes.push(format!("parked at t {now:.1} s; waiting for the other chair to pass"));
                } else if !self.nav.holding() {
                    self.nav.hold();
                    notes.push(format!("waiting at t {now:.1} s for the chair ahead to pull over"));
                }
            }
            Decision::PullOver(peer) if self.turns_off_clear_of(me, &peer.pose, &peer.footprint) => {
                // Going on is the quickest way out of its way: the other waits (we say we are
                // pulling over) until we have turned off, and the meeting then ends for both.
                if !std::mem::replace(&mut self.no_room_said, true) {
                    notes.push(format!("turning off out of {}'s way at t {now:.1} s", peer.name));
                }
            }
            // Looking for room costs a few milliseconds: every fifth tick is often enough.
            Decision::PullOver(_) if self.no_room_said && !input.tick.is_multiple_of(5) => self.nav.hold(),
            Decision::PullOver(peer) => {
                let others: Vec<_> = self.traffic.peers().iter().filter(|p| p.name != peer.name).cloned().collect();
                match manoeuvre::pull_over(self.nav.model(), me, &peer, &others) {
                    Some(p) => {
                        let how = if p.backwards { "backing" } else { "pulling over" };
                        notes.push(format!(
                            "{how} {:.2} m to the {} at t {now:.1} s to let {} pass",
                            p.offset_m.abs(),
                            p.side(),
                            peer.name
                        ));
                        self.nav.manoeuvre(&p.path, PULL_OVER_SPEED);
                        self.traffic.pulling();
                        // Its headway is judged from now.
                        self.still = Some((me, now));
                        self.no_room_said = false;
                    }
                    None => {
                        if !std::mem::replace(&mut self.no_room_said, true) {
                            notes.push(format!(
                                "no room to pull over for {} at t {now:.1} s; waiting for some",
                                peer.name
                            ));
                        }
                        self.nav.hold();
                    }
                }
            }
        }
        let out = self.nav.act(input);
        let state = if self.nav.finished() { State::Park } else { self.traffic.state() };
        let near = self.traffic.peers().iter().any(|p| (p.pose.pos() - me.pos()).norm() < NEAR_M);
        let claiming = self.traffic.claim().is_some();
        let say =
            (near || claiming || input.tick.is_multiple_of(SAY_EVERY_FAR) || self.said != Some(state)).then(|| {
                let body = &self.nav.config().body;
                let m = traffic::encode_claim(&self.name, self.nav.pose(), state, body, self.traffic.claim());
                if m.len() <= ipc_types::MESSAGE_BYTES {
                    return m;
                }
                if !std::mem::replace(&mut self.claim_too_long_said, true) {
                    notes.push(format!(
                        "the name {:?} is too long to say a claim on doorways in {} bytes; claims go unsaid",
                        self.name,
                        ipc_types::MESSAGE_BYTES
                    ));
                }
                traffic::encode(&self.name, self.nav.pose(), state, body)
            });
        if say.is_some() {
            self.said = Some(state);
        }
        PilotOutput { powers: out.powers, say, events: out.events, notes }
    }

    /// Whether the path the chair follows turns off by [`TURN_OFF_RAD`] within [`TURN_OFF_M`],
    /// keeping [`TURN_OFF_GAP_M`] from a chair standing at `at` until it has.
    fn turns_off_clear_of(&self, me: Pose, at: &Pose, other: &Footprint) -> bool {
        if self.nav.holding() || self.nav.manoeuvring() {
            return false;
        }
        let own = self.nav.model().footprint;
        let corners = other.corners(at, 0.0);
        let (mut along, mut last) = (0.0, me.pos());
        for q in self.nav.path() {
            along += (q.pos() - last).norm();
            last = q.pos();
            if along > TURN_OFF_M {
                break;
            }
            let c = corners.map(|p| q.to_body(p));
            if (0..4).any(|k| own.body_segment_distance(c[k], c[(k + 1) % 4]) < TURN_OFF_GAP_M) {
                return false;
            }
            // Once turned off, the rest of the way is the planner's and the safety layer's.
            if crate::geom::wrap_rad(q.theta - me.theta).abs() >= TURN_OFF_RAD {
                return true;
            }
        }
        false
    }

    /// The one-lane zone rule for a chair free to drive: claims the zones ahead, releases
    /// those left behind, and stops short of zones it does not hold. Whether it may drive.
    fn zone_gate(&mut self, me: Pose, now: f64, notes: &mut Vec<String>) -> bool {
        // A chair done for good claims nothing, though it may stand in a zone (its claim
        // was let go when it arrived).
        if self.zones.all().is_empty() || self.nav.finished() {
            self.pass_wait = None;
            return true;
        }
        // The path and the zones it goes through, once for both gates.
        let path = self.nav.path();
        let through = self.zones_through(me, &path);
        if !self.pass_by_gate(me, now, &path, &through, notes) {
            return false;
        }
        let under = self.zones_under(me);
        // A chair that finds no way on while outside the zones it holds lets them go: it
        // may be stuck for long (behind a chair that waits for those very zones), and a
        // hold nobody uses blocks the queue.
        if self.nav.blocked()
            && let Some(c) = self.traffic.claim().filter(|c| c.hold)
            && !c.zones.iter().any(|&z| self.zones.named(z).is_some_and(|k| under.contains(&k)))
        {
            let first = c.zones[0];
            self.traffic.release_zones();
            notes.push(format!("no way on at t {now:.1} s; the doorway at {} is let go", place(first)));
        }
        // In a zone we hold: keep the claim as it is until the body is out of it (a claim
        // changed on the way would be a new one, last in the queue, on a zone we are in).
        if let Some(c) = self.traffic.claim().filter(|c| c.hold)
            && c.zones.iter().any(|&z| self.zones.named(z).is_some_and(|k| under.contains(&k)))
        {
            return true;
        }
        // Waiting (the path is gone while the navigator holds): the zones stay those we
        // stopped for. Driving: those ahead on the path.
        let ahead = match &self.zone_wait {
            Some(centres) => {
                let ids: Vec<usize> = centres.iter().filter_map(|&c| self.zones.named(c)).collect();
                Some((ids, 0.0))
            }
            None => self.zones_ahead(me, &path, &through),
        };
        let Some((ids, first_at)) = ahead.filter(|(ids, _)| !ids.is_empty()) else {
            // Nothing ahead on a known path: a claim is let go once the body is out of its
            // zones (while a new path is being planned, nothing is known ahead).
            let known = !self.nav.path().is_empty() || self.nav.finished();
            if known && under.is_empty() && self.traffic.claim().is_some() {
                self.traffic.release_zones();
            }
            return true;
        };
        let centres: Vec<V2> = ids.iter().map(|&k| self.zones.all()[k].centre).collect();
        let inside = ids.iter().any(|k| under.contains(k));
        // While waiting, the path is gone: the way out is judged again once we drive.
        let clear = self.zone_wait.is_some() || self.way_out_clear(&ids);
        let zones = &self.zones;
        let go = self.traffic.want_zones(&centres, |c| zones.named(c), now, inside, clear);
        if go {
            self.zone_wait = None;
            self.traffic.set_zone_waiting(false);
            return true;
        }
        if inside {
            // Already in a zone nobody let us have (a new path through it, a start in it):
            // backing out would block it more; the safety layer keeps the distance.
            return true;
        }
        // Not ours: drive on until the front would be in it, then stand.
        let stop_at = self.nav.model().footprint.front + STOP_SHORT_M;
        if self.zone_wait.is_none() && first_at > stop_at {
            return true;
        }
        if self.zone_wait.is_none() {
            let zones = &self.zones;
            let why = match self.traffic.zone_blocker(|c| zones.named(c)) {
                Some(by) => Some(format!("{by} has it")),
                None if !clear => Some("a chair waits beyond it".to_owned()),
                // Only the claim settling: a moment, not worth a line.
                None => None,
            };
            if let Some(why) = why {
                notes.push(format!("waiting at t {now:.1} s for the doorway at {} ({why})", place(centres[0])));
            }
            self.zone_wait = Some(centres);
        }
        self.traffic.set_zone_waiting(true);
        self.nav.hold();
        false
    }
}

fn place(p: V2) -> String {
    format!("({:.1}, {:.1})", p.x, p.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{MapWall, NavMap};
    use crate::navigator::{Checkpoint, NavConfig};

    /// A tick's input for a chair that stands (its wheels never turn) with nothing in sight.
    fn standing(tick: u64) -> Input {
        Input {
            tick,
            time_s: tick as f64 * 0.1,
            proximity_m: [3.0; ipc_types::MAX_PROXIMITY],
            proximity_count: 0,
            encoder_ticks: [0, 0],
            gps: None,
            compass_deg: None,
            collision: false,
        }
    }

    /// A chair in a negotiation that has stood 15 s is stuck, whatever the negotiation: here
    /// it has the way and waits for the other to pull over, which only ever says it is
    /// pulling over (held up by a third chair). It then says `stuck`, so that the deadlock
    /// breaker settles who gives way.
    #[test]
    fn a_chair_waiting_in_a_negotiation_that_never_ends_says_it_is_stuck() {
        let mut map = NavMap::empty(30.0, 4.0);
        map.walls.push(MapWall::rectangle(0.0, 0.0, 30.0, 0.1, false));
        map.walls.push(MapWall::rectangle(0.0, 2.1, 30.0, 2.2, false));
        let start = Pose::from_deg(15.0, 1.1, 0.0);
        let cfg = NavConfig {
            checkpoints: vec![Checkpoint { pos: V2::new(27.0, 1.1), radius_m: 0.5 }],
            start,
            encoder_ticks_per_m: 1000.0,
            ..NavConfig::intellwheels()
        };
        let body = cfg.body;
        let mut pilot = Pilot::new("chair1", Navigator::new(map, cfg));
        let other = Pose::from_deg(21.0, 1.1, 180.0);
        let mut said = Vec::new();
        for tick in 0..200u64 {
            let input = standing(tick);
            let msg = traffic::encode("chair2", other, State::Pull, &body).into_bytes();
            let out = pilot.tick(&input, [msg.as_slice()]);
            assert_eq!(out.powers, [0.0, 0.0], "it waits (tick {tick})");
            if let Some(s) = out.say {
                said.push((tick, s));
            }
        }
        let stuck_at = said.iter().find(|(_, s)| s.contains(" stuck ")).map(|(t, _)| *t);
        assert!(said.iter().any(|(_, s)| s.contains(" wait ")), "it waited first: {said:?}");
        assert!(stuck_at.is_some_and(|t| (150..=160).contains(&t)), "stuck after 15 s: {stuck_at:?}");
    }

    /// Two 15 m × 4 m rooms joined by a 1 m doorway (x 15–15.2, y 1.5–2.5), and a pilot with
    /// the zone rule on at `start`, bound for `goal`.
    fn doorway_pilot(start: Pose, goal: V2) -> Pilot {
        let mut map = NavMap::empty(30.2, 4.0);
        map.walls.push(MapWall::rectangle(0.0, 0.0, 30.2, 0.1, false));
        map.walls.push(MapWall::rectangle(0.0, 3.9, 30.2, 4.0, false));
        map.walls.push(MapWall::rectangle(15.0, 0.1, 15.2, 1.5, false));
        map.walls.push(MapWall::rectangle(15.0, 2.5, 15.2, 3.9, false));
        let cfg = NavConfig {
            checkpoints: vec![Checkpoint { pos: goal, radius_m: 0.5 }],
            start,
            encoder_ticks_per_m: 1000.0,
            ..NavConfig::intellwheels()
        };
        Pilot::new("chair1", Navigator::new(map, cfg)).with_zone_claims()
    }

    /// A chair queued for a doorway that another chair holds is not stuck while that chair
    /// is not: the queue moves. (It said `stuck` after 5 s, let its claim go, drove on,
    /// claimed again at the back of the queue and stopped, every other tick.) It waits
    /// in its place, saying `wait` with its claim, for up to a minute, and is stuck after
    /// that; behind a chair that is stuck itself it is stuck after 5 s.
    #[test]
    fn a_chair_queued_for_a_doorway_behind_a_chair_not_stuck_waits_its_turn() {
        let run = |holder: State| {
            let mut pilot = doorway_pilot(Pose::from_deg(12.0, 2.0, 0.0), V2::new(20.0, 2.0));
            assert_eq!(pilot.zones().all().len(), 1, "{:?}", pilot.zones().all());
            let door = pilot.zones().all()[0].centre;
            let body = pilot.navigator().config().body;
            let claim = traffic::Claim { hold: true, since_s: 0.0, zones: vec![door] };
            let mut stuck_at = None;
            for tick in 0..700u64 {
                let input = standing(tick);
                let other =
                    traffic::encode_claim("chair2", Pose::from_deg(17.5, 2.0, 0.0), holder, &body, Some(&claim));
                let out = pilot.tick(&input, [other.as_bytes()]);
                let said = out.say.unwrap_or_default();
                if said.contains(" stuck ") {
                    stuck_at.get_or_insert(tick);
                }
                if tick >= 20 {
                    // Stuck or not, it keeps its place in the queue (wanted since 0.1 s).
                    assert_eq!(out.powers, [0.0, 0.0], "it stands short of the doorway (tick {tick})");
                    assert!(said.contains(" w 1 "), "tick {tick}: {said}");
                    assert!(stuck_at.is_some() || said.contains(" wait "), "tick {tick}: {said}");
                }
            }
            stuck_at
        };
        let t = run(State::Go);
        assert!(t.is_some_and(|t| (600..=620).contains(&t)), "stuck after a minute behind a chair going: {t:?}");
        let t = run(State::Stuck);
        assert!(t.is_some_and(|t| (50..=60).contains(&t)), "stuck after 5 s behind a stuck chair: {t:?}");
    }

    /// A chair done for good claims nothing, even where it stands in a doorway: a claim it
    /// kept would stop the queue there for the rest of the run. (Its first tick's claim is
    /// made before the navigator finds itself at its goal, and let go on the next.)
    #[test]
    fn a_chair_done_in_a_doorway_claims_nothing() {
        let at = Pose::from_deg(15.1, 2.0, 0.0);
        let mut pilot = doorway_pilot(at, at.pos());
        for tick in 0..30u64 {
            let out = pilot.tick(&standing(tick), []);
            assert!(pilot.navigator().finished(), "at its goal from the start");
            // The first tick's claim is made before the navigator finds itself at its goal.
            if tick == 0 {
                continue;
            }
            let said = out.say.unwrap_or_default();
            assert!(!said.contains(" h ") && !said.contains(" w "), "tick {tick}: {said}");
        }
    }

    /// A corridor 2 m wide (y 6–8) with a 1 m doorway (x 5.5–6.5) into a room south of it,
    /// and a pilot with the zone rule on at `start`, bound for `goal`.
    fn corridor_pilot(start: Pose, goal: V2) -> Pilot {
        let mut map = NavMap::empty(12.0, 8.1);
        map.walls.push(MapWall::rectangle(0.0, 5.9, 5.5, 6.0, false));
        map.walls.push(MapWall::rectangle(6.5, 5.9, 12.0, 6.0, false));
        map.walls.push(MapWall::rectangle(0.0, 8.0, 12.0, 8.1, false));
        let cfg = NavConfig {
            checkpoints: vec![Checkpoint { pos: goal, radius_m: 0.5 }],
            start,
            encoder_ticks_per_m: 1000.0,
            ..NavConfig::intellwheels()
        };
        Pilot::new("chair1", Navigator::new(map, cfg)).with_zone_claims()
    }

    /// A chair that drives along a corridor past a doorway claims nothing: it passes the
    /// doorway by, in its lane. (Claiming every doorway on the way, as the zone rule did,
    /// queued the whole corridor behind each chair going into a room: ward, 10 chairs,
    /// 94 of 100 arrived, 98 with this.) A chair whose way goes through the doorway claims it.
    #[test]
    fn a_chair_passing_a_doorway_by_claims_nothing_one_going_in_claims_it() {
        let run = |goal: V2| {
            let mut pilot = corridor_pilot(Pose::from_deg(3.0, 6.6, 0.0), goal);
            assert_eq!(pilot.zones().all().len(), 1, "the doorway: {:?}", pilot.zones().all());
            let mut claimed = Vec::new();
            for tick in 0..40u64 {
                let said = pilot.tick(&standing(tick), []).say.unwrap_or_default();
                assert!(!pilot.navigator().path().is_empty() || tick < 20, "tick {tick}: no path");
                if pilot.traffic.claim().is_some() {
                    claimed.push(tick);
                }
                assert_eq!(
                    said.contains(" w ") || said.contains(" h "),
                    pilot.traffic.claim().is_some() && !said.is_empty(),
                    "tick {tick}: {said}"
                );
            }
            claimed
        };
        assert_eq!(run(V2::new(10.5, 6.6)), Vec::<u64>::new(), "passing by");
        let going_in = run(V2::new(6.0, 3.0));
        assert!(going_in.len() >= 20, "going in claims the doorway: {going_in:?}");
    }

    /// A chair passing a doorway along the corridor stands short of it while another chair
    /// holds it (in the doorway, or turning out of it across both lanes), and drives on once
    /// that chair lets it go. (Driving into the junction while another turned into its
    /// doorway shut both in for good: ward, 6 chairs, seed 1.)
    #[test]
    fn a_chair_passing_a_doorway_by_waits_while_another_chair_holds_it() {
        let mut pilot = corridor_pilot(Pose::from_deg(3.6, 6.6, 0.0), V2::new(10.5, 6.6));
        let body = pilot.navigator().config().body;
        let door = pilot.zones().all()[0].centre;
        let other = Pose::from_deg(6.0, 5.0, 90.0);
        let holding = traffic::Claim { hold: true, since_s: 0.0, zones: vec![door] };
        let (mut waited, mut went) = (None, None);
        for tick in 0..80u64 {
            let msg = if tick < 50 {
                traffic::encode_claim("chair2", other, State::Go, &body, Some(&holding))
            } else {
                traffic::encode("chair2", other, State::Go, &body)
            };
            let out = pilot.tick(&standing(tick), [msg.as_bytes()]);
            assert!(pilot.traffic.claim().is_none(), "passing by claims nothing (tick {tick})");
            if out.notes.iter().any(|n| n.contains("by the doorway") && n.contains("chair2 is using it")) {
                waited.get_or_insert(tick);
            }
            // Standing: braking (the drive's model still has it rolling), never driving on.
            let forward = out.powers.iter().any(|&p| p > 0.0);
            if tick < 50 && waited.is_some() {
                assert!(!forward, "it stands while chair2 holds the doorway (tick {tick}): {:?}", out.powers);
            }
            if tick >= 50 && forward {
                went.get_or_insert(tick);
            }
        }
        assert!(waited.is_some_and(|t| t < 20), "it stood short of the doorway: {waited:?}");
        assert!(went.is_some_and(|t| t < 60), "and went on once it was let go: {went:?}");
    }

    /// A chair whose way turns off (here to a goal round a right turn) within 3 m goes on when
    /// a chair whose name sorts first comes head-on: turning off is the quickest way out of
    /// its way. Where its turn would come near the other, it does not.
    #[test]
    fn a_yielder_turning_off_out_of_the_way_goes_on() {
        let run = |other: Pose| {
            let cfg = NavConfig {
                checkpoints: vec![Checkpoint { pos: V2::new(7.0, 2.0), radius_m: 0.3 }],
                start: Pose::from_deg(5.0, 5.0, 0.0),
                encoder_ticks_per_m: 1000.0,
                ..NavConfig::intellwheels()
            };
            let body = cfg.body;
            let mut pilot = Pilot::new("chair2", Navigator::new(NavMap::empty(20.0, 10.0), cfg));
            let mut notes = Vec::new();
            for tick in 0..10u64 {
                let input = standing(tick);
                let msg = traffic::encode("chair1", other, State::Go, &body).into_bytes();
                let heard: Vec<&[u8]> = if tick >= 3 { vec![msg.as_slice()] } else { Vec::new() };
                let out = pilot.tick(&input, heard);
                if tick >= 3 {
                    notes.extend(out.notes);
                    assert!(pilot.traffic.negotiating(), "tick {tick}: a head-on meeting");
                }
            }
            notes
        };
        let clear = run(Pose::from_deg(10.0, 5.0, 180.0));
        assert!(clear.iter().any(|n| n.contains("turning off out of chair1's way")), "{clear:?}");
        assert!(!run(Pose::from_deg(7.0, 5.0, 180.0)).iter().any(|n| n.contains("turning off")));
    }

    /// Among seven chairs heard within 8 m a chair may not hear them all: it does not drive
    /// to a refuge there. Six, or seven with one farther off, are no crowd.
    #[test]
    fn seven_chairs_heard_near_by_are_a_crowd() {
        let cfg = NavConfig::intellwheels();
        let body = cfg.body;
        let mut pilot = Pilot::new("chair1", Navigator::new(NavMap::empty(40.0, 14.0), cfg));
        let me = Pose::from_deg(20.0, 7.0, 0.0);
        let hear = |pilot: &mut Pilot, k: usize, x: f64| {
            let m = traffic::encode(&format!("chair{}", k + 2), Pose::from_deg(x, 7.0, 0.0), State::Go, &body);
            pilot.traffic.hear(m.as_bytes(), 0.0);
        };
        for k in 0..6 {
            hear(&mut pilot, k, 14.0 + 2.0 * k as f64);
        }
        assert!(!pilot.in_crowd(me), "six are no crowd");
        hear(&mut pilot, 6, 29.0);
        assert!(!pilot.in_crowd(me), "the seventh is 9 m off");
        hear(&mut pilot, 7, 27.5);
        assert!(pilot.in_crowd(me), "seven within 8 m are");
    }
}
