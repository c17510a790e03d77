//! `iwsim._iwsim`: the native half of the `iwsim` Python package. It binds the Rust agent SDK
//! (`agent-sdk`) with PyO3, so a Python agent talks to the hub over the same iceoryx2 shared
//! memory as a Rust agent, with the same payloads: there is one definition of every layout,
//! `ipc-types`, and the Python side builds its NumPy dtype from the offsets this module reports
//! ([`sensor_block_layout`]) instead of mirroring them.
//!
//! The Python-facing API (`iwsim.connect`, `Agent.register`, `wait_tick`, `sensors`, `send`,
//! the exceptions) is in `python/iwsim/__init__.py`, which wraps this module; this one stays
//! small: calls in, checked values out, every SDK error mapped to a typed exception.
//!
//! Like every agent, the agent API sees only what an agent may see (sensor blocks of its own
//! robots, the map without the scenario's obstacles): it links the SDK, never the hub or the
//! world. The truth the envs' referees judge from is in the submodule `referee` (see
//! [`referee`]), which `iwsim.env` alone imports.

mod referee;

use std::time::{Duration, Instant};

use agent_sdk::{Agent as SdkAgent, AgentError};
use ipc_types::{ActionBlock, FixedName, RobotRegistration, SensorBlock};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyKeyboardInterrupt, PyTimeoutError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes};

create_exception!(_iwsim, IwsimError, PyException, "Base class of iwsim's errors.");
create_exception!(_iwsim, SessionNotFound, IwsimError, "No hub serves the session (or its name is not valid).");
create_exception!(_iwsim, Refused, IwsimError, "The hub refused a request, such as a registration.");
create_exception!(_iwsim, HubGone, IwsimError, "The hub's process has exited.");
create_exception!(_iwsim, NoAnswer, IwsimError, "The hub did not answer in time.");

/// The longest a wait sleeps before it looks at Python's signals (so Ctrl-C interrupts it) and
/// at the hub's liveness.
const WAIT_SLICE: Duration = Duration::from_millis(50);

/// The longest [`Agent::step`] polls before it sleeps.
const MAX_SPIN: Duration = Duration::from_millis(1);

/// An SDK error as the Python exception a caller can catch by kind.
pub(crate) fn to_py(e: AgentError) -> PyErr {
    let text = e.to_string();
    match e {
        AgentError::Services(_) | AgentError::NoBridge(_) => SessionNotFound::new_err(text),
        AgentError::Refused { .. } => Refused::new_err(text),
        AgentError::HubGone { .. } | AgentError::BridgeGone(_) => HubGone::new_err(text),
        AgentError::NoAnswer(..) => NoAnswer::new_err(text),
        AgentError::Interrupted => PyKeyboardInterrupt::new_err(text),
        AgentError::Ipc(_) | AgentError::Map(_) | AgentError::Zenoh(_) | AgentError::Frame { .. } => {
            IwsimError::new_err(text)
        }
    }
}

pub(crate) fn seconds(what: &str, s: f64) -> PyResult<Duration> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| PyValueError::new_err(format!("{what} must be a finite number of seconds ≥ 0, not {s}")))
}

/// Connects to the hub of `session` as an agent named `name`, waiting up to `timeout` seconds
/// for the hub to appear; with `zenoh` (an endpoint, `tcp/HOST:7447`), to a hub on another
/// machine through its Zenoh bridge.
#[pyfunction]
#[pyo3(signature = (session, name = "python", timeout = 5.0, zenoh = None))]
fn connect(session: &str, name: &str, timeout: f64, zenoh: Option<&str>) -> PyResult<Agent> {
    let timeout = seconds("timeout", timeout)?;
    let agent = match zenoh {
        Some(endpoint) => SdkAgent::connect_zenoh(&agent_sdk::remote::Remote::new(endpoint), session, timeout),
        None => SdkAgent::connect_within(session, name, timeout),
    };
    agent.map(|a| Agent { sdk: Some(a) }).map_err(to_py)
}

/// An agent process's connection to a hub (one per process is the rule; several work).
/// Not thread-safe: use it from the thread that made it.
#[pyclass(unsendable, module = "iwsim._iwsim")]
pub struct Agent {
    sdk: Option<SdkAgent>,
}

impl std::fmt::Debug for Agent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Agent").field("session", &self.sdk.as_ref().map(SdkAgent::session)).finish()
    }
}

impl Agent {
    pub(crate) fn sdk(&mut self) -> PyResult<&mut SdkAgent> {
        self.sdk.as_mut().ok_or_else(|| IwsimError::new_err("the agent is closed"))
    }
}

#[pymethods]
impl Agent {
    /// Registers a robot: `body` is (length, width, centre of movement as a fraction of the
    /// length from the rear), `pose` (x m, y m, heading degrees), `motors` (top speed m/s,
    /// acceleration curve), `sensors` up to 8 proximity cones (x m, y m, direction degrees,
    /// opening degrees, range m; e.g. `CHAIR_SENSORS`); the hub's defaults where omitted.
    /// Returns the robot's id.
    #[pyo3(signature = (name, *, body = None, pose = None, motors = None, sensors = None, id = 0))]
    fn register(
        &mut self,
        name: &str,
        body: Option<(f64, f64, f64)>,
        pose: Option<(f64, f64, f64)>,
        motors: Option<(f64, f64)>,
        sensors: Option<Vec<Cone>>,
        id: u32,
    ) -> PyResult<u32> {
        if FixedName::new(name).is_none_or(|n| n.as_str().is_none_or(str::is_empty)) {
            return Err(PyValueError::new_err(format!(
                "robot name {name:?} must be 1 to {} bytes of UTF-8",
                ipc_types::NAME_BYTES - 1
            )));
        }
        let mut reg = RobotRegistration::new(name).id(id).at(pose.map(|(x, y, d)| [x, y, d]));
        if let Some((length, width, com)) = body {
            reg = reg.body(length, width, com);
        }
        if let Some((speed, curve)) = motors {
            reg = reg.motors(speed, curve);
        }
        if let Some(cones) = sensors {
            if cones.len() > reg.sensors.len() {
                return Err(PyValueError::new_err(format!(
                    "{} sensors: a robot has at most {}",
                    cones.len(),
                    reg.sensors.len()
                )));
            }
            for (slot, &(x_m, y_m, angle_deg, cone_deg, range_m)) in reg.sensors.iter_mut().zip(&cones) {
                *slot = ipc_types::SensorSpec { x_m, y_m, angle_deg, cone_deg, range_m };
            }
            reg.sensor_count = cones.len() as u32;
        }
        self.sdk()?.register(&reg).map_err(to_py)
    }

    /// Says this agent's robots are registered; in lock-step the run starts once every
    /// expected agent is ready.
    fn ready(&mut self) -> PyResult<()> {
        self.sdk()?.ready().map_err(to_py)
    }

    /// Waits for the next tick and returns (tick, simulated seconds), or `None` once the run
    /// has finished. Raises `TimeoutError` after `timeout` seconds without one, `HubGone` when
    /// the hub exits. Ctrl-C interrupts it.
    #[pyo3(signature = (timeout = None))]
    fn wait_tick(&mut self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Option<(u64, f64)>> {
        let deadline = match timeout {
            Some(t) => Some(Instant::now() + seconds("timeout", t)?),
            None => None,
        };
        loop {
            let sdk = self.sdk()?;
            if let Some(t) = sdk.try_tick().map_err(to_py)? {
                return Ok(Some((t.tick, t.sim_time_s)));
            }
            if sdk.finished() {
                return Ok(None);
            }
            let now = Instant::now();
            let slice = match deadline {
                Some(d) if now >= d => {
                    return Err(PyTimeoutError::new_err(format!(
                        "no tick from the hub of session {:?} within {:.3} s",
                        sdk.session(),
                        timeout.unwrap_or_default()
                    )));
                }
                Some(d) => (d - now).min(WAIT_SLICE),
                None => WAIT_SLICE,
            };
            let fd = sdk.tick_fd();
            // The GIL is released while the thread sleeps on the tick's descriptor.
            let rang = py.detach(|| wait_readable(fd, slice));
            if !rang {
                sdk.check_alive().map_err(to_py)?;
            }
            py.check_signals()?;
        }
    }

    /// This tick's sensor blocks of this agent's robots, as the bytes of `SensorBlock`s back
    /// to back (`iwsim.Agent.sensors` views them as a NumPy structured array).
    fn sensors_bytes<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let blocks: &[SensorBlock] = self.sdk()?.sensors();
        Ok(PyBytes::new(py, bytemuck::cast_slice(blocks)))
    }

    /// Answers tick `tick` with motor powers: `actions` is a list of (robot id, left, right),
    /// powers in [-1, 1] (the hub clamps larger ones).
    fn send(&mut self, tick: u64, actions: Vec<(u32, f64, f64)>) -> PyResult<()> {
        let sdk = self.sdk()?;
        let mut blocks = Vec::with_capacity(actions.len());
        for (id, left, right) in actions {
            if !sdk.robots().contains(&id) {
                return Err(PyValueError::new_err(format!(
                    "robot {id} is not one of this agent's robots {:?}",
                    sdk.robots()
                )));
            }
            blocks.push(motors(&format!("robot {id}"), id, left, right)?);
        }
        sdk.send(tick, &blocks).map_err(to_py)
    }

    /// Answers tick `tick` with motor powers for many robots at once: `ids` (n robot ids, as
    /// a little-endian u32 buffer such as a NumPy uint32 array) and `powers` (n × 2 float64,
    /// C order, likewise), checked as [`Agent::send`] checks them.
    fn send_powers(&mut self, tick: u64, ids: &[u8], powers: &[u8]) -> PyResult<()> {
        if !ids.len().is_multiple_of(4) || powers.len() != ids.len() / 4 * 16 {
            return Err(PyValueError::new_err(format!(
                "{} id bytes and {} power bytes: expected n u32 ids and n × 2 float64 powers",
                ids.len(),
                powers.len()
            )));
        }
        let ids = ids.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        let actions: Vec<(u32, f64, f64)> = ids.zip(power_pairs(powers)).map(|(id, [l, r])| (id, l, r)).collect();
        self.send(tick, actions)
    }

    /// One environment step for every robot of this agent at once: answers `tick` with
    /// `powers` (n × 2 float64, little-endian, one row per robot in registration order; each
    /// checked finite; the hub clamps them to [-1, 1]) and waits for the next tick, as
    /// [`Agent::wait_tick`] does. Returns that tick, or `None` once the run has finished.
    ///
    /// `spin` seconds (at most [`MAX_SPIN`]) are spent polling for the answer before the
    /// thread sleeps: a lock-step hub usually answers within tens of microseconds, sooner than
    /// a sleeping thread wakes, so a process that runs the whole step (an environment) spends a
    /// core for speed. Python's other threads wait meanwhile.
    #[pyo3(signature = (tick, powers, timeout = None, spin = 0.0))]
    pub(crate) fn step(
        &mut self,
        py: Python<'_>,
        tick: u64,
        powers: &[u8],
        timeout: Option<f64>,
        spin: f64,
    ) -> PyResult<Option<(u64, f64)>> {
        let spin = seconds("spin", spin)?.min(MAX_SPIN);
        let sdk = self.sdk()?;
        let n = sdk.robots().len();
        if powers.len() != n * 16 {
            return Err(PyValueError::new_err(format!(
                "{} power bytes for {n} robots: expected n × 2 float64 ({} bytes)",
                powers.len(),
                n * 16
            )));
        }
        let blocks = sdk
            .robots()
            .iter()
            .zip(power_pairs(powers))
            .enumerate()
            .map(|(k, (&id, [left, right]))| motors(&format!("row {k} (robot {id})"), id, left, right))
            .collect::<PyResult<Vec<_>>>()?;
        sdk.send(tick, &blocks).map_err(to_py)?;
        let spin_until = Instant::now() + spin;
        while !spin.is_zero() && Instant::now() < spin_until {
            if let Some(t) = sdk.try_tick().map_err(to_py)? {
                return Ok(Some((t.tick, t.sim_time_s)));
            }
            if sdk.finished() {
                return Ok(None);
            }
            std::hint::spin_loop();
        }
        self.wait_tick(py, timeout)
    }

    /// What each robot's own sensors say this tick, as a chair's observation: one row per
    /// robot in registration order of its `MAX_PROXIMITY` proximity readings in metres
    /// (clipped to [0, `max_range`]; a missing or invalid reading is `max_range`) and its
    /// compass as (cos, sin) (zeros without a compass), float32, little-endian, back to back
    /// in a new `bytearray` (so the NumPy view of it is writable).
    fn observations<'py>(&mut self, py: Python<'py>, max_range: f32) -> PyResult<Bound<'py, PyByteArray>> {
        let sdk = self.sdk()?;
        Ok(PyByteArray::new(py, &observation_table(sdk, max_range)))
    }

    /// The ids of this agent's robots, in registration order.
    #[getter]
    fn robots(&self) -> Vec<u32> {
        self.sdk.as_ref().map_or_else(Vec::new, |s| s.robots().to_vec())
    }

    /// Whether the hub has ended the run.
    #[getter]
    fn finished(&self) -> bool {
        self.sdk.as_ref().is_none_or(SdkAgent::finished)
    }

    /// The session's name.
    #[getter]
    fn session(&self) -> Option<String> {
        self.sdk.as_ref().map(|s| s.session().to_owned())
    }

    /// Leaves the hub (it removes this agent's robots); the last process of a session removes
    /// its shared-memory files. Closing twice does nothing.
    fn close(&mut self) {
        if let Some(sdk) = self.sdk.take() {
            sdk.close();
        }
    }
}

/// A proximity cone as Python passes it: x m, y m, direction degrees, opening degrees, range m.
type Cone = (f64, f64, f64, f64, f64);

/// The chair observations of an agent's robots (see [`Agent::observations`]).
pub(crate) fn observation_table(sdk: &SdkAgent, max_range: f32) -> Vec<u8> {
    const ROW: usize = ipc_types::MAX_PROXIMITY + 2;
    let blocks = sdk.sensors();
    let mut out = vec![0u8; sdk.robots().len() * ROW * 4];
    for (k, (row, &id)) in out.chunks_exact_mut(ROW * 4).zip(sdk.robots()).enumerate() {
        let mut values = [max_range; ROW];
        (values[ROW - 2], values[ROW - 1]) = (0.0, 0.0);
        // Blocks come in registration order; look further only when the robots changed.
        let block = blocks.get(k).filter(|b| b.robot_id == id).or_else(|| blocks.iter().find(|b| b.robot_id == id));
        if let Some(b) = block {
            let count = (b.proximity_count as usize).min(ipc_types::MAX_PROXIMITY);
            for (v, &m) in values.iter_mut().zip(&b.proximity_m[..count]) {
                let m = m as f32;
                *v = if m.is_finite() { m.clamp(0.0, max_range) } else { max_range };
            }
            if b.present & ipc_types::HAS_COMPASS != 0 {
                let r = b.compass_deg.to_radians();
                (values[ROW - 2], values[ROW - 1]) = (r.cos() as f32, r.sin() as f32);
            }
        }
        write_f32s(row, &values);
    }
    out
}

/// One robot's motor powers as an action, refused when not finite (`what` names the robot in
/// the error). Out-of-range powers go as they are: the hub clamps them.
fn motors(what: &str, id: u32, left: f64, right: f64) -> PyResult<ActionBlock> {
    if left.is_finite() && right.is_finite() {
        Ok(ActionBlock::motors(id, left, right))
    } else {
        Err(PyValueError::new_err(format!("{what}: motor powers must be finite numbers, not ({left}, {right})")))
    }
}

/// (left, right) pairs from n × 2 little-endian float64 (a trailing partial pair is dropped;
/// callers check the length first).
fn power_pairs(bytes: &[u8]) -> impl Iterator<Item = [f64; 2]> + '_ {
    let f = |b: &[u8]| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]));
    bytes.chunks_exact(16).map(move |p| [f(&p[..8]), f(&p[8..])])
}

/// `values` as little-endian bytes into `out` (as long as both are).
fn write_f32s(out: &mut [u8], values: &[f32]) {
    for (bytes, v) in out.chunks_exact_mut(4).zip(values) {
        bytes.copy_from_slice(&v.to_le_bytes());
    }
}

/// `values` as little-endian bytes into `out` (as long as both are).
pub(crate) fn write_f64s(out: &mut [u8], values: &[f64]) {
    for (bytes, v) in out.chunks_exact_mut(8).zip(values) {
        bytes.copy_from_slice(&v.to_le_bytes());
    }
}

/// Waits up to `slice` for `fd` to become readable; whether it did.
fn wait_readable(fd: i32, slice: Duration) -> bool {
    os::poll::any_readable(&[fd], Some(slice)).unwrap_or(false)
}

/// `SensorBlock`'s fields as (name, byte offset, NumPy type code, element count), from the
/// Rust definition itself, so the Python dtype cannot drift from it.
#[pyfunction]
fn sensor_block_layout() -> Vec<(&'static str, usize, &'static str, usize)> {
    use core::mem::offset_of;
    use ipc_types::{ChallengeStanding, INBOX_BYTES, MAX_BEACONS, MAX_INBOX_MESSAGES, MAX_PROXIMITY};
    let entry = core::mem::size_of::<ipc_types::InboxEntry>();
    let standing = offset_of!(SensorBlock, standing);
    vec![
        ("tick", offset_of!(SensorBlock, tick), "<u8", 1),
        ("robot_id", offset_of!(SensorBlock, robot_id), "<u4", 1),
        ("present", offset_of!(SensorBlock, present), "<u4", 1),
        ("proximity_m", offset_of!(SensorBlock, proximity_m), "<f8", MAX_PROXIMITY),
        ("compass_deg", offset_of!(SensorBlock, compass_deg), "<f8", 1),
        ("gps_x_m", offset_of!(SensorBlock, gps_x_m), "<f8", 1),
        ("gps_y_m", offset_of!(SensorBlock, gps_y_m), "<f8", 1),
        ("gps_heading_deg", offset_of!(SensorBlock, gps_heading_deg), "<f8", 1),
        ("beacons_deg", offset_of!(SensorBlock, beacons_deg), "<f8", MAX_BEACONS),
        ("encoder_ticks", offset_of!(SensorBlock, encoder_ticks), "<i8", 2),
        ("collision_count", offset_of!(SensorBlock, collision_count), "<u4", 1),
        ("ground", offset_of!(SensorBlock, ground), "<u4", 1),
        ("proximity_count", offset_of!(SensorBlock, proximity_count), "<u4", 1),
        ("beacon_count", offset_of!(SensorBlock, beacon_count), "<u4", 1),
        ("inbox_count", offset_of!(SensorBlock, inbox_count), "<u4", 1),
        ("inbox_dropped", offset_of!(SensorBlock, inbox_dropped), "<u4", 1),
        ("inbox", offset_of!(SensorBlock, inbox), "V1", entry * MAX_INBOX_MESSAGES),
        ("inbox_bytes", offset_of!(SensorBlock, inbox_bytes), "u1", INBOX_BYTES),
        ("drive", offset_of!(SensorBlock, drive), "<f4", 2),
        ("drive_flags", offset_of!(SensorBlock, drive_flags), "<u4", 1),
        ("sensor_mode", offset_of!(SensorBlock, sensor_mode), "<u4", 1),
        ("line_bits", offset_of!(SensorBlock, line_bits), "<u4", 1),
        // The challenge standing (with HAS_SCORE), its fields spelled out flat.
        ("phase", standing + offset_of!(ChallengeStanding, phase), "<u4", 1),
        ("score", standing + offset_of!(ChallengeStanding, score), "<i4", 1),
        ("arrival_tick", standing + offset_of!(ChallengeStanding, arrival_tick), "<u4", 1),
        ("returning_ticks", standing + offset_of!(ChallengeStanding, returning_ticks), "<u4", 1),
        ("score_collisions", standing + offset_of!(ChallengeStanding, collisions), "<u4", 1),
        ("visited_mask", standing + offset_of!(ChallengeStanding, visited_mask), "<u8", 1),
    ]
}

/// [`sensor_block_layout`] for Rust tests.
#[doc(hidden)]
pub fn layout_for_tests() -> Vec<(&'static str, usize, &'static str, usize)> {
    sensor_block_layout()
}

/// The module `iwsim._iwsim`.
#[pymodule]
fn _iwsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_function(wrap_pyfunction!(connect, m)?)?;
    m.add_function(wrap_pyfunction!(sensor_block_layout, m)?)?;
    m.add_class::<Agent>()?;
    // The truth, for referees only, in a submodule the agent API never imports.
    let referee = PyModule::new(py, "referee")?;
    referee::register(&referee)?;
    m.add_submodule(&referee)?;
    m.add("SENSOR_BLOCK_BYTES", core::mem::size_of::<SensorBlock>())?;
    m.add("MAX_PROXIMITY", ipc_types::MAX_PROXIMITY)?;
    m.add("HAS_COMPASS", ipc_types::HAS_COMPASS)?;
    m.add("HAS_GPS", ipc_types::HAS_GPS)?;
    // The Intellwheels chair as every iwsim process knows it (sim_model::chair).
    let [length, width, com] = sim_model::chair::BODY;
    m.add("CHAIR_BODY", (length, width, com))?;
    m.add("CHAIR_MOTORS", (sim_model::chair::MAX_SPEED_MPS, sim_model::chair::ACCEL_CURVE))?;
    let cones: Vec<Cone> =
        sim_model::chair::SENSORS.iter().map(|s| (s.x_m, s.y_m, s.angle_deg, s.cone_deg, s.range_m)).collect();
    m.add("CHAIR_SENSORS", cones)?;
    m.add("IwsimError", py.get_type::<IwsimError>())?;
    m.add("SessionNotFound", py.get_type::<SessionNotFound>())?;
    m.add("Refused", py.get_type::<Refused>())?;
    m.add("HubGone", py.get_type::<HubGone>())?;
    m.add("NoAnswer", py.get_type::<NoAnswer>())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layout_covers_every_byte_of_a_sensor_block_in_order_without_overlap() {
        let size = |code: &str| match code {
            "<u8" | "<i8" | "<f8" => 8,
            "<u4" | "<i4" | "<f4" => 4,
            "V1" | "u1" => 1,
            other => panic!("unknown code {other}"),
        };
        let mut end = 0;
        for (name, offset, code, count) in sensor_block_layout() {
            assert!(offset >= end, "{name} at {offset} overlaps the field before (ends at {end})");
            // Only alignment padding may lie between fields.
            assert!(offset - end < 8, "{name}: a gap of {} bytes", offset - end);
            end = offset + size(code) * count;
        }
        assert!(core::mem::size_of::<SensorBlock>() - end < 8, "the last field ends at {end}");
    }
}
