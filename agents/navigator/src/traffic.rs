//! Meeting another chair head-on: the two agree by messages who yields (beyond the thesis).
//!
//! Every navigator says where it is and what it is doing, `nav NAME X Y HEADING STATE LENGTH
//! WIDTH COM` ([`encode`]), where STATE is `go`, `pull` (pulling over), `wait` (standing still
//! until the chair ahead has pulled over), `stuck` (no way on for a while: see
//! [`State::Stuck`]) or `park` (standing still: parked for someone, or
//! done). When two of them are within [`MEET_M`], face each
//! other, each has the other ahead and their lines are close enough to clash, both apply the
//! same rule to what they heard — the name that sorts last yields:
//!
//! - the yielder pulls over to the side (its right if that leaves room for the other, else
//!   its left) along an S-curve that the navigator's own path follower drives
//!   ([`crate::manoeuvre`]), stops, and says `park`;
//! - the other stands still (saying `wait`) until it hears that `park`; then its navigator
//!   plans round the parked chair's rectangle (any chair that says `park` or `wait` stands
//!   still and is an obstacle to plan round) and drives on;
//! - once the other has gone past, the yielder goes back to its navigator, which re-plans
//!   from where it stands.
//!
//! Nothing is decided on one side alone: the chair with the right of way does not move
//! towards the other before it has heard that the other is out of the way. This module is
//! the rule and its state; [`crate::pilot`] carries it out with the navigator.
//!
//! **One-lane zones** (doorways and other narrows, [`crate::zones`]) are claimed before they
//! are entered: the message then ends in `w SINCE ZONES` (wanted since SINCE, simulated
//! tenths of a second) or `h ZONES` (held), each zone named by its centre in centimetres
//! (`1250,595`). A chair claims every zone on its way up to the next place where it can stand
//! without being in one, all at once, and enters only once it holds them: it has wanted them
//! for [`CLAIM_SETTLE_S`] (so a claim made at the same moment has been heard) and no peer
//! heard in the last [`CLAIM_FRESH_S`] holds one of them or wanted one earlier (ties: the name
//! that sorts first). First come, first served: no zone is held by a chair that waits for
//! another, so claims alone make no deadlock. A claim lapses when its chair falls silent;
//! a chair that says nothing (a teleop, a Ciber-Rato robot) claims nothing and is only an
//! obstacle its sensors find.

use crate::geom::{Footprint, Pose};

/// Chairs nearer than this (axle to axle, metres), facing each other, negotiate. The
/// yielder needs a few metres ahead to pull over and the other a few more to swing round it;
/// the hub's default message range is 8 m.
pub const MEET_M: f64 = 7.0;
/// A peer not heard for this many seconds is forgotten.
const FORGET_S: f64 = 3.0;
/// The chair with the right of way waits this long for the other to yield, then goes on
/// regardless (its safety layer still stops it short of the other).
const WAIT_LIMIT_S: f64 = 40.0;
/// Two chairs whose lines pass farther apart than their half-widths plus this do not clash.
const CLASH_SLACK_M: f64 = 0.4;
/// The same for chairs that keep right ([`Traffic::keeping_right`]): two chairs in the lanes
/// of a 2 m corridor (1 m apart) pass without a word; in a narrower one they still agree who
/// pulls over.
const CLASH_SLACK_LANES_M: f64 = 0.25;
/// The other has gone past when its axle is this far behind ours, metres.
const PASSED_M: f64 = 1.4;
/// Bodies said to be longer or wider than this are not believed, metres.
const MAX_BODY_M: f64 = 5.0;
/// Nor places farther from the origin than this, metres.
const MAX_COORD_M: f64 = 10_000.0;
/// A zone is entered only after it has been wanted this long, seconds: two ticks at 100 ms,
/// so that a claim made at the same tick elsewhere has been heard (messages arrive a tick
/// after they are said).
pub const CLAIM_SETTLE_S: f64 = 0.25;
/// A peer's claim counts while it was heard within this many seconds (claims are said every
/// tick).
pub const CLAIM_FRESH_S: f64 = 1.0;
/// A peer whose said pose moves less than this (metres, radians) stands still.
pub const STILL_M: f64 = 0.03;
/// See [`STILL_M`].
pub const STILL_RAD: f64 = 0.035;

/// At most this many zones in one claim.
pub const MAX_CLAIM_ZONES: usize = 4;
/// Longest name a navigator's chair may have, in bytes: the name travels in every traffic
/// message, which must fit the hub's 100 bytes with its pose, state and claimed zones (the
/// hub itself takes names of up to 255 bytes).
pub const MAX_NAME_BYTES: usize = 31;

/// A claim on one-lane zones, as said.
#[derive(Debug, Clone, PartialEq)]
pub struct Claim {
    /// Held (entered or about to be), not only wanted.
    pub hold: bool,
    /// Since when they are wanted, simulated seconds (to a tenth).
    pub since_s: f64,
    /// The zones, by centre.
    pub zones: Vec<crate::geom::V2>,
}

impl Claim {
    fn words(&self) -> String {
        let zones: Vec<String> =
            self.zones.iter().map(|z| format!("{},{}", (z.x * 100.0).round(), (z.y * 100.0).round())).collect();
        if self.hold {
            format!(" h {}", zones.join(" "))
        } else {
            format!(" w {} {}", (self.since_s * 10.0).round(), zones.join(" "))
        }
    }

    /// Whether `self` goes before `other` for a zone both want: the earlier claim, then the
    /// name that sorts first.
    fn before(&self, name: &str, other: &Claim, other_name: &str) -> bool {
        (self.since_s, name) < (other.since_s, other_name)
    }
}

/// What a navigator says it is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// Driving (or waiting) on its own account.
    Go,
    /// Pulling over for another chair (or looking for room to).
    Pull,
    /// Standing still until the chair ahead has pulled over: plan round it.
    Wait,
    /// Standing still for good or for a while (parked for another chair to pass, or at its
    /// last checkpoint): plan round it.
    Park,
    /// Standing, with no way on for a while (or backing off to make one): plan round it.
    /// Of the chairs stuck near each other, all but the one whose name sorts first back off.
    Stuck,
}

impl State {
    /// Whether a chair that says this stands still and is to be planned round.
    pub fn stands(self) -> bool {
        matches!(self, State::Park | State::Stuck)
    }

    fn word(self) -> &'static str {
        match self {
            State::Go => "go",
            State::Pull => "pull",
            State::Wait => "wait",
            State::Park => "park",
            State::Stuck => "stuck",
        }
    }
}

/// What another navigator said.
#[derive(Debug, Clone, PartialEq)]
pub struct Peer {
    /// Its name.
    pub name: String,
    /// Where it is: x, y metres, heading radians.
    pub pose: Pose,
    /// What it is doing.
    pub state: State,
    /// Its rectangle relative to its axle.
    pub footprint: Footprint,
    /// When we heard it, seconds.
    pub heard_s: f64,
    /// Its claim on one-lane zones, if any.
    pub claim: Option<Claim>,
    /// Since when it has said the same place (within [`STILL_M`] and [`STILL_RAD`]),
    /// seconds: a chair that stands, whatever it says it does.
    pub still_since_s: f64,
}

impl Peer {
    /// Whether it has stood where it is for at least `s` seconds at `now_s`.
    pub fn standing_for(&self, now_s: f64, s: f64) -> bool {
        now_s - self.still_since_s >= s
    }
}

/// The message a navigator says about itself (at most 100 bytes for names up to 40).
pub fn encode(name: &str, pose: Pose, state: State, body: &crate::Body) -> String {
    encode_claim(name, pose, state, body, None)
}

/// [`encode`] with a claim on zones; the caller checks that it fits in a message (a name
/// longer than about 20 bytes with a claim of several zones does not).
pub fn encode_claim(name: &str, pose: Pose, state: State, body: &crate::Body, claim: Option<&Claim>) -> String {
    let mut m = format!(
        "nav {name} {:.3} {:.3} {:.1} {} {:.2} {:.2} {:.2}",
        pose.x,
        pose.y,
        sim_model::wire_deg(pose.theta),
        state.word(),
        body.width_m,
        body.height_m,
        body.com
    );
    if let Some(c) = claim {
        m.push_str(&c.words());
    }
    m
}

/// Reads another navigator's message; `None` for anything else (other agents' messages,
/// junk, impossible bodies).
pub fn decode(bytes: &[u8], heard_s: f64) -> Option<Peer> {
    let text = std::str::from_utf8(bytes).ok()?;
    let mut w = text.split_whitespace();
    if w.next()? != "nav" {
        return None;
    }
    let name = w.next()?.to_owned();
    let num = |t: Option<&str>| t?.parse::<f64>().ok().filter(|v| v.is_finite());
    let (x, y, deg) = (num(w.next())?, num(w.next())?, num(w.next())?);
    let state = match w.next()? {
        "go" => State::Go,
        "pull" => State::Pull,
        "wait" => State::Wait,
        "park" => State::Park,
        "stuck" => State::Stuck,
        _ => return None,
    };
    let (length, width, com) = (num(w.next())?, num(w.next())?, num(w.next())?);
    let claim = match w.next() {
        None => None,
        Some(kind @ ("w" | "h")) => {
            let since_s = if kind == "w" { num(w.next())? / 10.0 } else { 0.0 };
            let mut zones = Vec::new();
            for z in w.by_ref() {
                let (x, y) = z.split_once(',')?;
                let (x, y) = (num(Some(x))? / 100.0, num(Some(y))? / 100.0);
                if !(x.abs() <= MAX_COORD_M && y.abs() <= MAX_COORD_M) || zones.len() == MAX_CLAIM_ZONES {
                    return None;
                }
                zones.push(crate::geom::V2::new(x, y));
            }
            if zones.is_empty() {
                return None;
            }
            Some(Claim { hold: kind == "h", since_s, zones })
        }
        Some(_) => return None,
    };
    // Anything may say anything (the UDP bridge relays remote agents): only bodies and places
    // a chair could have are believed, so that no message can make the planner's work or
    // memory blow up.
    let body = |v: f64| v > 0.0 && v <= MAX_BODY_M;
    let place = |v: f64| v.abs() <= MAX_COORD_M;
    let believable = body(length) && body(width) && com > 0.0 && com < 1.0 && place(x) && place(y);
    if w.next().is_some() || !believable {
        return None;
    }
    Some(Peer {
        name,
        pose: Pose { x, y, theta: deg.to_radians() },
        state,
        footprint: Footprint::of_body(length, width, com),
        heard_s,
        claim,
        still_since_s: heard_s,
    })
}

/// Where this chair stands in a negotiation.
#[derive(Debug, Clone, PartialEq)]
enum Role {
    /// None going on.
    Free,
    /// We yield to `peer` and pull over; `since_s` we have looked for room, and `moving` once
    /// the manoeuvre is under way.
    PullingOver { peer: String, since_s: f64, moving: bool },
    /// We yield to `peer` and are parked.
    Parked { peer: String },
    /// We have the right of way and wait for `peer` to yield, since `since_s`.
    Waiting { peer: String, since_s: f64 },
    /// `peer` has yielded; we drive past it.
    Passing { peer: String },
}

/// What the traffic rule asks of the chair this tick.
#[derive(Debug, Clone, PartialEq)]
pub enum Decision {
    /// Drive on with the navigator.
    Go,
    /// Stand still (waiting for the other to yield, or parked until it has passed).
    Hold,
    /// Pull over for this peer now: asked each tick, standing still, until there is room and
    /// [`Traffic::pulling`] is called; then [`Decision::Hold`] until [`Traffic::parked`].
    PullOver(Peer),
}

/// One navigator's side of the negotiation.
#[derive(Debug, Clone)]
pub struct Traffic {
    name: String,
    peers: Vec<Peer>,
    role: Role,
    /// Peers we have already met; not met again until they are far away.
    crossed: Vec<String>,
    /// Our claim on one-lane zones.
    claim: Option<Claim>,
    /// When the claim last changed its zones, simulated seconds: it holds new ones only
    /// [`CLAIM_SETTLE_S`] after (a claim kept in its place in the queue says an older SINCE).
    claim_changed_s: f64,
    /// Standing still until the zones claimed are ours.
    zone_waiting: bool,
    /// Stuck, or backing off ([`State::Stuck`]).
    stuck: bool,
    /// [`CLASH_SLACK_M`], or less for chairs that keep right.
    clash_slack: f64,
}

fn along(me: Pose, other: Pose) -> f64 {
    (other.x - me.x) * me.theta.cos() + (other.y - me.y) * me.theta.sin()
}

fn across(me: Pose, other: Pose) -> f64 {
    -(other.x - me.x) * me.theta.sin() + (other.y - me.y) * me.theta.cos()
}

fn facing(a: Pose, b: Pose) -> bool {
    crate::geom::wrap_rad(a.theta - b.theta).abs() > 2.4 // more than about 137° apart
}

/// Whether `other` still comes our way: ahead of us and heading more against us than with
/// us. Looser than a meeting ([`facing`]), so that a chair swinging round us as it passes
/// still counts.
fn coming(me: Pose, other: Pose) -> bool {
    along(me, other) > -PASSED_M && crate::geom::wrap_rad(me.theta - other.theta).abs() > std::f64::consts::FRAC_PI_2
}

impl Traffic {
    /// The rule for the navigator called `name`.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_owned(),
            peers: Vec::new(),
            role: Role::Free,
            crossed: Vec::new(),
            claim: None,
            claim_changed_s: 0.0,
            zone_waiting: false,
            stuck: false,
            clash_slack: CLASH_SLACK_M,
        }
    }

    /// Chairs keep right in two-lane corridors (`--keep-right`): two in opposite lanes pass
    /// each other without negotiating.
    pub fn keeping_right(mut self) -> Self {
        self.clash_slack = CLASH_SLACK_LANES_M;
        self
    }

    /// Our claim on one-lane zones, as we say it.
    pub fn claim(&self) -> Option<&Claim> {
        self.claim.as_ref()
    }

    /// Claims the zones named by `zones` (their centres; `zone_of` says which of our zones a
    /// centre names, ours or a peer's) at `now_s`, or keeps the claim already made on them;
    /// whether we hold them and may go in. `inside`: the chair is already in one of them, so
    /// a hold it has is kept whatever a peer says (backing out would block both). `may_enter`:
    /// the way out beyond them is clear; if not, the claim keeps its place in the queue but
    /// holds nothing (a chair never stands in a zone waiting for room beyond it).
    pub fn want_zones(
        &mut self,
        zones: &[crate::geom::V2],
        zone_of: impl Fn(crate::geom::V2) -> Option<usize>,
        now_s: f64,
        inside: bool,
        may_enter: bool,
    ) -> bool {
        let zones = &zones[..zones.len().min(MAX_CLAIM_ZONES)];
        let ids: Vec<usize> = zones.iter().filter_map(|&z| zone_of(z)).collect();
        let same = self.claim.as_ref().is_some_and(|c| {
            c.zones.len() == ids.len() && c.zones.iter().all(|&z| zone_of(z).is_some_and(|k| ids.contains(&k)))
        });
        if !same {
            // A claim on other zones keeps its place in the queue if it still wants one of
            // those it wanted: a path planned anew (round a chair that stopped) changes the
            // zones ahead by one more or one fewer, and a claim made anew each time went last
            // in the queue again and again. It holds what it held only if it wants nothing
            // more. Otherwise: simulated time to a tenth of a second, as said.
            let old = self.claim.take();
            let kept = old.filter(|c| c.zones.iter().any(|&z| zone_of(z).is_some_and(|k| ids.contains(&k))));
            let claim = match kept {
                Some(c) => {
                    let had: Vec<usize> = c.zones.iter().filter_map(|&z| zone_of(z)).collect();
                    Claim {
                        hold: c.hold && ids.iter().all(|k| had.contains(k)),
                        since_s: c.since_s,
                        zones: zones.to_vec(),
                    }
                }
                None => Claim { hold: false, since_s: (now_s * 10.0).round() / 10.0, zones: zones.to_vec() },
            };
            self.claim = Some(claim);
            self.claim_changed_s = now_s;
        }
        let Some(mine) = self.claim.clone() else { return false };
        let name = self.name.as_str();
        let conflict = self.peers.iter().any(|p| {
            let Some(c) = p.claim.as_ref().filter(|_| now_s - p.heard_s <= CLAIM_FRESH_S) else { return false };
            let shared = c.zones.iter().any(|&z| zone_of(z).is_some_and(|k| ids.contains(&k)));
            shared && ((c.hold && !(mine.hold && inside)) || (!mine.hold && c.before(&p.name, &mine, name)))
        });
        let claim = self.claim.as_mut().expect("made above");
        if conflict || (!may_enter && !inside) {
            claim.hold = false;
        } else if claim.hold || now_s - claim.since_s.max(self.claim_changed_s) >= CLAIM_SETTLE_S - 1e-9 {
            claim.hold = true;
        }
        claim.hold
    }

    /// Lets go of the zones claimed.
    pub fn release_zones(&mut self) {
        self.claim = None;
        self.zone_waiting = false;
    }

    /// Says whether we are stuck (or backing off): we then say `stuck`.
    pub fn set_stuck(&mut self, stuck: bool) {
        self.stuck = stuck;
    }

    /// Says whether we stand still waiting for zones (we then say `wait`: plan round us).
    pub fn set_zone_waiting(&mut self, waiting: bool) {
        self.zone_waiting = waiting;
    }

    /// The peer that holds (or wanted first) a zone of our claim, for the user.
    pub fn zone_blocker(&self, zone_of: impl Fn(crate::geom::V2) -> Option<usize>) -> Option<&str> {
        let mine = self.claim.as_ref()?;
        let ids: Vec<usize> = mine.zones.iter().filter_map(|&z| zone_of(z)).collect();
        self.peers
            .iter()
            .find(|p| {
                p.claim.as_ref().is_some_and(|c| c.zones.iter().any(|&z| zone_of(z).is_some_and(|k| ids.contains(&k))))
            })
            .map(|p| p.name.as_str())
    }

    /// What we say we are doing.
    pub fn state(&self) -> State {
        match self.role {
            Role::PullingOver { moving: true, .. } => State::Pull,
            Role::Parked { .. } => State::Park,
            // Stuck outranks waiting for a pull-over that finds no room: the other then plans
            // round us, or, stuck too, one of us backs off.
            _ if self.stuck => State::Stuck,
            Role::PullingOver { .. } => State::Pull,
            Role::Waiting { .. } => State::Wait,
            _ if self.zone_waiting => State::Wait,
            _ => State::Go,
        }
    }

    /// Whether standing still now may be a deadlock: not while a negotiation goes its way
    /// (waiting for the other to pull over, pulling over, parked for it, passing it), only
    /// with none going on or as a yielder that finds no room.
    pub fn may_be_stuck(&self) -> bool {
        matches!(self.role, Role::Free | Role::PullingOver { moving: false, .. })
    }

    /// Whether a negotiation is going on.
    pub fn negotiating(&self) -> bool {
        self.role != Role::Free
    }

    /// The peers heard lately.
    pub fn peers(&self) -> &[Peer] {
        &self.peers
    }

    /// Takes in a message heard at `now_s`.
    pub fn hear(&mut self, bytes: &[u8], now_s: f64) {
        if let Some(mut p) = decode(bytes, now_s)
            && p.name != self.name
        {
            if let Some(old) = self.peers.iter().find(|q| q.name == p.name)
                && (old.pose.pos() - p.pose.pos()).norm() <= STILL_M
                && crate::geom::wrap_rad(old.pose.theta - p.pose.theta).abs() <= STILL_RAD
            {
                // Still where it was: keep the earlier pose, so that creeping adds up.
                p.still_since_s = old.still_since_s;
                p.pose = old.pose;
            }
            self.peers.retain(|q| q.name != p.name);
            self.peers.push(p);
        }
    }

    /// Says that the pull-over manoeuvre has begun.
    pub fn pulling(&mut self) {
        if let Role::PullingOver { moving, .. } = &mut self.role {
            *moving = true;
        }
    }

    /// Says that the pull-over manoeuvre was lost on the way (the chair strayed from it):
    /// look for room again from where the chair is.
    pub fn pull_lost(&mut self) {
        if let Role::PullingOver { moving, .. } = &mut self.role {
            *moving = false;
        }
    }

    /// Says that the pull-over is over: we are parked and say so.
    pub fn parked(&mut self) {
        if let Role::PullingOver { peer, .. } = &self.role {
            self.role = Role::Parked { peer: peer.clone() };
        }
    }

    fn peer(&self, name: &str) -> Option<&Peer> {
        self.peers.iter().find(|p| p.name == name)
    }

    /// Whether `peer` has gone past us (or is no longer heard).
    fn gone_past(&self, me: Pose, peer: &str) -> bool {
        self.peer(peer).is_none_or(|p| along(me, p.pose) < -PASSED_M)
    }

    /// Whether we and `p` meet head-on: near, facing each other, each ahead of the other,
    /// on lines close enough to clash.
    fn clashes(&self, me: Pose, own: &Footprint, p: &Peer) -> bool {
        (p.pose.x - me.x).hypot(p.pose.y - me.y) <= MEET_M
            && facing(me, p.pose)
            && along(me, p.pose) > 0.5
            && along(p.pose, me) > 0.5
            // Each side measures the other's offset in its own frame; the larger of the two
            // makes the test the same on both sides.
            && across(me, p.pose).abs().max(across(p.pose, me).abs()) < own.half + p.footprint.half + self.clash_slack
    }

    fn finish(&mut self, peer: String) -> Decision {
        self.role = Role::Free;
        self.crossed.push(peer);
        Decision::Go
    }

    /// Decides for this tick, with our pose estimate and our own rectangle.
    pub fn decide(&mut self, me: Pose, own: &Footprint, now_s: f64) -> Decision {
        self.decide_in_lanes(me, own, now_s, &|_| false)
    }

    /// [`Traffic::decide`] where `in_own_lane` says whether a chair at a pose drives in its own
    /// lane of a two-lane passage: two chairs that both do pass each other without a word.
    pub fn decide_in_lanes(
        &mut self,
        me: Pose,
        own: &Footprint,
        now_s: f64,
        in_own_lane: &dyn Fn(Pose) -> bool,
    ) -> Decision {
        self.peers.retain(|p| now_s - p.heard_s <= FORGET_S);
        match self.role.clone() {
            Role::PullingOver { peer, since_s, moving } => {
                if moving {
                    return Decision::Hold;
                }
                // No room found yet: look again while the other is still there, and give up
                // after as long as the other waits (it then goes on regardless).
                // A meeting that has come apart (the other turned off, into a doorway or a
                // lane of its own) asks nothing more of us: pulling over for a chair that no
                // longer comes only blocks the way (a yielder once stood 20 s in a doorway
                // for a chair long gone down the corridor).
                return match self.peer(&peer).cloned() {
                    Some(p) if !p.state.stands() && now_s - since_s <= WAIT_LIMIT_S && self.clashes(me, own, &p) => {
                        Decision::PullOver(p)
                    }
                    _ => self.finish(peer),
                };
            }
            Role::Parked { peer } => {
                // Gone past, or standing for good itself (arrived beside us, or parked for a
                // third chair), or no longer coming our way: it will not pass, so we go on
                // and plan round it.
                let done = self.peer(&peer).is_none_or(|p| p.state.stands() || !coming(me, p.pose));
                return if done || self.gone_past(me, &peer) { self.finish(peer) } else { Decision::Hold };
            }
            Role::Waiting { peer, since_s } => {
                if self.gone_past(me, &peer) || self.peer(&peer).is_some_and(|p| !coming(me, p.pose)) {
                    return self.finish(peer);
                }
                match self.peer(&peer).map(|p| p.state) {
                    None => return self.finish(peer),
                    Some(State::Park | State::Stuck) => {
                        self.role = Role::Passing { peer };
                        return Decision::Go;
                    }
                    // Pulling over (or looking for room to): the wait starts again, so that
                    // the two sides' limits do not race.
                    Some(State::Pull) => {
                        self.role = Role::Waiting { peer, since_s: now_s };
                        return Decision::Hold;
                    }
                    Some(_) if now_s - since_s > WAIT_LIMIT_S => return self.finish(peer),
                    Some(_) => return Decision::Hold,
                }
            }
            Role::Passing { peer } => {
                return if self.gone_past(me, &peer) { self.finish(peer) } else { Decision::Go };
            }
            Role::Free => {}
        }
        let peers = &self.peers;
        self.crossed
            .retain(|n| peers.iter().any(|p| &p.name == n && (p.pose.x - me.x).hypot(p.pose.y - me.y) < 2.0 * MEET_M));
        let me_in_lane = in_own_lane(me);
        let meeting = self.peers.iter().find(|p| {
            !self.crossed.contains(&p.name)
                // One already parked is planned round; one already pulling over may have
                // seen the meeting a moment before we did.
                && !p.state.stands()
                && self.clashes(me, own, p)
                // Two chairs each in its own lane pass each other.
                && (!me_in_lane || !in_own_lane(p.pose))
        });
        let Some(p) = meeting.cloned() else { return Decision::Go };
        if self.name > p.name {
            self.role = Role::PullingOver { peer: p.name.clone(), since_s: now_s, moving: false };
            Decision::PullOver(p)
        } else {
            self.role = Role::Waiting { peer: p.name.clone(), since_s: now_s };
            Decision::Hold
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Body;
    use crate::geom::V2;

    fn pose(x: f64, y: f64, deg: f64) -> Pose {
        Pose { x, y, theta: deg.to_radians() }
    }

    const BODY: Body = Body::INTELLWHEELS;

    fn say(name: &str, p: Pose, state: State) -> Vec<u8> {
        encode(name, p, state, &BODY).into_bytes()
    }

    #[test]
    fn messages_round_trip_and_junk_is_ignored() {
        let m = encode("chair2", pose(20.0, 6.0, 180.0), State::Park, &BODY);
        assert_eq!(m, "nav chair2 20.000 6.000 180.0 park 1.10 0.65 0.80");
        let p = decode(m.as_bytes(), 1.0).expect("decodes");
        assert_eq!((p.name.as_str(), p.state, p.pose.x), ("chair2", State::Park, 20.0));
        assert_eq!(p.footprint, BODY.footprint());
        for junk in [
            &b"door open door1"[..],
            b"nav",
            b"nav a 1 2",
            b"nav a 1 2 NaN go 1 1 0.5",
            b"nav a 1 2 3 maybe 1 1 0.5",
            b"nav a 1 2 3 go 1 1",
            b"nav a 1 2 3 go 1 -1 0.5",
            b"nav a 1 2 3 go 1 1 2",
            b"nav a 1 2 3 go 1 1 0",
            b"nav a 1 2 180 park 1 1e18 0.5",
            b"nav a 1e300 2 180 park 1 1 0.5",
            b"nav a 1 2 3 go 1 1 0.5 extra",
            b"\xff\xfe",
        ] {
            assert_eq!(decode(junk, 0.0), None, "{junk:?}");
        }
        assert!(encode(&"n".repeat(40), pose(-100.0, -100.0, -179.9), State::Park, &BODY).len() <= 100);
    }

    #[test]
    fn claims_round_trip_and_bad_claims_are_junk() {
        let c = Claim { hold: false, since_s: 15.3, zones: vec![V2::new(12.5, 5.95), V2::new(12.5, 8.05)] };
        let m = encode_claim("chair2", pose(20.0, 6.0, 180.0), State::Wait, &BODY, Some(&c));
        assert_eq!(m, "nav chair2 20.000 6.000 180.0 wait 1.10 0.65 0.80 w 153 1250,595 1250,805");
        assert_eq!(decode(m.as_bytes(), 1.0).expect("decodes").claim, Some(c));
        let h = Claim { hold: true, since_s: 0.0, zones: vec![V2::new(2.5, 6.0)] };
        let m = encode_claim("chair2", pose(20.0, 6.0, 180.0), State::Go, &BODY, Some(&h));
        assert!(m.ends_with(" h 250,600"), "{m}");
        assert_eq!(decode(m.as_bytes(), 1.0).expect("decodes").claim, Some(h));
        for junk in [
            &b"nav a 1 2 3 go 1 1 0.5 h"[..],
            b"nav a 1 2 3 go 1 1 0.5 w 10",
            b"nav a 1 2 3 go 1 1 0.5 h 1,2 3",
            b"nav a 1 2 3 go 1 1 0.5 h 1,x",
            b"nav a 1 2 3 go 1 1 0.5 h 1e12,0",
            b"nav a 1 2 3 go 1 1 0.5 h 1,1 2,2 3,3 4,4 5,5",
            b"nav a 1 2 3 go 1 1 0.5 x 1,1",
        ] {
            assert_eq!(decode(junk, 0.0), None, "{:?}", std::str::from_utf8(junk));
        }
    }

    /// Zones numbered by the integer part of their centre's x (a stand-in for the map's).
    fn zone_of(z: V2) -> Option<usize> {
        Some(z.x as usize)
    }

    /// What `t` says at `now`, heard by `other`.
    fn tell(t: &Traffic, other: &mut Traffic, at: Pose, now: f64) {
        let m = encode_claim(&t.name, at, t.state(), &BODY, t.claim());
        other.hear(m.as_bytes(), now);
    }

    #[test]
    fn of_two_chairs_claiming_a_zone_at_once_the_first_name_goes_and_the_other_after_it_left() {
        let door = [V2::new(12.5, 6.0)];
        let (pa, pb) = (pose(12.5, 4.0, 90.0), pose(11.0, 7.0, 0.0));
        let mut a = Traffic::new("chair1");
        let mut b = Traffic::new("chair2");
        let mut entered = (None, None);
        for k in 0..30 {
            let now = f64::from(k) * 0.1;
            let ga = a.want_zones(&door, zone_of, now, false, true);
            let gb = b.want_zones(&door, zone_of, now, false, true);
            assert!(!(ga && gb), "both hold the doorway at {now}");
            if ga && entered.0.is_none() {
                entered.0 = Some(now);
            }
            if gb && entered.1.is_none() {
                entered.1 = Some(now);
            }
            // Messages arrive a tick after they are said.
            tell(&a, &mut b, pa, now + 0.1);
            tell(&b, &mut a, pb, now + 0.1);
            if now >= 2.0 {
                a.release_zones();
            }
        }
        let (ta, tb) = (entered.0.expect("chair1 went in"), entered.1.expect("chair2 went in after"));
        assert!(ta <= 0.3 + 1e-9, "chair1 waited only for the settling: {ta}");
        assert!(tb > 2.0, "chair2 waited until chair1 had let go: {tb}");
    }

    #[test]
    fn the_earlier_claim_goes_first_whatever_the_names_and_a_silent_claim_lapses() {
        let door = [V2::new(7.5, 6.0)];
        let mut late = Traffic::new("chair1");
        let mut early = Traffic::new("chair9");
        assert!(!early.want_zones(&door, zone_of, 1.0, false, true));
        tell(&early, &mut late, pose(7.5, 4.0, 90.0), 1.1);
        assert!(!late.want_zones(&door, zone_of, 1.1, false, true));
        assert!(early.want_zones(&door, zone_of, 1.3, false, true), "settled, nobody before it");
        tell(&early, &mut late, pose(7.5, 4.0, 90.0), 1.4);
        assert!(!late.want_zones(&door, zone_of, 1.5, false, true), "chair9 wanted it first");
        // chair9 falls silent inside (crashed, its messages lost): its claim lapses after 1 s.
        assert!(!late.want_zones(&door, zone_of, 2.4, false, true));
        assert!(late.want_zones(&door, zone_of, 2.5, false, true), "a claim not heard for 1 s lapses");
    }

    /// A path planned anew changes the zones ahead: a claim that still wants one of those
    /// it wanted keeps its place in the queue (a later claimant still waits for it); it keeps
    /// its hold only if it wants nothing more. A claim on other zones altogether is a new one.
    #[test]
    fn a_claim_changed_by_a_new_path_keeps_its_place_in_the_queue() {
        let (door, junction) = (V2::new(7.5, 6.0), V2::new(12.5, 6.0));
        let mut first = Traffic::new("chair9");
        let mut later = Traffic::new("chair1");
        assert!(!first.want_zones(&[door], zone_of, 1.0, false, true));
        assert!(first.want_zones(&[door], zone_of, 1.3, false, true), "settled, nobody before it");
        // One more zone beyond: the hold goes (all or nothing), the place in the queue stays.
        assert!(!first.want_zones(&[door, junction], zone_of, 5.0, false, true));
        assert_eq!(first.claim().map(|c| (c.since_s, c.hold)), Some((1.0, false)));
        assert!(!later.want_zones(&[door], zone_of, 4.0, false, true));
        tell(&first, &mut later, pose(7.5, 4.0, 90.0), 5.1);
        assert!(!later.want_zones(&[door], zone_of, 5.2, false, true), "chair9 wanted it first");
        tell(&later, &mut first, pose(7.5, 8.0, -90.0), 5.1);
        assert!(!first.want_zones(&[door, junction], zone_of, 5.2, false, true), "the new zone settles first");
        assert!(first.want_zones(&[door, junction], zone_of, 5.3, false, true), "then chair9 goes first");
        // Back to the doorway alone: held still, as it wants nothing it did not hold.
        assert!(first.want_zones(&[door], zone_of, 6.0, false, true));
        assert_eq!(first.claim().map(|c| c.since_s), Some(1.0));
        // Somewhere else altogether: a new claim, wanted from now.
        assert!(!first.want_zones(&[V2::new(22.5, 6.0)], zone_of, 9.0, false, true));
        assert_eq!(first.claim().map(|c| (c.since_s, c.hold)), Some((9.0, false)));
    }

    #[test]
    fn the_later_name_pulls_over_and_the_other_waits_until_it_is_parked() {
        let fp = BODY.footprint();
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(21.0, 6.0, 180.0));
        let mut one = Traffic::new("chair1");
        let mut two = Traffic::new("chair2");
        one.hear(&say("chair2", b, State::Go), 0.0);
        two.hear(&say("chair1", a, State::Go), 0.0);
        assert_eq!(one.decide(a, &fp, 0.1), Decision::Hold);
        let Decision::PullOver(peer) = two.decide(b, &fp, 0.1) else { panic!("chair2 yields") };
        assert_eq!(peer.name, "chair1");
        assert!(matches!(two.decide(b, &fp, 0.2), Decision::PullOver(_)), "asked again until it moves");
        two.pulling();
        assert_eq!(two.decide(b, &fp, 0.3), Decision::Hold, "pulling over");
        // While chair2 is pulling over, chair1 still waits.
        one.hear(&say("chair2", b, State::Pull), 0.2);
        assert_eq!(one.decide(a, &fp, 0.3), Decision::Hold);
        let b = pose(19.5, 6.45, 180.0);
        two.parked();
        assert_eq!(two.state(), State::Park);
        one.hear(&say("chair2", b, two.state()), 0.4);
        assert_eq!(one.decide(a, &fp, 0.5), Decision::Go, "chair1 goes once chair2 is parked");
        // chair1 goes by; chair2 stays until chair1 is well behind it.
        let beside = pose(19.4, 5.55, 0.0);
        two.hear(&say("chair1", beside, State::Go), 5.0);
        assert_eq!(two.decide(b, &fp, 5.0), Decision::Hold);
        assert_eq!(one.decide(beside, &fp, 5.0), Decision::Go);
        let past = pose(21.0, 5.6, 0.0);
        two.hear(&say("chair1", past, State::Go), 9.0);
        assert_eq!(two.decide(b, &fp, 9.0), Decision::Go);
        assert_eq!(two.state(), State::Go);
        assert_eq!(one.decide(past, &fp, 9.0), Decision::Go);
        assert!(!one.negotiating(), "chair1 is past chair2");
        // Met once: they do not negotiate again while near.
        one.hear(&say("chair2", b, State::Go), 9.1);
        assert_eq!(one.decide(past, &fp, 9.2), Decision::Go);
        assert!(!one.negotiating() && !two.negotiating());
    }

    /// The chair given the way stops for good before it has gone past (its goal was beside
    /// the yielder, as when two chairs swap rooms): it says `park`, and the yielder goes on
    /// rather than wait for a pass that never comes.
    #[test]
    fn a_yielder_goes_on_when_the_other_stops_for_good_before_passing() {
        let fp = BODY.footprint();
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(21.0, 6.0, 180.0));
        let mut two = Traffic::new("chair2");
        two.hear(&say("chair1", a, State::Go), 0.0);
        assert!(matches!(two.decide(b, &fp, 0.1), Decision::PullOver(_)));
        two.pulling();
        two.parked();
        let nearer = pose(18.5, 6.3, 10.0);
        two.hear(&say("chair1", nearer, State::Go), 5.0);
        assert_eq!(two.decide(b, &fp, 5.0), Decision::Hold, "still on its way");
        let mut turned = two.clone();
        two.hear(&say("chair1", nearer, State::Park), 6.0);
        assert_eq!(two.decide(b, &fp, 6.0), Decision::Go, "it stands for good: go on round it");
        // Nor does it wait for one that turned off (into a doorway beside it).
        turned.hear(&say("chair1", pose(20.0, 7.2, 90.0), State::Go), 6.0);
        assert_eq!(turned.decide(b, &fp, 6.0), Decision::Go, "it no longer comes");
        // A yielder still looking for room does not pull over for a chair that stands.
        let mut three = Traffic::new("chair3");
        three.hear(&say("chair1", a, State::Go), 0.0);
        assert!(matches!(three.decide(b, &fp, 0.1), Decision::PullOver(_)));
        three.hear(&say("chair1", a, State::Park), 0.2);
        assert_eq!(three.decide(b, &fp, 0.3), Decision::Go);
    }

    /// Two chairs leaving facing doorways meet head-on for a moment, then both turn down the
    /// corridor: the one looking for room to pull over stops looking, the other stops
    /// waiting (a yielder once stood 20 s in a doorway for a chair long gone).
    #[test]
    fn a_meeting_that_comes_apart_is_over_for_both() {
        let fp = BODY.footprint();
        let (one_at, two_at) = (pose(12.5, 5.0, 90.0), pose(12.6, 9.0, -90.0));
        let mut one = Traffic::new("chair1");
        let mut two = Traffic::new("chair2");
        one.hear(&say("chair2", two_at, State::Go), 0.0);
        two.hear(&say("chair1", one_at, State::Go), 0.0);
        assert_eq!(one.decide(one_at, &fp, 0.1), Decision::Hold);
        assert!(matches!(two.decide(two_at, &fp, 0.1), Decision::PullOver(_)), "no room found yet");
        // chair1 turns east down the corridor.
        let east = pose(14.0, 6.6, 0.0);
        two.hear(&say("chair1", east, State::Go), 3.0);
        assert_eq!(two.decide(two_at, &fp, 3.0), Decision::Go, "no longer anybody to pull over for");
        assert!(!two.negotiating());
        // chair2 turns east too: chair1, had it waited, waits no more.
        one.hear(&say("chair2", pose(13.5, 7.5, 0.0), State::Pull), 3.0);
        assert_eq!(one.decide(one_at, &fp, 3.0), Decision::Go, "it no longer comes");
        assert!(!one.negotiating());
    }

    #[test]
    fn the_chair_with_the_right_of_way_waits_even_when_it_hears_of_the_meeting_late() {
        let fp = BODY.footprint();
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(21.0, 6.0, 180.0));
        let mut one = Traffic::new("chair1");
        // chair2 saw the meeting first and is already pulling over.
        one.hear(&say("chair2", b, State::Pull), 0.0);
        assert_eq!(one.decide(a, &fp, 0.1), Decision::Hold);
        one.hear(&say("chair2", pose(19.0, 6.45, 180.0), State::Park), 3.0);
        assert_eq!(one.decide(a, &fp, 3.1), Decision::Go);
        assert!(one.negotiating(), "passing");
        // A chair already parked head-on is simply planned round.
        let mut three = Traffic::new("chair1");
        three.hear(&say("chair0", b, State::Park), 0.0);
        assert_eq!(three.decide(a, &fp, 0.1), Decision::Go);
        assert!(!three.negotiating());
    }

    #[test]
    fn chairs_going_the_same_way_far_apart_or_on_separate_lines_do_not_negotiate() {
        let fp = BODY.footprint();
        let me = pose(15.0, 6.0, 0.0);
        let cases = [
            (pose(17.0, 6.0, 0.0), 0.0, "same direction"),
            (pose(25.0, 6.0, 180.0), 0.0, "10 m away"),
            (pose(13.0, 6.0, 180.0), 0.0, "behind, going away"),
            (pose(18.0, 8.0, 180.0), 0.0, "a lane 2 m to the side"),
            (pose(18.0, 6.0, 180.0), 5.0, "not heard for 5 s"),
        ];
        for (other, now, why) in cases {
            let mut one = Traffic::new("chair1");
            one.hear(&say("chair2", other, State::Go), 0.0);
            assert_eq!(one.decide(me, &fp, now), Decision::Go, "{why}");
            assert!(!one.negotiating(), "{why}");
        }
    }

    /// Two chairs in the lanes of a corridor, each right of the middle line, pass without a
    /// word even where they drift 0.15 m towards the middle (0.7 m apart, within the clash
    /// test's reach); where one of them is not in its lane, they settle who pulls over.
    #[test]
    fn chairs_each_in_its_own_lane_pass_without_a_word() {
        let fp = BODY.footprint();
        let (me, other) = (pose(15.0, 6.65, 0.0), pose(20.0, 7.35, 180.0));
        // The corridor's lanes as a rule: south of y 7 eastbound, north of it westbound.
        let lanes = |p: Pose| if p.theta.cos() > 0.9 { p.y < 7.0 } else { p.theta.cos() < -0.9 && p.y > 7.0 };
        let (mut one, mut two) = (Traffic::new("chair1").keeping_right(), Traffic::new("chair2").keeping_right());
        one.hear(&say("chair2", other, State::Go), 0.0);
        two.hear(&say("chair1", me, State::Go), 0.0);
        assert_eq!(one.decide_in_lanes(me, &fp, 0.1, &lanes), Decision::Go);
        assert_eq!(two.decide_in_lanes(other, &fp, 0.1, &lanes), Decision::Go);
        assert!(!one.negotiating() && !two.negotiating());
        // Out of lanes (`decide` knows none), the same two meet head-on.
        assert_eq!(one.decide(me, &fp, 0.2), Decision::Hold, "chair1 has the way");
        assert!(matches!(two.decide(other, &fp, 0.2), Decision::PullOver(_)), "chair2 yields");
    }

    #[test]
    fn a_chair_without_room_to_pull_over_keeps_looking_then_gives_up() {
        let fp = BODY.footprint();
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(21.0, 6.0, 180.0));
        let mut two = Traffic::new("chair2");
        two.hear(&say("chair1", a, State::Go), 0.0);
        assert!(matches!(two.decide(b, &fp, 0.1), Decision::PullOver(_)));
        two.hear(&say("chair1", a, State::Wait), 20.0);
        assert!(matches!(two.decide(b, &fp, 20.0), Decision::PullOver(_)), "still looking");
        assert_eq!(two.state(), State::Pull);
        two.hear(&say("chair1", a, State::Wait), 41.0);
        assert_eq!(two.decide(b, &fp, 41.0), Decision::Go, "given up");
        assert_eq!(two.state(), State::Go);
    }

    #[test]
    fn a_peer_that_never_yields_is_waited_for_only_so_long() {
        let fp = BODY.footprint();
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(20.0, 6.0, 180.0));
        let mut one = Traffic::new("chair1");
        one.hear(&say("chair2", b, State::Go), 0.0);
        assert_eq!(one.decide(a, &fp, 0.0), Decision::Hold);
        one.hear(&say("chair2", b, State::Go), 30.0);
        assert_eq!(one.decide(a, &fp, 30.0), Decision::Hold);
        one.hear(&say("chair2", b, State::Go), 41.0);
        assert_eq!(one.decide(a, &fp, 41.0), Decision::Go);
        assert!(!one.negotiating());
        // While the other says it is pulling over, the wait starts again.
        let mut one = Traffic::new("chair1");
        one.hear(&say("chair2", b, State::Go), 0.0);
        assert_eq!(one.decide(a, &fp, 0.0), Decision::Hold);
        one.hear(&say("chair2", b, State::Pull), 39.0);
        assert_eq!(one.decide(a, &fp, 39.0), Decision::Hold);
        one.hear(&say("chair2", b, State::Pull), 60.0);
        assert_eq!(one.decide(a, &fp, 60.0), Decision::Hold, "still pulling over");
        // And it ends once the other has gone by regardless.
        one.hear(&say("chair2", pose(13.0, 6.5, 180.0), State::Go), 61.0);
        assert_eq!(one.decide(a, &fp, 61.0), Decision::Go);
    }

    #[test]
    fn a_peer_that_stays_put_is_standing_whatever_it_says_and_creeping_adds_up() {
        let mut me = Traffic::new("chair1");
        let at = |t: &Traffic| t.peers().iter().find(|p| p.name == "chair2").cloned().expect("heard");
        // Says `go` every tick from the same place, within its estimate's jitter.
        for k in 0..=20 {
            let jitter = if k % 2 == 0 { 0.01 } else { -0.01 };
            me.hear(&say("chair2", pose(10.0 + jitter, 6.0, 0.0), State::Go), f64::from(k) * 0.1);
        }
        let p = at(&me);
        assert!(p.standing_for(2.0, 2.0), "stood 2 s: {p:?}");
        assert!(!p.standing_for(2.0, 2.1));
        // Creeping 2 cm a tick is not standing: the steps add up past STILL_M.
        let mut me = Traffic::new("chair1");
        for k in 0..=20 {
            me.hear(&say("chair2", pose(10.0 + 0.02 * f64::from(k), 6.0, 0.0), State::Go), f64::from(k) * 0.1);
        }
        assert!(!at(&me).standing_for(2.0, 0.5), "{:?}", at(&me));
        // Turning on the spot is not standing either.
        let mut me = Traffic::new("chair1");
        for k in 0..=20 {
            me.hear(&say("chair2", pose(10.0, 6.0, 5.0 * f64::from(k)), State::Go), f64::from(k) * 0.1);
        }
        assert!(!at(&me).standing_for(2.0, 0.5));
    }

    #[test]
    fn a_yielder_with_no_room_that_is_stuck_says_so_and_the_other_plans_round_it() {
        let fp = BODY.footprint();
        let (a, b) = (pose(15.0, 6.0, 0.0), pose(21.0, 6.0, 180.0));
        let mut one = Traffic::new("chair1");
        let mut two = Traffic::new("chair2");
        one.hear(&say("chair2", b, State::Go), 0.0);
        two.hear(&say("chair1", a, State::Go), 0.0);
        assert_eq!(one.decide(a, &fp, 0.1), Decision::Hold);
        assert!(matches!(two.decide(b, &fp, 0.1), Decision::PullOver(_)));
        // No room: chair2 looks and says `pull`; chair1 waits.
        one.hear(encode("chair2", b, two.state(), &BODY).as_bytes(), 0.2);
        assert_eq!(one.decide(a, &fp, 0.3), Decision::Hold);
        // Stuck (its pilot's word after 5 s): it says `stuck`, which outranks `pull`...
        assert!(two.may_be_stuck(), "a yielder that finds no room may be stuck");
        two.set_stuck(true);
        assert_eq!(two.state(), State::Stuck);
        let m = encode("chair2", b, two.state(), &BODY);
        assert!(m.contains(" stuck "), "{m}");
        // ...and chair1 stops waiting for it: it drives on and plans round it.
        one.hear(m.as_bytes(), 5.5);
        assert_eq!(one.decide(a, &fp, 5.6), Decision::Go);
        assert!(!one.may_be_stuck(), "passing is a negotiation going its way");
        // A chair waiting for the other to pull over is never stuck by itself.
        let mut three = Traffic::new("chair0");
        three.hear(&say("chair2", b, State::Go), 0.0);
        assert_eq!(three.decide(a, &fp, 0.1), Decision::Hold);
        assert!(!three.may_be_stuck());
    }
}
