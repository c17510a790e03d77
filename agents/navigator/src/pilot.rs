//! A navigator that keeps to the traffic rule: each tick it hears the other chairs, lets the
//! rule ([`crate::traffic`]) decide whether to drive, wait, or pull over, has the navigator
//! carry that out, and says where it is. Without I/O: the agent feeds it from a hub, the
//! tests from the world model in-process.

use crate::geom::{Footprint, Pose};
use crate::manoeuvre;
use crate::navigator::{NavEvent, Navigator};
use crate::sensors::Input;
use crate::traffic::{self, Decision, MEET_M, State, Traffic};

/// Speed of the pull-over, m/s: a little below cruising, a few metres from another chair.
const PULL_OVER_SPEED: f64 = 0.25;
/// Say where we are every this many ticks (twice a second at 100 ms) when no other chair is
/// near...
const SAY_EVERY_FAR: u64 = 5;
/// ...and every tick when one is within this distance, metres (its readings of us are
/// matched to what we say).
const NEAR_M: f64 = MEET_M + 3.0;

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
    /// "No room to pull over" was said (once per search).
    no_room_said: bool,
}

impl Pilot {
    /// A pilot called `name` (as it registered with the hub) for `nav`.
    pub fn new(name: &str, nav: Navigator) -> Self {
        Self { name: name.to_owned(), traffic: Traffic::new(name), nav, said: None, no_room_said: false }
    }

    /// The name it goes by.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The navigator.
    pub fn navigator(&self) -> &Navigator {
        &self.nav
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
        // Chairs that say they stand still are obstacles to plan round.
        let parked: Vec<(Pose, Footprint)> = peers
            .iter()
            .filter(|p| matches!(p.state, State::Park | State::Wait))
            .map(|p| (p.pose, p.footprint))
            .collect();
        self.nav.set_peers(all, &parked);
        self.nav.perceive(input);
        let me = self.nav.pose();
        let own = self.nav.model().footprint;
        let mut notes = Vec::new();
        // A chair at its last checkpoint stands for good (and says `park`): it negotiates
        // nothing.
        let decision = if self.nav.finished() { Decision::Go } else { self.traffic.decide(me, &own, now) };
        if !matches!(decision, Decision::PullOver(_)) {
            self.no_room_said = false;
        }
        match decision {
            Decision::Go => {
                if !self.nav.manoeuvring() && self.nav.holding() {
                    notes.push(format!("going on at t {now:.1} s"));
                }
                self.nav.resume();
            }
            Decision::Hold => {
                let pulling = self.traffic.state() == State::Pull;
                if pulling && self.nav.manoeuvring() {
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
            // Looking for room costs a few milliseconds: every fifth tick is often enough.
            Decision::PullOver(_) if self.no_room_said && !input.tick.is_multiple_of(5) => self.nav.hold(),
            Decision::PullOver(peer) => {
                let others: Vec<_> = self.traffic.peers().iter().filter(|p| p.name != peer.name).cloned().collect();
                match manoeuvre::pull_over(self.nav.model(), me, &peer, &others) {
                    Some(p) => {
                        notes.push(format!(
                            "pulling over {:.2} m to the {} at t {now:.1} s to let {} pass",
                            p.offset_m.abs(),
                            p.side(),
                            peer.name
                        ));
                        self.nav.manoeuvre(&p.path, PULL_OVER_SPEED);
                        self.traffic.pulling();
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
        let say = (near || input.tick.is_multiple_of(SAY_EVERY_FAR) || self.said != Some(state))
            .then(|| traffic::encode(&self.name, self.nav.pose(), state, &self.nav.config().body));
        if say.is_some() {
            self.said = Some(state);
        }
        PilotOutput { powers: out.powers, say, events: out.events, notes }
    }
}
