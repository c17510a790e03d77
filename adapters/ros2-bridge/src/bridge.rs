//! The bridge: a hub client that registers chairs and serves each as a ROS 2 base driver on
//! Zenoh, in rmw_zenoh's wire format.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use agent_sdk::inbox::{Doorbell, Inbox, inbox};
use agent_sdk::map::Map;
use agent_sdk::odometry::Odometry;
use agent_sdk::{Agent, AgentError};
use ipc_types::{ActionBlock, COLLISION, HAS_COMPASS, RobotRegistration, SensorBlock, SensorSpec};
use sim_model::{Pose, PoseDeg, chair};
use zenoh::Wait as _;

use crate::drive::{self, Cone};
use crate::msgs::{self, Message, TypeDesc};
use crate::names::{self, EntityKind, Node, Qos};

/// What went wrong.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// The hub.
    #[error("the hub: {0}")]
    Hub(#[from] AgentError),
    /// Zenoh.
    #[error("Zenoh: {0}")]
    Zenoh(String),
    /// The options.
    #[error("{0}")]
    Options(String),
}

fn zerr<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> Ros2Error + '_ {
    move |e| Ros2Error::Zenoh(format!("{what}: {e}"))
}

/// A chair to serve: its name (the ROS namespace `/NAME`) and start pose (x, y metres,
/// heading degrees; none: the map's grid slot).
#[derive(Debug, Clone, PartialEq)]
pub struct ChairSpec {
    /// Name and namespace.
    pub name: String,
    /// Start pose in its wire form (as registered).
    pub pose: Option<PoseDeg>,
}

/// How the bridge runs.
#[derive(Debug, Clone)]
pub struct Ros2Config {
    /// The hub's session.
    pub session: String,
    /// How long to wait for the hub.
    pub connect_timeout: Duration,
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// The chairs.
    pub chairs: Vec<ChairSpec>,
    /// Simulated seconds a `cmd_vel` holds before the chair stops (a base driver's
    /// zero-velocity timeout).
    pub cmd_vel_timeout_s: f64,
    /// Tell the hub the bridge is ready only once every chair has a controller (a
    /// publisher on its `cmd_vel`).
    pub wait_controllers: bool,
    /// Publish `map → odom` (the start pose) on each chair's `tf_static`.
    pub map_to_odom: bool,
    /// The scan's angle between rays, radians.
    pub scan_step_rad: f64,
}

/// The body and sensors the bridge registers: the Intellwheels chair.
pub fn registration(name: &str, pose: Option<PoseDeg>) -> RobotRegistration {
    let [length, width, com] = chair::BODY;
    let mut reg =
        RobotRegistration::new(name).body(length, width, com).motors(chair::MAX_SPEED_MPS, chair::ACCEL_CURVE).at(pose);
    for (spec, m) in reg.sensors.iter_mut().zip(&chair::SENSORS) {
        *spec = SensorSpec { x_m: m.x_m, y_m: m.y_m, angle_deg: m.angle_deg, cone_deg: m.cone_deg, range_m: m.range_m };
    }
    reg.sensor_count = chair::SENSORS.len().min(reg.sensors.len()) as u32;
    reg
}

/// What Zenoh's threads hand the loop.
enum Event {
    /// A `cmd_vel` sample for chair `k`.
    CmdVel { k: usize, bytes: Vec<u8> },
    /// A graph token came (`true`) or went.
    Token { key: String, up: bool },
}

/// Events kept for the loop at most (a flood waits, or is dropped, in Zenoh's queues).
const MAX_EVENTS: usize = 4096;

fn now_ns() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as i64)
}

/// A ROS 2 graph on one Zenoh session: nodes and their entities, each with its liveliness
/// token, ids from one counter as rmw_zenoh numbers them within a context.
struct Graph {
    z: zenoh::Session,
    domain: u32,
    zid: String,
    next_id: u32,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl Graph {
    fn token(&mut self, key: String) -> Result<(), Ros2Error> {
        let t = self.z.liveliness().declare_token(key).wait().map_err(zerr("declare a liveliness token"))?;
        self.tokens.push(t);
        Ok(())
    }

    fn node(&mut self, namespace: &str, name: &str) -> Result<Node, Ros2Error> {
        let node = Node {
            domain: self.domain,
            zid: self.zid.clone(),
            id: self.next_id,
            namespace: namespace.to_owned(),
            name: name.to_owned(),
        };
        self.next_id += 1;
        self.token(node.token())?;
        Ok(node)
    }

    fn publisher(&mut self, node: &Node, topic: &str, ty: &'static TypeDesc, qos: Qos) -> Result<Topic, Ros2Error> {
        let entity = self.next_id;
        self.next_id += 1;
        let token = node.entity_token(entity, EntityKind::Publisher, topic, ty, qos);
        let key = names::data_key(self.domain, topic, ty);
        let publisher = self.z.declare_publisher(key.clone()).wait().map_err(zerr("declare a publisher"))?;
        let gid = names::gid(&token);
        self.token(token)?;
        Ok(Topic { entity, key, gid, seq: 0, publisher, buf: Vec::new() })
    }

    /// A transient-local publisher: late subscribers get its last sample (as rmw_zenoh's
    /// advanced publisher's cache gives it: a queryable and a token on `<key>/@adv/pub/…`).
    fn latched(&mut self, node: &Node, topic: &str, ty: &'static TypeDesc) -> Result<Latched, Ros2Error> {
        let topic = self.publisher(node, topic, ty, Qos::latched(1))?;
        let cache_key = names::cache_key(&topic.key, &self.zid, topic.entity);
        let last: Cache = Arc::default();
        let (kept, reply_key) = (last.clone(), topic.key.clone());
        let queryable = self
            .z
            .declare_queryable(cache_key.clone())
            .callback(move |q| {
                let sample = kept.lock().unwrap_or_else(|p| p.into_inner()).clone();
                // Replied on the topic's own key, as the cache does (the query accepts any key).
                if let Some((bytes, attachment)) = sample {
                    let _ = q.reply(reply_key.clone(), bytes).attachment(attachment.to_vec()).wait();
                }
            })
            .wait()
            .map_err(zerr("declare a publication cache"))?;
        self.token(cache_key)?;
        Ok(Latched { topic, last, _queryable: queryable })
    }

    fn subscription(&mut self, node: &Node, topic: &str, ty: &'static TypeDesc, qos: Qos) -> Result<String, Ros2Error> {
        let entity = self.next_id;
        self.next_id += 1;
        self.token(node.entity_token(entity, EntityKind::Subscription, topic, ty, qos))?;
        Ok(names::data_key(self.domain, topic, ty))
    }
}

/// A publisher with rmw_zenoh's attachment on every sample.
struct Topic {
    entity: u32,
    key: String,
    gid: [u8; 16],
    seq: i64,
    publisher: zenoh::pubsub::Publisher<'static>,
    buf: Vec<u8>,
}

impl Topic {
    fn put<M: Message>(&mut self, msg: &M) -> [u8; 33] {
        let mut w = crate::cdr::Writer::reusing(std::mem::take(&mut self.buf));
        msg.write(&mut w);
        let bytes = w.finish();
        self.seq += 1;
        let attachment = names::attachment(self.seq, now_ns(), &self.gid);
        if let Err(e) = self.publisher.put(bytes.clone()).attachment(attachment.to_vec()).wait() {
            tracing::warn!("{}: {e}", self.key);
        }
        self.buf = bytes;
        attachment
    }
}

/// A latched topic's last sample (CDR and attachment), which its cache's queries get.
type Cache = Arc<Mutex<Option<(Vec<u8>, [u8; 33])>>>;

struct Latched {
    topic: Topic,
    last: Cache,
    _queryable: zenoh::query::Queryable<()>,
}

impl Latched {
    fn put<M: Message>(&mut self, msg: &M) {
        let attachment = self.topic.put(msg);
        *self.last.lock().unwrap_or_else(|p| p.into_inner()) = Some((self.topic.buf.clone(), attachment));
    }
}

/// One chair's topics and state.
struct Chair {
    name: String,
    id: u32,
    /// The start pose: the `odom` frame's origin in the map.
    start: Pose,
    odometry: Odometry,
    /// The last estimate in the map frame and when (simulated seconds), for the twist.
    last: Option<(Pose, f64)>,
    /// The last command and the simulated time it came at.
    command: Option<(msgs::Twist, f64)>,
    /// The tick this chair's controller answered last (lock-step).
    answered: Option<u64>,
    /// A controller that missed a deadline is not waited for until it speaks again.
    waited_out: bool,
    /// A `cmd_vel` sample came.
    heard: bool,
    /// Graph tokens of publishers on its `cmd_vel`.
    controllers: BTreeSet<String>,
    cmd_vel_topic: String,
    odom: Topic,
    tf: Topic,
    scan: Topic,
    imu: Topic,
    bumper: Topic,
    ranges: Vec<Topic>,
    /// Kept: its cache answers late subscribers.
    _tf_static: Latched,
    _cmd_vel: zenoh::pubsub::Subscriber<()>,
}

impl Chair {
    fn controlled(&self) -> bool {
        self.heard || !self.controllers.is_empty()
    }
}

/// The bridge.
pub struct Bridge {
    cfg: Ros2Config,
    agent: Agent,
    map: Map,
    _graph: Graph,
    chairs: Vec<Chair>,
    by_id: BTreeMap<u32, usize>,
    clock: Topic,
    /// Kept: its cache answers late subscribers.
    _map: Latched,
    events: Arc<Inbox<Event>>,
    wake: Doorbell,
    _tokens: zenoh::pubsub::Subscriber<()>,
    cones: Vec<Cone>,
    tick: Option<(u64, f64, Instant)>,
    sent: Option<u64>,
    actions: Vec<ActionBlock>,
    /// A tick or a command came since the last answer.
    dirty: bool,
    /// `cmd_vel` samples that were not a Twist.
    pub malformed: u64,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge").field("session", &self.cfg.session).field("domain", &self.cfg.domain).finish()
    }
}

impl Bridge {
    /// Connects to the hub, registers the chairs and declares their topics on `z`.
    pub fn start(cfg: Ros2Config, z: zenoh::Session) -> Result<Self, Ros2Error> {
        if cfg.chairs.is_empty() {
            return Err(Ros2Error::Options("no chair to serve: give --chair NAME at least once".into()));
        }
        let mut seen = BTreeSet::new();
        for c in &cfg.chairs {
            let ok = !c.name.is_empty()
                && c.name.len() < 64
                && c.name.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
                && !c.name.starts_with(|ch: char| ch.is_ascii_digit());
            if !ok {
                return Err(Ros2Error::Options(format!(
                    "chair name {:?}: a ROS namespace takes letters, digits and '_', not starting with a digit",
                    c.name
                )));
            }
            if !seen.insert(c.name.as_str()) {
                return Err(Ros2Error::Options(format!("chair {:?} is given twice", c.name)));
            }
        }
        let mut agent =
            Agent::connect_within(&cfg.session, &format!("ros2-bridge-{}", std::process::id()), cfg.connect_timeout)?;
        let map = agent.map()?;
        let (events, wake) = inbox::<Event>(MAX_EVENTS).map_err(zerr("make a wake-up socket"))?;
        let mut graph =
            Graph { zid: z.zid().to_string(), z: z.clone(), domain: cfg.domain, next_id: 0, tokens: Vec::new() };
        let root = graph.node("/", "iwsim")?;
        let clock = graph.publisher(&root, "/clock", &msgs::CLOCK, Qos::sensor_data(1))?;
        let mut map_topic = graph.latched(&root, "/map", &msgs::OCCUPANCY_GRID)?;
        map_topic.put(&occupancy_grid(&map));
        let mut chairs = Vec::new();
        let mut by_id = BTreeMap::new();
        for (k, spec) in cfg.chairs.iter().enumerate() {
            let id = agent.register(&registration(&spec.name, spec.pose))?;
            let start = match spec.pose {
                Some(wire) => Pose::from_wire_deg(wire),
                None => map
                    .grid
                    .get(id as usize - 1)
                    .map_or(Pose::default(), |g| Pose::from_deg(g.pos.x, g.pos.y, g.heading_deg)),
            };
            let chair = serve_chair(&mut graph, &events, &z, k, spec, id, start, &map, &cfg)?;
            by_id.insert(id, k);
            chairs.push(chair);
        }
        let ev = events.clone();
        let tokens = z
            .liveliness()
            .declare_subscriber(format!("{}/{}/**", names::ADMIN_SPACE, cfg.domain))
            .history(true)
            .callback(move |s: zenoh::sample::Sample| {
                let up = s.kind() == zenoh::sample::SampleKind::Put;
                ev.push(Event::Token { key: s.key_expr().as_str().to_owned(), up });
            })
            .wait()
            .map_err(zerr("watch the ROS graph"))?;
        let cones = chair::SENSORS
            .iter()
            .map(|m| Cone {
                at: [m.x_m, m.y_m],
                axis_rad: m.angle_deg.to_radians(),
                cone_rad: m.cone_deg.to_radians(),
                range_m: m.range_m,
            })
            .collect();
        Ok(Self {
            cfg,
            agent,
            map,
            _graph: graph,
            chairs,
            by_id,
            clock,
            _map: map_topic,
            events,
            wake,
            _tokens: tokens,
            cones,
            tick: None,
            sent: None,
            actions: Vec::new(),
            dirty: false,
            malformed: 0,
        })
    }

    fn lockstep(&self) -> bool {
        self.map.header.params.lockstep != 0
    }

    /// Waits for the hub's tick or a Zenoh event, at most `timeout`; handles the events.
    fn wait(&mut self, timeout: Duration) {
        self.wake.wait(Some(self.agent.tick_fd()), timeout.min(Duration::from_secs(1)));
        while let Some(e) = self.events.take() {
            self.on_event(e);
        }
    }

    fn on_event(&mut self, e: Event) {
        match e {
            Event::CmdVel { k, bytes } => match msgs::Twist::from_cdr(&bytes) {
                Ok(t) => {
                    let now = self.tick.map_or(0.0, |(_, s, _)| s);
                    let tick = self.tick.map(|(t, _, _)| t);
                    let c = &mut self.chairs[k];
                    c.command = Some((t, now));
                    self.dirty = true;
                    c.heard = true;
                    c.waited_out = false;
                    // The answer to the tick whose readings it was published after.
                    if c.answered < tick {
                        c.answered = tick;
                    }
                }
                Err(e) => {
                    // Said once; a flood of junk is counted, not logged.
                    if self.malformed == 0 {
                        tracing::warn!("{}'s cmd_vel is not a geometry_msgs/msg/Twist: {e}", self.chairs[k].name);
                    }
                    self.malformed += 1;
                }
            },
            Event::Token { key, up } => {
                // @ros2_lv/<domain>/<zid>/<node>/<entity>/MP/<enclave>/<ns>/<name>/<topic>/…
                let parts: Vec<&str> = key.split('/').collect();
                if parts.len() < 13 || parts[5] != "MP" {
                    return;
                }
                for c in &mut self.chairs {
                    if parts[9] == c.cmd_vel_topic {
                        if up {
                            c.controllers.insert(key.clone());
                        } else {
                            c.controllers.remove(&key);
                        }
                    }
                }
            }
        }
    }

    /// Serves until the hub ends the run, goes away, or a stop signal comes.
    pub fn run(mut self) -> Result<u64, Ros2Error> {
        if self.cfg.wait_controllers {
            let mut told = Instant::now() - Duration::from_secs(10);
            while !self.chairs.iter().all(Chair::controlled) {
                if told.elapsed() >= Duration::from_secs(5) {
                    let waiting: Vec<_> = self
                        .chairs
                        .iter()
                        .filter(|c| !c.controlled())
                        .map(|c| format!("/{}/cmd_vel", c.name))
                        .collect();
                    agent_sdk::report!("iwsim ros2: waiting for a controller on {}", waiting.join(", "));
                    told = Instant::now();
                }
                self.wait(Duration::from_millis(50));
                self.agent.check_alive()?;
            }
        }
        self.agent.ready()?;
        agent_sdk::report!(
            "iwsim ros2: serving {} on ROS_DOMAIN_ID {} ({})",
            self.chairs.iter().map(|c| format!("/{}", c.name)).collect::<Vec<_>>().join(", "),
            self.cfg.domain,
            if self.lockstep() { "lock-step: each tick waits for every controller's cmd_vel" } else { "real time" }
        );
        let mut checked = Instant::now();
        loop {
            let timeout = self.next_wake();
            self.wait(timeout);
            if let Some(tick) = self.agent.try_tick()? {
                self.on_tick(tick.tick, tick.sim_time_s);
            }
            self.answer_hub()?;
            if self.agent.finished() {
                return Ok(self.malformed);
            }
            if checked.elapsed() >= Duration::from_millis(10) {
                self.agent.check_alive()?;
                checked = Instant::now();
            }
        }
    }

    fn deadline(&self) -> Duration {
        Duration::from_millis(u64::from(self.map.header.params.deadline_ms) * 9 / 10)
    }

    fn next_wake(&self) -> Duration {
        let idle = Duration::from_millis(20);
        match self.tick {
            Some((tick, _, since)) if self.lockstep() && self.sent != Some(tick) => {
                self.deadline().saturating_sub(since.elapsed()).clamp(Duration::from_millis(1), idle)
            }
            _ => idle,
        }
    }

    /// Publishes the tick's clock and every chair's readings.
    fn on_tick(&mut self, tick: u64, sim_time_s: f64) {
        self.tick = Some((tick, sim_time_s, Instant::now()));
        let stamp = msgs::Time::from_secs(sim_time_s);
        self.clock.put(&msgs::Clock { clock: stamp });
        let params = self.map.header.params;
        let cycle_s = f64::from(self.map.header.cycle_ms) / 1000.0;
        let step = self.cfg.scan_step_rad;
        for b in self.agent.sensors() {
            let Some(&k) = self.by_id.get(&b.robot_id) else { continue };
            publish_readings(&mut self.chairs[k], b, stamp, sim_time_s, &self.cones, &params, step, cycle_s);
        }
        self.dirty = true;
    }

    /// Sends the chairs' commands: in real time at every change; in lock-step once a tick,
    /// when every controller waited for has answered it, or near the hub's deadline.
    fn answer_hub(&mut self) -> Result<(), Ros2Error> {
        let Some((tick, now, since)) = self.tick else { return Ok(()) };
        if self.lockstep() {
            if self.sent == Some(tick) {
                return Ok(());
            }
            let all = self.chairs.iter().all(|c| !c.controlled() || c.waited_out || c.answered >= Some(tick));
            if !all {
                if since.elapsed() < self.deadline() {
                    return Ok(());
                }
                for c in &mut self.chairs {
                    if c.controlled() && c.answered < Some(tick) && !c.waited_out {
                        tracing::warn!("/{}: no cmd_vel for tick {tick} before the deadline", c.name);
                        c.waited_out = true;
                    }
                }
            }
        } else if !self.dirty {
            return Ok(());
        }
        self.dirty = false;
        self.actions.clear();
        let timeout = self.cfg.cmd_vel_timeout_s;
        let (max, track) = (chair::MAX_SPEED_MPS, chair::BODY[1]);
        for c in &self.chairs {
            let p = match c.command {
                Some((t, at)) if now - at <= timeout => drive::powers(t.linear[0], t.angular[2], max, track),
                _ => [0.0, 0.0],
            };
            self.actions.push(ActionBlock::motors(c.id, p[0], p[1]));
        }
        self.agent.send(tick, &self.actions)?;
        self.sent = Some(tick);
        Ok(())
    }
}

#[allow(clippy::too_many_arguments)]
fn serve_chair(
    graph: &mut Graph,
    events: &Arc<Inbox<Event>>,
    z: &zenoh::Session,
    k: usize,
    spec: &ChairSpec,
    id: u32,
    start: Pose,
    map: &Map,
    cfg: &Ros2Config,
) -> Result<Chair, Ros2Error> {
    let ns = format!("/{}", spec.name);
    let node = graph.node(&ns, "base_driver")?;
    let topic = |t: &str| format!("{ns}/{t}");
    let odom = graph.publisher(&node, &topic("odom"), &msgs::ODOMETRY, Qos::reliable(10))?;
    let tf = graph.publisher(&node, &topic("tf"), &msgs::TF_MESSAGE, Qos::reliable(100))?;
    let scan = graph.publisher(&node, &topic("scan"), &msgs::LASER_SCAN, Qos::sensor_data(5))?;
    let imu = graph.publisher(&node, &topic("imu"), &msgs::IMU, Qos::sensor_data(5))?;
    let bumper = graph.publisher(&node, &topic("bumper"), &msgs::BOOL, Qos::reliable(10))?;
    let mut ranges = Vec::new();
    for i in 0..chair::SENSORS.len() {
        ranges.push(graph.publisher(&node, &topic(&format!("range/prox{i}")), &msgs::RANGE, Qos::sensor_data(5))?);
    }
    let mut tf_static = graph.latched(&node, &topic("tf_static"), &msgs::TF_MESSAGE)?;
    let cmd_vel_key = graph.subscription(&node, &topic("cmd_vel"), &msgs::TWIST, Qos::reliable(10))?;
    let ev = events.clone();
    let cmd_vel = z
        .declare_subscriber(cmd_vel_key)
        .callback(move |s: zenoh::sample::Sample| {
            ev.push(Event::CmdVel { k, bytes: s.payload().to_bytes().into_owned() });
        })
        .wait()
        .map_err(zerr("subscribe to cmd_vel"))?;
    // The sensors' frames, fixed on the body; and the start pose as map → odom.
    let mut transforms: Vec<msgs::TransformStamped> = chair::SENSORS
        .iter()
        .enumerate()
        .map(|(i, m)| msgs::TransformStamped {
            header: msgs::Header { stamp: msgs::Time::default(), frame_id: "base_link".into() },
            child_frame_id: format!("prox{i}"),
            translation: [m.x_m, m.y_m, 0.0],
            rotation: msgs::yaw_quaternion(m.angle_deg.to_radians()),
        })
        .collect();
    if cfg.map_to_odom {
        transforms.push(msgs::TransformStamped {
            header: msgs::Header { stamp: msgs::Time::default(), frame_id: "map".into() },
            child_frame_id: "odom".into(),
            translation: [start.x_m, start.y_m, 0.0],
            rotation: msgs::yaw_quaternion(start.heading_rad),
        });
    }
    tf_static.put(&msgs::TfMessage { transforms });
    Ok(Chair {
        name: spec.name.clone(),
        id,
        start,
        odometry: Odometry::new(start, map.header.params.encoder_ticks_per_m, chair::BODY[1]),
        last: None,
        command: None,
        answered: None,
        waited_out: false,
        heard: false,
        controllers: BTreeSet::new(),
        cmd_vel_topic: names::mangle(&topic("cmd_vel")),
        odom,
        tf,
        scan,
        imu,
        bumper,
        ranges,
        _tf_static: tf_static,
        _cmd_vel: cmd_vel,
    })
}

/// Publishes one chair's readings of a tick: `tf` and `odom` from its encoders and compass
/// (never the true pose), the cones as `Range`s and a `LaserScan`, the compass as `Imu`, and
/// the collision flag as the bumper.
#[allow(clippy::too_many_arguments)]
fn publish_readings(
    c: &mut Chair,
    b: &SensorBlock,
    stamp: msgs::Time,
    now: f64,
    cones: &[Cone],
    params: &ipc_types::HubParams,
    scan_step_rad: f64,
    cycle_s: f64,
) {
    let compass = (b.present & HAS_COMPASS != 0).then_some(b.compass_deg);
    let pose = c.odometry.update(b.encoder_ticks, compass);
    let (v, omega) = match c.last {
        Some((p, t)) if now > t => {
            let dt = now - t;
            let ds = (pose.x_m - p.x_m).hypot(pose.y_m - p.y_m);
            let forward = (pose.x_m - p.x_m) * pose.heading_rad.cos() + (pose.y_m - p.y_m) * pose.heading_rad.sin();
            (ds.copysign(forward) / dt, sim_model::wrap_rad(pose.heading_rad - p.heading_rad) / dt)
        }
        _ => (0.0, 0.0),
    };
    c.last = Some((pose, now));
    // The pose in the odom frame, whose origin is the start pose.
    let Pose { x_m: sx, y_m: sy, heading_rad: sth } = c.start;
    let (dx, dy) = (pose.x_m - sx, pose.y_m - sy);
    let (s, co) = sth.sin_cos();
    let odom_pose = Pose::new(co * dx + s * dy, -s * dx + co * dy, sim_model::wrap_rad(pose.heading_rad - sth));
    let q = msgs::yaw_quaternion(odom_pose.heading_rad);
    let header = |frame: &str| msgs::Header { stamp, frame_id: frame.to_owned() };
    c.tf.put(&msgs::TfMessage {
        transforms: vec![msgs::TransformStamped {
            header: header("odom"),
            child_frame_id: "base_link".into(),
            translation: [odom_pose.x_m, odom_pose.y_m, 0.0],
            rotation: q,
        }],
    });
    // Planar: x, y and yaw are estimated; z, roll and pitch are not (a large variance).
    let mut pose_covariance = [0.0; 36];
    let mut twist_covariance = [0.0; 36];
    for (i, v) in [0.01, 0.01, 1e6, 1e6, 1e6, 0.01].into_iter().enumerate() {
        pose_covariance[i * 7] = v;
        twist_covariance[i * 7] = v;
    }
    c.odom.put(&msgs::Odometry {
        header: header("odom"),
        child_frame_id: "base_link".into(),
        position: [odom_pose.x_m, odom_pose.y_m, 0.0],
        orientation: q,
        pose_covariance,
        twist: msgs::Twist { linear: [v, 0.0, 0.0], angular: [0.0, 0.0, omega] },
        twist_covariance,
    });
    let n = (b.proximity_count as usize).min(cones.len()).min(c.ranges.len());
    let readings = &b.proximity_m[..n];
    let variance = (params.noise_proximity_m * params.noise_proximity_m) as f32;
    for (i, ((topic, cone), &d)) in c.ranges.iter_mut().zip(cones).zip(readings).enumerate() {
        let kind = chair::SENSORS.get(i).map(|m| m.kind);
        topic.put(&msgs::Range {
            header: header(&format!("prox{i}")),
            radiation_type: if kind == Some(chair::Kind::Ir) { msgs::INFRARED } else { msgs::ULTRASOUND },
            field_of_view: cone.cone_rad as f32,
            min_range: 0.0,
            max_range: cone.range_m as f32,
            range: if d < cone.range_m { d as f32 } else { f32::INFINITY },
            variance,
        });
    }
    let s = drive::scan(&cones[..n], readings, scan_step_rad);
    c.scan.put(&msgs::LaserScan {
        header: header("base_link"),
        angle_min: -std::f32::consts::PI,
        angle_max: (-std::f64::consts::PI + s.step_rad * (s.ranges.len() - 1) as f64) as f32,
        angle_increment: s.step_rad as f32,
        time_increment: 0.0,
        scan_time: cycle_s as f32,
        range_min: 0.0,
        range_max: s.range_max as f32,
        ranges: s.ranges,
        intensities: Vec::new(),
    });
    if let Some(deg) = compass {
        let var = params.noise_compass_deg.to_radians().powi(2);
        let mut orientation_covariance = [0.0; 9];
        orientation_covariance[0] = 1e6;
        orientation_covariance[4] = 1e6;
        orientation_covariance[8] = var.max(1e-9);
        // Not measured: -1 in the first element (REP 145).
        let mut none = [0.0; 9];
        none[0] = -1.0;
        c.imu.put(&msgs::Imu {
            header: header("base_link"),
            orientation: msgs::yaw_quaternion(deg.to_radians()),
            orientation_covariance,
            angular_velocity: [0.0; 3],
            angular_velocity_covariance: none,
            linear_acceleration: [0.0; 3],
            linear_acceleration_covariance: none,
        });
    }
    c.bumper.put(&msgs::Bool { data: b.present & COLLISION != 0 });
}

/// The lab's walls (never the scenario's obstacles) as an occupancy grid in the `map`
/// frame: 5 cm cells, coarser for a lab so large that it would pass 4 million cells.
pub fn occupancy_grid(map: &Map) -> msgs::OccupancyGrid {
    const MAX_CELLS: f64 = 4.0e6;
    let (w, h) = (map.width_m.max(0.0), map.height_m.max(0.0));
    let resolution = 0.05f64.max((w * h / MAX_CELLS).sqrt());
    let (cols, rows) = (((w / resolution).ceil() as u32).max(1), ((h / resolution).ceil() as u32).max(1));
    let mut data = vec![0i8; cols as usize * rows as usize];
    for wall in map.known_walls() {
        let xs = wall.corners.iter().map(|p| p.x);
        let ys = wall.corners.iter().map(|p| p.y);
        let (x0, x1) = (xs.clone().fold(f64::INFINITY, f64::min), xs.fold(f64::NEG_INFINITY, f64::max));
        let (y0, y1) = (ys.clone().fold(f64::INFINITY, f64::min), ys.fold(f64::NEG_INFINITY, f64::max));
        let cell = |v: f64, n: u32| ((v / resolution).floor().max(0.0) as u32).min(n - 1);
        let corners: Vec<[f64; 2]> = wall.corners.iter().map(|p| [p.x, p.y]).collect();
        for row in cell(y0, rows)..=cell(y1, rows) {
            for col in cell(x0, cols)..=cell(x1, cols) {
                let centre = [(f64::from(col) + 0.5) * resolution, (f64::from(row) + 0.5) * resolution];
                // A cell is occupied when its centre is in the wall, or the wall is thinner
                // than a cell and crosses it.
                let inside = sim_model::point_in_polygon(centre, &corners)
                    || corners
                        .iter()
                        .zip(corners.iter().cycle().skip(1))
                        .any(|(a, b)| sim_model::point_segment_distance(centre, *a, *b) <= resolution / 2.0);
                if inside {
                    data[row as usize * cols as usize + col as usize] = 100;
                }
            }
        }
    }
    msgs::OccupancyGrid {
        header: msgs::Header { stamp: msgs::Time::default(), frame_id: "map".into() },
        map_load_time: msgs::Time::default(),
        resolution: resolution as f32,
        width: cols,
        height: rows,
        origin_position: [0.0; 3],
        origin_orientation: [0.0, 0.0, 0.0, 1.0],
        data,
    }
}
