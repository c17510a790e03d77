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

use crate::{ANSWER_TIMEOUT, Agent, AgentError, NUDGE_EVERY, ipc};

/// A request sent to the hub whose answer has not been read yet. The hub's register service
/// holds at most 4 requests of one agent in flight: keep fewer than that outstanding (one
/// slot stays free for the goodbye).
pub struct PendingRequest {
    pending: PendingResponse<Svc, RegisterRequest, (), RegisterResponse, ()>,
    kind: RegisterKind,
    sent: Instant,
}

impl std::fmt::Debug for PendingRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PendingRequest").field("kind", &self.kind).field("sent", &self.sent).finish()
    }
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
        let pending = self.register.send_copy(req).map_err(ipc("send a registration"))?;
        let _ = self.doorbell.notify();
        Ok(PendingRequest { pending, kind, sent: Instant::now() })
    }

    /// The hub's answer to `request` if it has come: `Ok(None)` while it has not, the
    /// acceptance once (an accepted robot joins [`Agent::robots`]), or the hub's typed
    /// refusal. Fails with [`AgentError::NoAnswer`] once the request is [`ANSWER_TIMEOUT`] (15 s) old, and like
    /// [`Agent::check_alive`] when the hub is gone or a termination signal arrived.
    pub fn poll_pending(&mut self, request: &PendingRequest) -> Result<Option<Accepted>, AgentError> {
        let Some(r) = self.poll_response(request)? else { return Ok(None) };
        if request.kind == RegisterKind::Robot {
            self.robots.push(r.robot_id);
            Ok(Some(Accepted { robot_id: r.robot_id }))
        } else {
            Ok(Some(Accepted { robot_id: 0 }))
        }
    }

    /// The hub's accepted answer to `request` as it came, if it has come: what the blocking
    /// requests (hello, register, ready) and [`Agent::poll_pending`] are built on.
    pub(crate) fn poll_response(&mut self, request: &PendingRequest) -> Result<Option<RegisterResponse>, AgentError> {
        if let Some(resp) = request.pending.receive().map_err(ipc("receive an answer"))? {
            let r = *resp.payload();
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
            return Err(AgentError::NoAnswer(self.session.name().to_owned(), ANSWER_TIMEOUT));
        }
        // One clock for all of this agent's requests: the first nudge comes a second after
        // the agent's previous one, at most, and never for a request younger than that.
        if request.sent.elapsed() > NUDGE_EVERY {
            self.nudge.if_due(&self.register_svc, &self.doorbell);
        }
        Ok(None)
    }
}
