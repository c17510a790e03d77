//! Registration without waiting: send a request to the hub, go on serving other inputs, and
//! poll for the answer. For processes that carry other clients' robots (the UDP bridge), where
//! [`Agent::register`]'s wait (up to 15 s for a busy or stopped hub) would stall everyone.
//!
//! ```no_run
//! use agent_sdk::Agent;
//! use ipc_types::RobotRegistration;
//!
//! let mut agent = Agent::connect("demo", "bridge").expect("a hub serves session demo");
//! let pending = agent.start_register(&RobotRegistration::new("chair")).expect("sent");
//! let id = loop {
//!     // … serve other inputs here …
//!     if let Some(answer) = agent.poll_pending(&pending).expect("accepted") {
//!         break answer.robot_id;
//!     }
//! };
//! # let _ = id;
//! ```

use std::time::Instant;

use ipc_services::Svc;
use ipc_services::iceoryx2::pending_response::PendingResponse;
use ipc_types::{Refusal, RegisterKind, RegisterRequest, RegisterResponse, RobotRegistration};

use crate::{ANSWER_TIMEOUT, Agent, AgentError, Link, NUDGE_EVERY, ipc};

/// A request sent to the hub whose answer has not been read yet. The hub's register service
/// holds at most 4 requests of one agent in flight: keep fewer than that outstanding (one
/// slot stays free for the goodbye).
pub struct PendingRequest {
    pending: Pending,
    kind: RegisterKind,
    sent: Instant,
    /// A robot registration's request: through Zenoh a restarted bridge gets it again.
    robot: Option<RobotRegistration>,
}

impl std::fmt::Debug for PendingRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PendingRequest").field("kind", &self.kind).field("sent", &self.sent).finish()
    }
}

/// Where the answer will come from.
enum Pending {
    Shm(PendingResponse<Svc, RegisterRequest, (), RegisterResponse, ()>),
    Zenoh(crate::remote::PendingReply),
}

/// The hub's acceptance of a pending request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Accepted {
    /// The new robot's id (a robot registration), or 0 (a ready request).
    pub robot_id: u32,
}

impl Agent {
    /// Sends a robot registration and returns at once; read the answer with
    /// [`Agent::poll_pending`].
    pub fn start_register(&mut self, robot: &RobotRegistration) -> Result<PendingRequest, AgentError> {
        self.start_request(RegisterKind::Robot, Some(robot))
    }

    /// Sends "every robot is registered" (see [`Agent::ready`]) and returns at once.
    pub fn start_ready(&mut self) -> Result<PendingRequest, AgentError> {
        self.start_request(RegisterKind::Ready, None)
    }

    pub(crate) fn start_request(
        &mut self,
        kind: RegisterKind,
        robot: Option<&RobotRegistration>,
    ) -> Result<PendingRequest, AgentError> {
        let req = self.request_of(kind, robot);
        let pending = match &self.link {
            Link::Shm(link) => {
                let pending = link.register.send_copy(req).map_err(ipc("send a registration"))?;
                let _ = link.doorbell.notify();
                Pending::Shm(pending)
            }
            Link::Zenoh(z) => Pending::Zenoh(z.request(&req)?),
        };
        Ok(PendingRequest { pending, kind, sent: Instant::now(), robot: robot.copied() })
    }

    /// The hub's answer to `request` if it has come: `Ok(None)` while it has not, the
    /// acceptance once (an accepted robot joins [`Agent::robots`]), or the hub's typed
    /// refusal. Fails with [`AgentError::NoAnswer`] once the request is [`ANSWER_TIMEOUT`] (15 s) old, and like
    /// [`Agent::check_alive`] when the hub is gone or a termination signal arrived.
    pub fn poll_pending(&mut self, request: &PendingRequest) -> Result<Option<Accepted>, AgentError> {
        let answer = self.poll_answer(request)?;
        Ok(answer.map(|r| Accepted { robot_id: if request.kind == RegisterKind::Robot { r.robot_id } else { 0 } }))
    }

    /// [`Agent::poll_pending`] with the hub's whole answer (the robot's sensor count, the
    /// tick), for a bridge that passes it on.
    pub fn poll_answer(&mut self, request: &PendingRequest) -> Result<Option<RegisterResponse>, AgentError> {
        let Some(r) = self.poll_response(request)? else { return Ok(None) };
        if request.kind == RegisterKind::Robot {
            self.accepted(r.robot_id, request.robot.as_ref());
        }
        Ok(Some(r))
    }

    /// The hub's accepted answer to `request` as it came, if it has come: what the blocking
    /// requests (hello, register, ready) and [`Agent::poll_pending`] are built on.
    pub(crate) fn poll_response(&mut self, request: &PendingRequest) -> Result<Option<RegisterResponse>, AgentError> {
        let answer = match (&request.pending, &self.link) {
            (Pending::Shm(pending), _) => pending.receive().map_err(ipc("receive an answer"))?.map(|r| *r.payload()),
            (Pending::Zenoh(pending), Link::Zenoh(z)) => z.poll(pending, &self.session)?,
            (Pending::Zenoh(_), Link::Shm(_)) => unreachable!("a request is answered by the link that sent it"),
        };
        if let Some(r) = answer {
            return match Refusal::from_u32(r.status) {
                Some(Refusal::Accepted) => Ok(Some(r)),
                reason => Err(AgentError::Refused {
                    reason: reason.unwrap_or(Refusal::Malformed),
                    detail: r.detail().to_owned(),
                }),
            };
        }
        self.check()?;
        if request.sent.elapsed() > ANSWER_TIMEOUT {
            return Err(AgentError::NoAnswer(self.session.clone(), ANSWER_TIMEOUT));
        }
        // One clock for all of this agent's requests: the first nudge comes a second after
        // the agent's previous one, at most, and never for a request younger than that.
        if request.sent.elapsed() > NUDGE_EVERY
            && let Link::Shm(link) = &mut self.link
        {
            link.nudge.if_due(&link.register_svc, &link.doorbell);
        }
        Ok(None)
    }
}
