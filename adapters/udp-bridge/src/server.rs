//! The bridge process: a UDP registration port, one socket per client, and one agent on the
//! hub carrying every UDP robot.
//!
//! Per Ciber-Rato, a client registers on the port and gets its reply from a new socket of its
//! own, which carries all later traffic; that socket only accepts datagrams from the address
//! and port that registered. Each hub tick becomes one `<Measures>` per robot and one
//! `<Robot>` per robot per viewer. With a lock-step hub the bridge answers the tick once every
//! UDP robot has sent its `<Actions>` (or `<Sync/>`), or when the hub's deadline is near.
//!
//! As in Ciber-Rato, while the run waits for its Start (or is paused) every robot still gets
//! its Measures (`Time` frozen, `Buttons Stop="On"`) and every viewer its `<Robot>` datagrams,
//! once a cycle; a robot client that falls silent keeps its robot and its last powers
//! (removal for silence is opt-in: [`BridgeConfig::client_timeout`]).
//!
//! Scores: the hub scores every robot in the run's challenge (`world::challenge`); viewers get
//! each robot's `Score`, `ArrivalTime`, `ReturningTime`, `Collisions`, `VisitedMask` and
//! `State` from the world snapshot, and with `ScoreSensor="On"` each robot's Measures carry
//! its `<Score>` from its sensor block.
//!
//! After the run the bridge stays, as the simulator does: Measures (Time frozen, both Buttons
//! off) every cycle until the clients go quiet (see `Bridge::after_the_run`).

use std::io::ErrorKind;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant};

use agent_sdk::map::Map;
use agent_sdk::pending::PendingRequest;
use agent_sdk::{Agent, AgentError};
use ipc_types::{
    ACT_MOTORS, ACT_POSE, ActionBlock, COLLISION, ChallengeStanding, Command, HAS_COMPASS, HAS_GPS, HAS_GROUND,
    HAS_SCORE, LED_END, LED_RETURNING, LED_VISITING, REG_HAS_POSE, RobotInfo, RobotKind, RunState, SENSOR_BEACON,
    SENSOR_COLLISION, SENSOR_COMPASS, SENSOR_GPS, SENSOR_GROUND, SENSOR_OBSTACLE, SENSOR_SCORE, SensorBlock,
    SensorSpec,
};
use observer::Observer;

use crate::codec::{
    self, Actions, MeasuresData, Registration, ReplyParams, RobotType, ScoreData, ViewerCommand, ViewerRobot,
};
use crate::noise::NoiseLog;

/// Ciber-Rato's motor power limit: powers are clamped to ±0.15 and 0.15 means full power.
pub const MAX_POWER: f64 = 0.15;

/// How to run the bridge.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    /// The hub's session.
    pub session: String,
    /// Address to bind (127.0.0.1 unless the LAN is wanted).
    pub bind: IpAddr,
    /// Registration port.
    pub port: u16,
    /// A robot client silent this long is unregistered (its robot removed); `None` (the
    /// default, as in Ciber-Rato): never, and a silent robot keeps its last powers.
    pub client_timeout: Option<Duration>,
    /// How long to wait for the hub to come up.
    pub connect_timeout: Duration,
    /// Whether registered viewers and panels may start, pause and stop the run and remove
    /// robots; without it their `<Start/>`, `<Stop/>` and `<Robot Removed>` are ignored.
    pub allow_control: bool,
    /// Who may register as a viewer or panel (they get every robot's true pose each tick and,
    /// with `<LabReq/>`, the scenario's obstacles).
    pub viewers: Viewers,
    /// Addresses allowed to register as viewers besides those `viewers` lets in.
    pub viewer_allow: Vec<IpAddr>,
    /// The bridge tells the hub it is ready once this many robots were accepted (at least 1):
    /// a Ciber-Rato client registers when it likes, so only the user knows how many to wait
    /// for before a lock-step run starts.
    pub wait_robots: usize,
}

/// Who may register as a Ciber-Rato viewer or panel: a viewer sees the truth (every robot's
/// pose, the scenario's obstacles), which no robot client gets, so by default only this
/// machine may.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Viewers {
    /// Only this machine (loopback addresses), and the `--viewer-allow` list.
    #[default]
    Loopback,
    /// Any address the bridge's socket is reachable from.
    Any,
    /// None, apart from the `--viewer-allow` list.
    Off,
}

impl Viewers {
    /// Whether a viewer or panel registering from `peer` is let in.
    pub fn admits(self, peer: IpAddr, allow: &[IpAddr]) -> bool {
        // An IPv4 peer on a dual-stack socket comes as ::ffff:a.b.c.d.
        let peer = match peer {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(peer, IpAddr::V4),
            v4 => v4,
        };
        allow.contains(&peer)
            || match self {
                Self::Loopback => peer.is_loopback(),
                Self::Any => true,
                Self::Off => false,
            }
    }
}

/// Why the bridge stopped.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// The hub could not be reached, or went away.
    #[error(transparent)]
    Hub(#[from] AgentError),
    /// A socket could not be set up.
    #[error("cannot {what}: {source}")]
    Io {
        /// What was tried.
        what: String,
        /// Why it failed.
        source: std::io::Error,
    },
}

/// Counters of what the bridge refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Datagrams that did not decode.
    pub malformed: u64,
    /// Datagrams to a client's port from another address or port.
    pub foreign: u64,
    /// Registrations the hub refused.
    pub refused: u64,
    /// Clients dropped for silence.
    pub timed_out: u64,
    /// Run commands from viewers and panels ignored for want of `--allow-control`.
    pub ignored_commands: u64,
    /// Viewer and panel registrations refused by `--viewers` (and `--viewer-allow`).
    pub refused_viewers: u64,
}

#[derive(Debug)]
struct RobotClient {
    robot_id: u32,
    /// The client's IR sensor ids, in registration order.
    ir_ids: Vec<u32>,
    real: bool,
    name: String,
    leds: [bool; 3],
    motors: [f64; 2],
    pose: Option<(f64, f64, f64)>,
    say: Option<Vec<u8>>,
    requests: Vec<String>,
    /// Measures sent and Actions received: a robot has answered the tick in hand when it has
    /// sent as many Actions as it was sent Measures (a late reply to an older tick does not
    /// count for the newer one).
    measures_sent: u64,
    actions_received: u64,
    /// The last Measures sent, re-sent every cycle while the run waits or is paused.
    last_measures: Option<Vec<u8>>,
    /// The tick of the last Measures sent: the hub re-publishes a tick when a robot joins,
    /// and only the robots that have not had it yet get it then.
    measured_tick: Option<u64>,
    /// In lock-step, the bridge answered a tick at the deadline without this robot: it is not
    /// waited for again until it sends Actions (a client that speaks only when it changes its
    /// mind, as Ciber-Rato allows, would otherwise cost every tick the whole deadline).
    waited_out: bool,
}

#[derive(Debug)]
enum Kind {
    Robot(Box<RobotClient>),
    Viewer,
    Panel,
}

/// A robot client whose registration the hub has not answered yet (or, accepted, waits for
/// the bridge's ready): it is answered on a later loop turn, so a slow hub never stalls the
/// clients already served.
#[derive(Debug)]
struct Joining {
    socket: UdpSocket,
    peer: SocketAddr,
    robot: codec::RobotRegistration,
    hub_reg: ipc_types::RobotRegistration,
    ir_ids: Vec<u32>,
    /// The request in flight; `None` while queued or once answered.
    request: Option<PendingRequest>,
    /// The robot's id once the hub accepted it.
    robot_id: Option<u32>,
}

#[derive(Debug)]
struct Client {
    socket: UdpSocket,
    peer: SocketAddr,
    kind: Kind,
    last_heard: Instant,
}

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> BridgeError {
    let what = what.into();
    move |source| BridgeError::Io { what, source }
}

fn send(socket: &UdpSocket, peer: SocketAddr, datagram: &[u8]) {
    if let Err(e) = socket.send_to(datagram, peer) {
        tracing::debug!("sending to {peer}: {e}");
    }
}

fn reply_params(map: &Map) -> ReplyParams {
    let p = &map.header.params;
    let req = |bit: u32| p.requestable & bit != 0;
    ReplyParams {
        sim_time: p.sim_time_ticks,
        cycle_ms: map.header.cycle_ms,
        compass_noise: p.noise_compass_deg,
        beacon_noise: p.noise_beacon_deg,
        obstacle_noise: p.noise_proximity_m,
        motors_noise: p.noise_motors_pct,
        gps: p.sensors_on & SENSOR_GPS != 0,
        gps_lin_noise: p.noise_gps_pos_m,
        gps_dir_noise: p.noise_gps_heading_deg,
        beacon_sensor: p.sensors_on & SENSOR_BEACON != 0,
        compass_sensor: p.sensors_on & SENSOR_COMPASS != 0,
        n_beacons: map.header.beacon_count as usize,
        requests_per_cycle: p.requests_per_cycle,
        requestable: [
            req(SENSOR_OBSTACLE),
            req(SENSOR_BEACON),
            req(SENSOR_GROUND),
            req(SENSOR_COMPASS),
            req(SENSOR_COLLISION),
        ],
        latency: [p.latency[0], p.latency[1], p.latency[2], p.latency[3], p.latency[4]],
        beacon_aperture: p.beacon_aperture_rad,
        key_time: p.key_time_ticks,
        scoring: p.scoring,
        score_sensor: p.sensors_on & SENSOR_SCORE != 0,
    }
}

/// Ciber-Rato's default IR sensor angles (`irSensorDefaultAngles`), on the rim.
const CIBER_RATO_IR_ANGLES: [f64; 4] = [0.0, 60.0, -60.0, 180.0];

/// A plain Ciber-Rato robot's diameter, metres: Ciber-Rato measures its labs in robot
/// diameters, and iwsim reads one unit as one metre.
pub const CIBER_RATO_DIAMETER_M: f64 = 1.0;

/// Ciber-Rato's motor filter `out = (in + out_prev)/2` as iwsim's acceleration curve.
const CIBER_RATO_ACCEL_CURVE: f64 = 0.5;

/// The hub registration for a Ciber-Rato / Intellwheels robot on a hub stepping every
/// `cycle_ms` whose parameters give `ObstacleRange` = `obstacle_range_m` (0: none), and the
/// client's IR sensor ids in order; or why it cannot be registered.
///
/// A plain Ciber-Rato robot (no `Width`, `Height`, `COM` or `Type`) gets Ciber-Rato's body
/// and motion: a disc of [`CIBER_RATO_DIAMETER_M`] turning about its centre, whose wheels
/// move [`MAX_POWER`] diameters per cycle at full power (top speed 0.15 m / cycle, 3 m/s at
/// 50 ms), through the filter `(in + out)/2`; and, unless `ObstacleRange` says otherwise, IR
/// sensors of the longest range the hub allows (the real simulator's see as far as the lab
/// goes: far walls read 0.1, not the 1/3 a 3 m range would floor them at). An Intellwheels
/// robot keeps its rectangle and the hub's default range.
pub fn hub_registration(
    r: &codec::RobotRegistration,
    cycle_ms: u32,
    obstacle_range_m: f64,
) -> Result<(ipc_types::RobotRegistration, Vec<u32>), String> {
    let mut reg = ipc_types::RobotRegistration::new(&r.name);
    reg.requested_id = r.id;
    reg.kind = match r.kind {
        Some(RobotType::Real) => RobotKind::Real,
        Some(RobotType::Door) => RobotKind::Door,
        _ => RobotKind::Simulated,
    } as u32;
    let intellwheels = r.width.is_some() || r.height.is_some() || r.com.is_some() || r.kind.is_some();
    if !intellwheels {
        // A hub cycle of 0 ms would mean an infinite speed: the hub never runs one; read it as
        // 1 ms, whose speed the hub refuses with its reason.
        let cycle_s = f64::from(cycle_ms.max(1)) / 1000.0;
        reg =
            reg.disc(CIBER_RATO_DIAMETER_M).motors(MAX_POWER * CIBER_RATO_DIAMETER_M / cycle_s, CIBER_RATO_ACCEL_CURVE);
    }
    if let Some(v) = r.width {
        reg.width_m = v;
    }
    if let Some(v) = r.height {
        reg.height_m = v;
    }
    if let Some(v) = r.com {
        reg.com = v;
    }
    if let Some(v) = r.max_speed {
        reg.max_speed_mps = v;
    }
    if let Some(v) = r.accel_curve {
        reg.accel_curve = v;
    }
    if let (Some(x), Some(y)) = (r.x, r.y) {
        reg.flags |= REG_HAS_POSE;
        reg.pose = [x, y, r.dir.unwrap_or(0.0)];
    }
    // Without <IRSensor> children a Ciber-Rato robot has four sensors at 0, 60, −60 and 180°
    // on its rim; an Intellwheels one (it gave a body) gets thesis Table 4.5's, from the hub.
    let sensors: Vec<codec::IrSensor> = if r.sensors.is_empty() && !intellwheels {
        CIBER_RATO_IR_ANGLES
            .iter()
            .enumerate()
            .map(|(k, &a)| codec::IrSensor { id: k as u32, x: None, y: None, angle_deg: a, cone_deg: None })
            .collect()
    } else {
        r.sensors.clone()
    };
    if sensors.len() > reg.sensors.len() {
        return Err(format!("{} IR sensors; at most {}", sensors.len(), reg.sensors.len()));
    }
    let mut ids = Vec::new();
    for (k, s) in sensors.iter().enumerate() {
        if s.id as usize >= reg.sensors.len() || ids.contains(&s.id) {
            return Err(format!("IR sensor id {} is repeated or not in 0..{}", s.id, reg.sensors.len()));
        }
        // Ciber-Rato sensors sit on the rim of a robot of radius 0.5 and look outwards;
        // Intellwheels ones give their own position and cone.
        let a = s.angle_deg.to_radians();
        reg.sensors[k] = SensorSpec {
            x_m: s.x.unwrap_or(0.5 * a.cos()),
            y_m: s.y.unwrap_or(0.5 * a.sin()),
            angle_deg: s.angle_deg,
            cone_deg: s.cone_deg.unwrap_or(60.0),
            range_m: if intellwheels || obstacle_range_m > 0.0 { 0.0 } else { sim_model::MAX_SENSOR_RANGE_M },
        };
        ids.push(s.id);
    }
    reg.sensor_count = ids.len() as u32;
    if ids.is_empty() {
        ids = vec![0, 1, 2, 3];
    }
    Ok((reg, ids))
}

/// Ciber-Rato `Buttons`: Start when the next state is running, Stop when it is stopped.
fn buttons(state: RunState) -> (bool, bool) {
    match state {
        RunState::Running => (true, false),
        RunState::Waiting | RunState::Paused => (false, true),
        RunState::Finished => (false, false),
    }
}

/// The sensors a robot's requests unlock this tick: the first `limit` requests, each using a
/// slot even when its sensor is not requestable (research §6).
fn honoured(requested: &[String], limit: u32) -> &[String] {
    &requested[..requested.len().min(limit as usize)]
}

/// Whether `request` names sensor `prefix` + `id` (`IRSensor3`), as `format!("{prefix}{id}")`
/// would spell it, without making that string.
fn names_numbered(request: &str, prefix: &str, id: usize) -> bool {
    request.strip_prefix(prefix).is_some_and(|digits| {
        let canonical = digits == "0" || !digits.starts_with('0');
        canonical && digits.bytes().all(|c| c.is_ascii_digit()) && digits.parse::<usize>().ok() == Some(id)
    })
}

/// The measures of one robot for one tick, into `m`, reusing its lists: a bridge keeps one
/// between robots and ticks, so a tick's Measures allocate nothing once warm.
#[allow(clippy::too_many_arguments)] // a robot's block, its tick and its requests, and `m`
pub fn measures_into(
    m: &mut MeasuresData,
    b: &SensorBlock,
    tick: u64,
    state: RunState,
    ir_ids: &[u32],
    leds: [bool; 3],
    map: &Map,
    requested: &[String],
) {
    let p = &map.header.params;
    let requested = honoured(requested, p.requests_per_cycle);
    let asked = |name: &str| requested.iter().any(|r| r == name);
    let asked_numbered = |prefix: &str, id: usize| requested.iter().any(|r| names_numbered(r, prefix, id));
    let allowed = |bit: u32, name: &str| p.requestable & bit == 0 || asked(name);
    let (mut ir, mut beacons, mut messages) =
        (std::mem::take(&mut m.ir), std::mem::take(&mut m.beacons), std::mem::take(&mut m.messages));
    *m = MeasuresData { time: tick, leds, buttons: buttons(state), ..MeasuresData::default() };
    if allowed(SENSOR_COLLISION, "Collision") {
        m.collision = Some(b.present & COLLISION != 0);
    }
    if b.present & HAS_COMPASS != 0 && allowed(SENSOR_COMPASS, "Compass") {
        m.compass = Some(b.compass_deg.round());
    }
    if allowed(SENSOR_GROUND, "Ground") {
        m.ground = Some(if b.present & HAS_GROUND != 0 { b.ground as i32 } else { -1 });
    }
    // Ids were checked at registration to lie in 0..8.
    let max_id = ir_ids.iter().copied().max().unwrap_or(0).min(7) as usize;
    ir.clear();
    ir.resize(max_id + 1, None);
    for (k, &id) in ir_ids.iter().enumerate().take(b.proximity_count as usize) {
        if let (Some(slot), Some(&d)) = (ir.get_mut(id as usize), b.proximity_m.get(k))
            && (p.requestable & SENSOR_OBSTACLE == 0 || asked_numbered("IRSensor", id as usize))
        {
            *slot = Some(sim_model::ir_value(d));
        }
    }
    m.ir = ir;
    beacons.clear();
    if p.sensors_on & SENSOR_BEACON != 0 {
        beacons.extend((0..(b.beacon_count as usize).min(b.beacons_deg.len())).map(|k| {
            (p.requestable & SENSOR_BEACON == 0 || asked_numbered("Beacon", k))
                .then(|| b.beacons_deg.get(k).copied().filter(|v| !v.is_nan()).map(f64::round))
        }));
    }
    m.beacons = beacons;
    if b.present & HAS_GPS != 0 {
        m.gps = Some((b.gps_x_m, b.gps_y_m));
    }
    // Sent every tick, as by the real simulator (it cannot be switched off or requested).
    m.line = Some(b.line_bits as u8);
    if b.present & HAS_SCORE != 0 {
        m.score = Some(score_data(&b.standing, b.present & COLLISION != 0, map.targets.len()));
    }
    messages.clear();
    messages.extend(b.messages().map(|(from, bytes)| (from, bytes.to_vec())));
    m.messages = messages;
}

/// A robot of a world snapshot at `tick` as viewers see it, named from its info.
fn viewer_robot<'a>(
    s: &ipc_types::RobotState,
    info: Option<&'a RobotInfo>,
    tick: u64,
    targets: usize,
) -> ViewerRobot<'a> {
    ViewerRobot {
        name: info.and_then(|i| i.name.as_str()).unwrap_or(""),
        id: s.id,
        time: tick,
        score: score_data(&s.standing, s.flags & ipc_types::ROBOT_COLLISION != 0, targets),
        state: sim_model::CHALLENGE_PHASES.get(s.standing.phase as usize).copied().unwrap_or("Running"),
        width: s.width_m as f64,
        height: s.height_m as f64,
        com: s.com as f64,
        kind: match RobotKind::from_u32(s.kind) {
            Some(RobotKind::Real) => "Real",
            Some(RobotKind::Door) => "Door",
            _ => "Simulated",
        },
        pose: (s.x_m, s.y_m, s.heading_deg),
    }
}

/// A robot's standing as Measures and viewer datagrams carry it.
fn score_data(s: &ChallengeStanding, collision: bool, targets: usize) -> ScoreData {
    ScoreData {
        score: s.score,
        arrival_time: s.arrival_tick,
        returning_time: s.returning_ticks,
        collisions: s.collisions,
        collision,
        visited: s.visited_mask,
        targets,
    }
}

/// The hub's sensor sample of the tick in hand, read where it lies (the agent holds it), with
/// each robot's place in it.
struct Blocks<'a> {
    blocks: &'a [SensorBlock],
    /// (robot id, index in `blocks`), sorted by id.
    index: &'a [(u32, u32)],
}

impl<'a> Blocks<'a> {
    fn get(&self, robot_id: u32) -> Option<&'a SensorBlock> {
        let i = self.index.binary_search_by_key(&robot_id, |&(id, _)| id).ok()?;
        self.blocks.get(self.index[i].1 as usize).filter(|b| b.robot_id == robot_id)
    }
}

/// What a bridge keeps between ticks so that serving one allocates nothing once warm.
#[derive(Debug, Default)]
struct Scratch {
    /// One robot's measures, refilled for each.
    measures: MeasuresData,
    /// One viewer datagram, rewritten for each robot.
    datagram: Vec<u8>,
    /// The actions sent to the hub.
    actions: Vec<ActionBlock>,
}

/// A running bridge.
#[derive(Debug)]
pub struct Bridge {
    cfg: BridgeConfig,
    agent: Agent,
    /// The map as the UDP robots' agent may know it (parameters, beacons, targets).
    map: Map,
    /// The bridge's observer side: the truth it serves to Ciber-Rato viewers (every robot's
    /// pose, the lab with the scenario's obstacles), as the Ciber-Rato simulator serves them.
    /// Its robots' Measures never come from it.
    observer: Observer,
    viewer_map: Map,
    reg: UdpSocket,
    clients: Vec<Client>,
    /// The hub tick the clients' actions answer, and when it arrived.
    tick: Option<(u64, Instant)>,
    run_state: RunState,
    answered: bool,
    is_ready: bool,
    /// The ready request in flight.
    ready: Option<PendingRequest>,
    /// Robots the hub accepted so far (the ready waits for `cfg.wait_robots` of them).
    accepted: usize,
    /// Robot registrations not yet answered, in arrival order.
    joining: Vec<Joining>,
    /// Bad datagrams, logged at a bounded rate.
    noise: NoiseLog,
    /// Where each robot's block lies in the agent's sensor sample of the tick in hand
    /// (robot id, index), sorted by id: the blocks themselves are read in place.
    block_index: Vec<(u32, u32)>,
    scratch: Scratch,
    control: Option<agent_sdk::ControlClient>,
    /// When Measures were last sent: while the run waits or is paused they are re-sent every
    /// cycle, as the simulator does (pClient quits after 2 s without them).
    last_sent: Instant,
    /// Counters of refused input.
    pub counters: Counters,
    /// When an ignored run command was last reported (at most once a second).
    ignored_reported: Option<Instant>,
    /// Whether the run of the last world snapshot was going: while it is not, viewers get its
    /// robots every cycle, as the simulator sends them (the snapshot stays in the observer).
    world_running: bool,
    /// When viewers were last sent their `<Robot>` datagrams.
    last_viewed: Instant,
}

impl Bridge {
    /// Connects to the hub and binds the registration port.
    pub fn start(cfg: BridgeConfig) -> Result<Self, BridgeError> {
        let agent =
            Agent::connect_within(&cfg.session, &format!("udp-bridge-{}", std::process::id()), cfg.connect_timeout)?;
        // Ready only once a UDP robot exists: a bridge with no robots must not count towards
        // a hub's --wait-agents.
        let map = agent.map()?;
        let observer = Observer::connect_within(
            &cfg.session,
            &format!("udp-bridge-viewers-{}", std::process::id()),
            cfg.connect_timeout,
        )?;
        let viewer_map = observer.map()?;
        let reg = UdpSocket::bind((cfg.bind, cfg.port)).map_err(io(format!("bind UDP {}:{}", cfg.bind, cfg.port)))?;
        reg.set_nonblocking(true).map_err(io("make the registration socket non-blocking"))?;
        Ok(Self {
            cfg,
            agent,
            map,
            observer,
            viewer_map,
            reg,
            clients: Vec::new(),
            tick: None,
            run_state: RunState::Waiting,
            answered: true,
            is_ready: false,
            ready: None,
            accepted: 0,
            joining: Vec::new(),
            noise: NoiseLog::new(),
            block_index: Vec::new(),
            scratch: Scratch::default(),
            control: None,
            last_sent: Instant::now(),
            counters: Counters::default(),
            ignored_reported: None,
            world_running: false,
            last_viewed: Instant::now(),
        })
    }

    /// The registration port's address.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.reg.local_addr().ok()
    }

    /// Serves until the hub ends the run or goes away.
    pub fn run(mut self) -> Result<Counters, BridgeError> {
        let (mut fds, mut poller): (Vec<i32>, os::poll::Poller) = Default::default();
        loop {
            fds.clear();
            fds.push(self.reg.as_raw_fd());
            fds.push(self.agent.tick_fd());
            fds.extend(self.clients.iter().map(|c| c.socket.as_raw_fd()));
            // Whatever woke it (or a failed wait), every source is looked at below.
            let _ = poller.wait(&fds, Some(Duration::from_millis(20)));
            self.serve_registrations();
            self.serve_joining()?;
            let changed = self.serve_clients();
            for line in self.noise.due(Instant::now()) {
                tracing::warn!("{line}");
            }
            // Read the hub before judging its liveness: its last tick may be waiting.
            if let Some(tick) = self.agent.try_tick()? {
                self.on_tick(tick.tick, tick.run_state);
            }
            if self.agent.finished() {
                tracing::info!("the hub ended the run");
                return Ok(self.after_the_run());
            }
            self.agent.check_alive()?;
            self.serve_viewers()?;
            self.resend_while_stopped();
            self.answer_hub(changed)?;
            self.drop_silent();
        }
    }

    /// After the run, as the real simulator does: each robot keeps getting its last Measures
    /// every cycle (`Time` frozen, both Buttons off) with the LEDs it sets echoed, and viewers
    /// their robots, until no robot client has spoken for [`GONE_AFTER`] (stock clients quit
    /// when their EndLed comes back on, or 2 s after the Measures stop) or a termination
    /// signal comes. The session's nodes close first: the hub is gone, and nothing of the
    /// session is left in /dev/shm while the bridge lingers.
    fn after_the_run(mut self) -> Counters {
        let tick = self.tick.map_or(0, |t| t.0);
        let blocks = Blocks { blocks: self.agent.sensors(), index: &self.block_index };
        let last: Vec<Option<SensorBlock>> = self
            .clients
            .iter()
            .map(|c| match &c.kind {
                Kind::Robot(r) => blocks.get(r.robot_id).copied(),
                _ => None,
            })
            .collect();
        let views = self.viewer_datagrams();
        let Bridge { agent, control, observer, mut clients, map, viewer_map, counters, mut noise, .. } = self;
        drop(control);
        drop(observer);
        agent.close();
        let cycle = Duration::from_millis(map.header.cycle_ms.max(10) as u64);
        let mut measures = MeasuresData::default();
        let mut datagram = Vec::new();
        let mut buf = [0u8; 65536];
        let (mut fds, mut poller): (Vec<i32>, os::poll::Poller) = Default::default();
        let mut due = Instant::now();
        loop {
            let now = Instant::now();
            let heard = |c: &Client| matches!(c.kind, Kind::Robot(_)) && now.duration_since(c.last_heard) < GONE_AFTER;
            if agent_sdk::stop_signalled() || !clients.iter().any(heard) {
                return counters;
            }
            for c in &mut clients {
                for _ in 0..MAX_READS_PER_SOCKET {
                    let Ok((n, from)) = c.socket.recv_from(&mut buf) else { break };
                    if from != c.peer {
                        continue;
                    }
                    c.last_heard = Instant::now();
                    match &mut c.kind {
                        Kind::Robot(r) => match codec::decode_actions(&buf[..n]) {
                            Ok(a) => apply_actions(r, &a),
                            Err(e) => noisy(&mut noise, from, || format!("actions from {from} dropped: {e}")),
                        },
                        Kind::Viewer | Kind::Panel => match codec::decode_viewer(&buf[..n]) {
                            Ok(ViewerCommand::LabReq) => send(&c.socket, c.peer, &codec::encode_lab(&viewer_map)),
                            Ok(ViewerCommand::GridReq) => send(&c.socket, c.peer, &codec::encode_grid(&map)),
                            // The run is over: nothing left to start, stop or remove.
                            Ok(_) => {}
                            Err(e) => noisy(&mut noise, from, || format!("viewer command from {from} dropped: {e}")),
                        },
                    }
                }
            }
            if now >= due {
                due = now + cycle;
                for (c, b) in clients.iter().zip(&last) {
                    match (&c.kind, b) {
                        (Kind::Robot(r), Some(b)) => {
                            measures_into(&mut measures, b, tick, RunState::Finished, &r.ir_ids, r.leds, &map, &[]);
                            codec::encode_measures_into(&measures, &mut datagram);
                            send(&c.socket, c.peer, &datagram);
                        }
                        (Kind::Viewer, _) => views.iter().for_each(|v| send(&c.socket, c.peer, v)),
                        _ => {}
                    }
                }
            }
            fds.clear();
            fds.extend(clients.iter().map(|c| c.socket.as_raw_fd()));
            let wait = due.saturating_duration_since(Instant::now()).min(Duration::from_secs(1));
            let _ = poller.wait(&fds, Some(wait));
        }
    }

    /// Every robot of the last world snapshot as viewers get it.
    fn viewer_datagrams(&mut self) -> Vec<Vec<u8>> {
        // The names as the hub last published them; a failed look keeps the ones held.
        let _ = self.observer.refresh_robot_info();
        let targets = self.map.targets.len();
        let infos = self.observer.robot_infos();
        let mut out = Vec::new();
        let _ = self.observer.with_last_world(|h, robots| {
            for (k, s) in robots.iter().enumerate() {
                let mut d = Vec::new();
                let info = RobotInfo::find(infos, k, s.id);
                codec::encode_viewer_robot_into(&viewer_robot(s, info, h.tick, targets), &mut d);
                out.push(d);
            }
        });
        out
    }

    fn serve_registrations(&mut self) {
        let mut buf = [0u8; 65536];
        // Bounded, so a flood on the port cannot keep the loop from serving everyone else.
        for _ in 0..MAX_READS_PER_SOCKET {
            let (n, peer) = match self.reg.recv_from(&mut buf) {
                Ok(x) => x,
                Err(e) if e.kind() == ErrorKind::WouldBlock => return,
                Err(e) => {
                    tracing::debug!("registration socket: {e}");
                    return;
                }
            };
            let registration = match codec::decode_registration(&buf[..n]) {
                Ok(r) => r,
                Err(e @ codec::DecodeError::BadRobotId(_)) => {
                    // Ciber-Rato answers a robot it cannot place with a refusal, from a fresh
                    // port like every answer; the client hears no at once instead of timing out.
                    self.counters.malformed += 1;
                    noisy(&mut self.noise, peer, || format!("registration from {peer} refused: {e}"));
                    match UdpSocket::bind((self.cfg.bind, 0)) {
                        Ok(socket) => send(&socket, peer, &codec::encode_refused()),
                        Err(e) => tracing::debug!("cannot open a socket to refuse {peer}: {e}"),
                    }
                    continue;
                }
                Err(e) => {
                    // Ciber-Rato sends no reply to what it cannot parse.
                    self.counters.malformed += 1;
                    noisy(&mut self.noise, peer, || format!("registration from {peer} dropped: {e}"));
                    continue;
                }
            };
            // A viewer or panel registering again from the same address gets its old socket's
            // reply again instead of a new socket each time.
            if matches!(registration, Registration::View | Registration::Panel)
                && let Some(c) = self.clients.iter().find(|c| c.peer == peer && !matches!(c.kind, Kind::Robot(_)))
            {
                send(&c.socket, peer, &codec::encode_reply_ok(&reply_params(&self.map)));
                continue;
            }
            if matches!(registration, Registration::View | Registration::Panel)
                && !self.cfg.viewers.admits(peer.ip(), &self.cfg.viewer_allow)
            {
                self.counters.refused_viewers += 1;
                noisy(&mut self.noise, peer, || {
                    format!(
                        "viewer registration from {peer} refused: viewers see every robot's true pose, and \
                         this bridge admits {} (start it with --viewers any or --viewer-allow {} to let it in)",
                        match self.cfg.viewers {
                            Viewers::Loopback => "this machine's only",
                            Viewers::Any => "any",
                            Viewers::Off => "none",
                        },
                        peer.ip()
                    )
                });
                send(&self.reg, peer, &codec::encode_refused());
                continue;
            }
            if self.clients.len() + self.joining.len() >= MAX_CLIENTS {
                self.counters.refused += 1;
                noisy(&mut self.noise, peer, || {
                    format!("registration from {peer} refused: the bridge serves at most {MAX_CLIENTS} clients")
                });
                send(&self.reg, peer, &codec::encode_refused());
                continue;
            }
            let socket = match UdpSocket::bind((self.cfg.bind, 0)).and_then(|s| s.set_nonblocking(true).map(|_| s)) {
                Ok(s) => s,
                Err(e) => {
                    noisy(&mut self.noise, peer, || {
                        format!("registration from {peer} dropped: cannot open its socket: {e}")
                    });
                    continue;
                }
            };
            let kind = match registration {
                Registration::View => Kind::Viewer,
                Registration::Panel => Kind::Panel,
                Registration::Robot(r) | Registration::RobotBeacon(r) => {
                    match hub_registration(&r, self.map.header.cycle_ms, self.map.header.params.obstacle_range_m) {
                        Ok((hub_reg, ir_ids)) => self.joining.push(Joining {
                            socket,
                            peer,
                            robot: r,
                            hub_reg,
                            ir_ids,
                            request: None,
                            robot_id: None,
                        }),
                        Err(detail) => {
                            self.counters.refused += 1;
                            noisy(&mut self.noise, peer, || {
                                format!(
                                    "robot {:?} from {peer} refused: {:?}: {detail}",
                                    r.name,
                                    ipc_types::Refusal::BadParameters
                                )
                            });
                            // The refusal comes from a fresh port, as the simulator's does.
                            send(&socket, peer, &codec::encode_refused());
                        }
                    }
                    continue;
                }
            };
            send(&socket, peer, &codec::encode_reply_ok(&reply_params(&self.map)));
            tracing::info!("{peer} registered as {kind:?}");
            self.clients.push(Client { socket, peer, kind, last_heard: Instant::now() });
        }
    }

    /// Moves robot registrations along without waiting for the hub: sends queued ones (a few
    /// in flight at a time), reads the answers that came, and admits accepted robots (once the
    /// bridge is ready, when their number reached `wait_robots`).
    fn serve_joining(&mut self) -> Result<(), BridgeError> {
        if self.joining.is_empty() && self.ready.is_none() {
            return Ok(());
        }
        let in_flight = self.joining.iter().filter(|j| j.request.is_some()).count() + self.ready.is_some() as usize;
        let room = MAX_REQUESTS_IN_FLIGHT.saturating_sub(in_flight);
        for j in self.joining.iter_mut().filter(|j| j.request.is_none() && j.robot_id.is_none()).take(room) {
            j.request = Some(self.agent.start_register(&j.hub_reg)?);
        }
        let mut k = 0;
        while k < self.joining.len() {
            let j = &mut self.joining[k];
            let Some(request) = &j.request else {
                k += 1;
                continue;
            };
            match self.agent.poll_pending(request) {
                Ok(None) => k += 1,
                Ok(Some(accepted)) => {
                    j.request = None;
                    j.robot_id = Some(accepted.robot_id);
                    self.accepted += 1;
                    if !self.is_ready && self.ready.is_none() && self.accepted >= self.cfg.wait_robots {
                        self.ready = Some(self.agent.start_ready()?);
                    }
                    k += 1;
                }
                Err(AgentError::Refused { reason, detail }) => {
                    let j = self.joining.remove(k);
                    self.counters.refused += 1;
                    let peer = j.peer;
                    noisy(&mut self.noise, peer, || {
                        format!("robot {:?} from {peer} refused: {reason:?}: {detail}", j.robot.name)
                    });
                    // The refusal comes from a fresh port, as the simulator's does.
                    send(&j.socket, peer, &codec::encode_refused());
                }
                Err(e) => return Err(e.into()),
            }
        }
        if let Some(ready) = &self.ready
            && self.agent.poll_pending(ready)?.is_some()
        {
            self.ready = None;
            self.is_ready = true;
        }
        // While the ready is asked, the accepted robots wait for it (the hub counts the
        // bridge before their first tick). Before that, while `--wait-robots` are still to
        // come, they are admitted at once: a client registering several robots waits for each
        // reply before it sends the next registration.
        if !self.is_ready && self.accepted >= self.cfg.wait_robots {
            return Ok(());
        }
        let (admitted, waiting): (Vec<Joining>, Vec<Joining>) =
            std::mem::take(&mut self.joining).into_iter().partition(|j| j.robot_id.is_some());
        self.joining = waiting;
        for j in admitted {
            let Joining { socket, peer, robot: r, ir_ids, robot_id, .. } = j;
            let kind = Kind::Robot(Box::new(RobotClient {
                robot_id: robot_id.unwrap_or_default(),
                ir_ids,
                real: r.kind == Some(RobotType::Real),
                name: r.name,
                leds: [false; 3],
                motors: [0.0; 2],
                pose: None,
                say: None,
                requests: Vec::new(),
                measures_sent: 0,
                actions_received: 0,
                last_measures: None,
                measured_tick: None,
                waited_out: false,
            }));
            send(&socket, peer, &codec::encode_reply_ok(&reply_params(&self.map)));
            tracing::info!("{peer} registered as {kind:?}");
            let mut client = Client { socket, peer, kind, last_heard: Instant::now() };
            // The hub's sample of the tick in hand may have come while this robot waited for
            // the bridge's ready: its Measures are due now (a run that waits for a Start
            // brings no other tick to send them with).
            if let Some((tick, _)) = self.tick {
                let blocks = Blocks { blocks: self.agent.sensors(), index: &self.block_index };
                send_measures(&mut client, &blocks, &mut self.scratch.measures, tick, self.run_state, &self.map);
            }
            self.clients.push(client);
        }
        Ok(())
    }

    /// Reads every client's datagrams; returns whether some robot's actions changed.
    fn serve_clients(&mut self) -> bool {
        let mut changed = false;
        let mut buf = [0u8; 65536];
        let mut commands = Vec::new();
        for c in &mut self.clients {
            for _ in 0..MAX_READS_PER_SOCKET {
                let Ok((n, from)) = c.socket.recv_from(&mut buf) else { break };
                if from != c.peer {
                    self.counters.foreign += 1;
                    let to = c.peer;
                    noisy(&mut self.noise, from, || format!("datagram to {to}'s port from {from} dropped"));
                    continue;
                }
                c.last_heard = Instant::now();
                match &mut c.kind {
                    Kind::Robot(r) => match codec::decode_actions(&buf[..n]) {
                        Ok(a) => {
                            apply_actions(r, &a);
                            changed = true;
                        }
                        Err(e) => {
                            self.counters.malformed += 1;
                            noisy(&mut self.noise, from, || format!("actions from {from} dropped: {e}"));
                        }
                    },
                    Kind::Viewer | Kind::Panel => match codec::decode_viewer(&buf[..n]) {
                        Ok(cmd) => commands.push((c.socket.try_clone(), c.peer, cmd)),
                        Err(e) => {
                            self.counters.malformed += 1;
                            noisy(&mut self.noise, from, || format!("viewer command from {from} dropped: {e}"));
                        }
                    },
                }
            }
        }
        for (socket, peer, cmd) in commands {
            let Ok(socket) = socket else { continue };
            self.viewer_command(&socket, peer, cmd);
        }
        changed
    }

    /// Sends a run-control command without waiting for the hub's answer.
    fn command(&mut self, command: Command, robot_id: u32) {
        if let Err(e) = agent_sdk::ControlClient::send_lazily(&mut self.control, &self.cfg.session, command, robot_id) {
            tracing::warn!("{command:?} for the hub failed: {e}");
        }
    }

    fn viewer_command(&mut self, socket: &UdpSocket, peer: SocketAddr, cmd: ViewerCommand) {
        match cmd {
            ViewerCommand::LabReq => send(socket, peer, &codec::encode_lab(&self.viewer_map)),
            ViewerCommand::GridReq => send(socket, peer, &codec::encode_grid(&self.map)),
            // Any registered viewer or panel (with --bind 0.0.0.0, any machine on the LAN)
            // would otherwise control every robot, shared-memory ones included.
            ViewerCommand::Start | ViewerCommand::Stop | ViewerCommand::RemoveRobot(_) if !self.cfg.allow_control => {
                self.counters.ignored_commands += 1;
                let now = Instant::now();
                if self.ignored_reported.is_none_or(|t| now.duration_since(t) >= Duration::from_secs(1)) {
                    self.ignored_reported = Some(now);
                    agent_sdk::report!(
                        "iwsim udp: {cmd:?} from {peer} ignored ({} so far): start iwsim udp with --allow-control to let viewers control the run",
                        self.counters.ignored_commands
                    );
                }
            }
            ViewerCommand::Start => self.command(Command::Start, 0),
            ViewerCommand::Stop => self.command(Command::Pause, 0),
            ViewerCommand::RemoveRobot(id) => {
                self.command(Command::RemoveRobot, id);
                self.clients.retain(|c| !matches!(&c.kind, Kind::Robot(r) if r.robot_id == id));
            }
            // A reset of the whole hub is not a viewer's to make: the viewer is told to start
            // over, which is what it needs.
            ViewerCommand::Reset => send(socket, peer, &codec::encode_restart()),
        }
    }

    fn on_tick(&mut self, tick: u64, state: RunState) {
        if self.tick.map(|t| t.0) != Some(tick) {
            self.tick = Some((tick, Instant::now()));
            self.answered = false;
        }
        self.run_state = state;
        let sensors = self.agent.sensors();
        self.block_index.clear();
        self.block_index.extend(sensors.iter().enumerate().map(|(i, b)| (b.robot_id, i as u32)));
        self.block_index.sort_unstable();
        let blocks = Blocks { blocks: sensors, index: &self.block_index };
        for c in &mut self.clients {
            // A tick re-published (a robot joined) goes only to the robots that lack it, so
            // no client gets the same Time twice.
            if let Kind::Robot(r) = &c.kind
                && r.measured_tick == Some(tick)
            {
                continue;
            }
            send_measures(c, &blocks, &mut self.scratch.measures, tick, state, &self.map);
        }
        self.last_sent = Instant::now();
    }

    /// Viewers get one `<Robot>` per robot for every world snapshot, whoever drives the robots,
    /// and while the run waits or is paused (no snapshot comes) the last ones every cycle, as
    /// the simulator sends them every cycle whatever its state.
    fn serve_viewers(&mut self) -> Result<(), BridgeError> {
        // Only viewers read the world: with none there, snapshots are not even received (the
        // newest waits in the observer's queue for the next viewer).
        if !self.clients.iter().any(|c| matches!(c.kind, Kind::Viewer)) {
            return Ok(());
        }
        let due = match self.observer.try_with_world(|h, _| h.run_state)? {
            Some(run_state) => {
                self.world_running = RunState::from_u32(run_state) == Some(RunState::Running);
                true
            }
            None => {
                let cycle = Duration::from_millis(self.map.header.cycle_ms.max(10) as u64);
                !self.world_running && self.last_viewed.elapsed() >= cycle
            }
        };
        if !due {
            return Ok(());
        }
        self.observer.refresh_robot_info()?;
        let (clients, datagram) = (&self.clients, &mut self.scratch.datagram);
        let targets = self.map.targets.len();
        let infos = self.observer.robot_infos();
        // Encoded from the snapshot where the hub wrote it, one robot at a time into one buffer.
        let sent = self.observer.with_last_world(|h, robots| {
            for (k, s) in robots.iter().enumerate() {
                let info = RobotInfo::find(infos, k, s.id);
                codec::encode_viewer_robot_into(&viewer_robot(s, info, h.tick, targets), datagram);
                for c in clients.iter().filter(|c| matches!(c.kind, Kind::Viewer)) {
                    send(&c.socket, c.peer, datagram);
                }
            }
        });
        if sent.is_some() {
            self.last_viewed = Instant::now();
        }
        Ok(())
    }

    /// While the run waits or is paused no tick comes, but the simulator keeps sending
    /// Measures every cycle (stock clients quit after 2 s without them): re-send the last ones.
    fn resend_while_stopped(&mut self) {
        if self.run_state == RunState::Running {
            return;
        }
        let cycle = Duration::from_millis(self.map.header.cycle_ms.max(10) as u64);
        if self.last_sent.elapsed() < cycle {
            return;
        }
        self.last_sent = Instant::now();
        for c in &self.clients {
            if let Kind::Robot(r) = &c.kind
                && let Some(m) = &r.last_measures
            {
                send(&c.socket, c.peer, m);
            }
        }
    }

    /// Sends the UDP robots' actions to the hub. In lock-step: once per tick, when every robot
    /// sent this tick's Measures has answered, or the hub's deadline is near (a silent client
    /// then lags like any agent). In real time: whenever some robot's actions changed.
    fn answer_hub(&mut self, changed: bool) -> Result<(), BridgeError> {
        let Some((tick, since)) = self.tick else { return Ok(()) };
        let p = &self.map.header.params;
        let robots = || self.clients.iter().filter_map(|c| if let Kind::Robot(r) = &c.kind { Some(r) } else { None });
        let mut late = false;
        let due = if p.lockstep != 0 {
            // A robot the hub may have taken but the bridge has not admitted yet is owed this
            // tick's Measures on admission: wait for its answer too (the deadline still holds).
            let all = self.joining.is_empty()
                && self.ready.is_none()
                && robots().all(|r| r.waited_out || r.actions_received >= r.measures_sent);
            // Answer a little before the hub's deadline, so the robots that did act still count.
            let near_deadline = since.elapsed() >= Duration::from_millis(p.deadline_ms as u64 * 9 / 10);
            late = !all;
            !self.answered && (all || near_deadline)
        } else {
            changed
        };
        if !due {
            return Ok(());
        }
        let mut actions = std::mem::take(&mut self.scratch.actions);
        actions.clear();
        actions.extend(robots().map(|r| {
            let mut b = ActionBlock::motors(r.robot_id, r.motors[0], r.motors[1]);
            if r.real {
                b.flags &= !ACT_MOTORS;
                if let Some((x, y, d)) = r.pose {
                    b.flags |= ACT_POSE;
                    b.pose = [x, y, d];
                }
            }
            if let Some(say) = &r.say {
                b.with_say(say);
            }
            b.flags |=
                (r.leds[0] as u32 * LED_END) | (r.leds[1] as u32 * LED_RETURNING) | (r.leds[2] as u32 * LED_VISITING);
            b
        }));
        let sent = self.agent.send(tick, &actions);
        self.scratch.actions = actions;
        sent?;
        self.answered = true;
        for c in &mut self.clients {
            if let Kind::Robot(r) = &mut c.kind {
                r.say = None;
                // Answered at the deadline without it: not waited for until it speaks again.
                if late && r.actions_received < r.measures_sent {
                    r.waited_out = true;
                }
            }
        }
        Ok(())
    }

    fn drop_silent(&mut self) {
        // Only robots must talk every tick, and only while the run is going; viewers send a
        // command now and then.
        if self.run_state != RunState::Running {
            for c in &mut self.clients {
                c.last_heard = Instant::now();
            }
            return;
        }
        // Ciber-Rato never removes a robot for silence: only when the user asked for it.
        let Some(timeout) = self.cfg.client_timeout else { return };
        let mut gone = Vec::new();
        self.clients.retain(|c| {
            let Kind::Robot(r) = &c.kind else { return true };
            if c.last_heard.elapsed() < timeout {
                return true;
            }
            tracing::warn!("robot {} ({:?}) silent for {timeout:?}: removed", r.robot_id, r.name);
            gone.push(r.robot_id);
            false
        });
        self.counters.timed_out += gone.len() as u64;
        for id in gone {
            self.command(Command::RemoveRobot, id);
        }
    }
}

/// Datagrams read from one socket per loop: enough for any honest client, and a flood on one
/// port cannot starve the others.
const MAX_READS_PER_SOCKET: usize = 64;
/// After the run, a robot client silent this long has left (stock clients quit 2 s after
/// their last Measures, or at once when their EndLed comes back on).
const GONE_AFTER: Duration = Duration::from_secs(2);
/// Clients one bridge serves (each has a socket).
const MAX_CLIENTS: usize = 512;
/// Robot registrations sent to the hub and not yet answered, counting the ready request: the
/// hub holds 4 requests per agent, and one slot stays free for the bridge's goodbye.
const MAX_REQUESTS_IN_FLIGHT: usize = 2;
/// Sensor requests kept per robot between ticks.
const MAX_REQUESTS: usize = 64;

/// Sends a robot client its Measures for `tick`, if the hub's sample has its robot's block,
/// written into the client's kept datagram (re-sent while the run is stopped).
fn send_measures(
    c: &mut Client,
    blocks: &Blocks<'_>,
    scratch: &mut MeasuresData,
    tick: u64,
    state: RunState,
    map: &Map,
) {
    if let Kind::Robot(r) = &mut c.kind
        && let Some(b) = blocks.get(r.robot_id)
    {
        measures_into(scratch, b, tick, state, &r.ir_ids, r.leds, map, &r.requests);
        r.requests.clear();
        let datagram = r.last_measures.get_or_insert_with(Vec::new);
        codec::encode_measures_into(scratch, datagram);
        send(&c.socket, c.peer, datagram);
        r.measured_tick = Some(tick);
        r.measures_sent += 1;
        // A client that is behind never owes more than the tick in hand.
        r.actions_received = r.actions_received.max(r.measures_sent.saturating_sub(1));
    }
}

/// Logs a bad datagram from `peer` if the rate limit allows; the caller counts it either way.
fn noisy(log: &mut NoiseLog, peer: SocketAddr, what: impl FnOnce() -> String) {
    if let Some(line) = log.note(peer, Instant::now(), what) {
        tracing::warn!("{line}");
    }
}

fn apply_actions(r: &mut RobotClient, a: &Actions) {
    let power = |p: f64| p.clamp(-MAX_POWER, MAX_POWER) / MAX_POWER;
    if let Some(l) = a.left {
        r.motors[0] = power(l);
    }
    if let Some(rt) = a.right {
        r.motors[1] = power(rt);
    }
    for (k, v) in [a.end_led, a.returning_led, a.visiting_led].into_iter().enumerate() {
        if let Some(on) = v {
            r.leds[k] = on;
        }
    }
    if a.pose.is_some() {
        r.pose = a.pose;
    }
    if let Some(s) = &a.say
        && s.len() <= ipc_types::MESSAGE_BYTES
    {
        r.say = Some(s.clone());
    }
    let room = MAX_REQUESTS.saturating_sub(r.requests.len());
    r.requests.extend(a.requests.iter().take(room).cloned());
    // Stock clients send exactly one <Actions> per <Measures> (<Sync/> says so explicitly):
    // count them, never beyond the Measures sent.
    r.actions_received = (r.actions_received + 1).min(r.measures_sent);
    r.waited_out = false;
}

#[cfg(test)]
mod registration_tests {
    use super::*;
    use ipc_types::REG_DISC;

    fn decode(xml: &str) -> codec::RobotRegistration {
        match codec::decode_registration(xml.as_bytes()) {
            Ok(Registration::Robot(r)) => r,
            other => panic!("not a robot registration: {other:?}"),
        }
    }

    #[test]
    fn a_plain_robot_becomes_a_ciber_rato_disc_at_the_hubs_cycle() {
        let plain = decode(r#"<Robot Name="pClient" Id="2"/>"#);
        let (reg, ids) = hub_registration(&plain, 50, 0.0).expect("valid");
        assert_ne!(reg.flags & REG_DISC, 0);
        assert_eq!((reg.width_m, reg.height_m, reg.com), (1.0, 1.0, 0.5));
        // 0.15 m per 50 ms cycle at full power, filtered by (in + out)/2.
        assert!((reg.max_speed_mps - 3.0).abs() < 1e-12, "{}", reg.max_speed_mps);
        assert_eq!(reg.accel_curve, 0.5);
        assert_eq!((reg.requested_id, reg.kind), (2, RobotKind::Simulated as u32));
        // Four IR sensors on the rim (radius 0.5) at 0, 60, −60 and 180°, ±30° cones.
        assert_eq!(ids, [0, 1, 2, 3]);
        assert_eq!(reg.sensor_count, 4);
        for (s, a) in reg.sensors.iter().zip([0.0f64, 60.0, -60.0, 180.0]) {
            assert!((s.x_m.hypot(s.y_m) - 0.5).abs() < 1e-12);
            assert!((s.x_m - 0.5 * a.to_radians().cos()).abs() < 1e-12);
            assert_eq!((s.angle_deg, s.cone_deg), (a, 60.0));
            // The real simulator's IR sees as far as the lab goes: the longest range allowed.
            assert_eq!(s.range_m, 20.0);
        }
        // With an ObstacleRange in the parameters, the hub's range (0 here means "the hub's").
        let (ranged, _) = hub_registration(&plain, 50, 2.5).expect("valid");
        assert!(ranged.sensors[..4].iter().all(|s| s.range_m == 0.0));
        // The top speed follows the hub's cycle: 0.15 m per 100 ms cycle.
        let (slow, _) = hub_registration(&plain, 100, 0.0).expect("valid");
        assert!((slow.max_speed_mps - 1.5).abs() < 1e-12);
        // Sensors registered at other angles sit on the rim too.
        let two = decode(r#"<Robot Name="r"><IRSensor Id="0" Angle="90"/><IRSensor Id="1" Angle="-90"/></Robot>"#);
        let (reg, ids) = hub_registration(&two, 50, 0.0).expect("valid");
        assert_eq!((ids, reg.sensor_count, reg.flags & REG_DISC), (vec![0, 1], 2, REG_DISC));
        assert!(reg.sensors[0].x_m.abs() < 1e-12 && (reg.sensors[0].y_m - 0.5).abs() < 1e-12);
    }

    #[test]
    fn an_intellwheels_robot_keeps_its_rectangle_and_motors() {
        let chair = decode(
            r#"<Robot Name="chair" Width="1.2" Height="0.7" COM="0.8" MaxSpeed="0.6" AccelerationCurve="0.83"/>"#,
        );
        let (reg, _) = hub_registration(&chair, 50, 0.0).expect("valid");
        assert_eq!(reg.flags & REG_DISC, 0);
        assert_eq!((reg.width_m, reg.height_m, reg.com), (1.2, 0.7, 0.8));
        assert_eq!((reg.max_speed_mps, reg.accel_curve), (0.6, 0.83));
        assert!(reg.sensors[..reg.sensor_count as usize].iter().all(|s| s.range_m == 0.0), "the hub's default range");
        // A Type alone marks an Intellwheels robot too: thesis defaults, not a disc.
        let door = decode(r#"<Robot Name="door" Type="door"/>"#);
        let (reg, _) = hub_registration(&door, 50, 0.0).expect("valid");
        assert_eq!(reg.flags & REG_DISC, 0);
        assert_eq!((reg.max_speed_mps, reg.kind), (0.5, RobotKind::Door as u32));
    }
}

#[cfg(test)]
mod measures_tests {
    use super::*;

    #[test]
    fn a_numbered_request_matches_exactly_the_name_format_would_make() {
        let requests = [
            "IRSensor3",
            "IRSensor03",
            "IRSensor+3",
            "IRSensor",
            "IRSensor 3",
            "IRSensor30",
            "Beacon0",
            "Beacon00",
            "x",
        ];
        for r in requests {
            for prefix in ["IRSensor", "Beacon"] {
                for id in [0, 3, 30, 300] {
                    assert_eq!(names_numbered(r, prefix, id), r == format!("{prefix}{id}"), "{r} {prefix}{id}");
                }
            }
        }
    }

    #[test]
    fn measures_refilled_in_place_are_the_measures_made_afresh() {
        let mut b =
            SensorBlock { robot_id: 1, proximity_count: 3, present: HAS_COMPASS, ..bytemuck::Zeroable::zeroed() };
        b.proximity_m[..3].copy_from_slice(&[0.5, 1.25, 3.0]);
        b.compass_deg = 12.6;
        let map = Map::default();
        let mut kept = MeasuresData {
            ir: vec![Some(9.0); 8],
            beacons: vec![None; 3],
            messages: vec![(1, b"old".to_vec())],
            ..MeasuresData::default()
        };
        for (ids, tick) in [(&[0u32, 1, 2][..], 7), (&[2, 0][..], 8), (&[5][..], 9)] {
            measures_into(&mut kept, &b, tick, RunState::Running, ids, [true, false, false], &map, &[]);
            let mut fresh = MeasuresData::default();
            measures_into(&mut fresh, &b, tick, RunState::Running, ids, [true, false, false], &map, &[]);
            assert_eq!(kept, fresh);
        }
    }
}

#[cfg(test)]
mod viewer_tests {
    use super::*;

    #[test]
    fn viewers_are_let_in_from_this_machine_only_unless_told_otherwise() {
        let lan: IpAddr = "192.168.1.20".parse().expect("ip");
        let mapped: IpAddr = "::ffff:192.168.1.20".parse().expect("ip");
        let local: IpAddr = "127.0.0.1".parse().expect("ip");
        let local6: IpAddr = "::1".parse().expect("ip");
        assert!(Viewers::Loopback.admits(local, &[]) && Viewers::Loopback.admits(local6, &[]));
        assert!(!Viewers::Loopback.admits(lan, &[]) && !Viewers::Loopback.admits(mapped, &[]));
        assert!(Viewers::Loopback.admits(lan, &[lan]) && Viewers::Loopback.admits(mapped, &[lan]));
        assert!(Viewers::Any.admits(lan, &[]));
        assert!(!Viewers::Off.admits(local, &[]) && Viewers::Off.admits(local, &[local]));
        assert_eq!(Viewers::default(), Viewers::Loopback);
    }
}
