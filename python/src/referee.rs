//! `iwsim._iwsim.referee`: the truth, for referees (the envs' rewards and terminations) and
//! never for the agent under test. It is a submodule of its own so the agent API
//! (`iwsim._iwsim`, wrapped by `iwsim`) has no call that returns a true pose; `iwsim.referee`
//! wraps this one, and only `iwsim.env` imports it (an architecture invariant).

use std::time::Instant;

use pyo3::exceptions::{PyKeyError, PyTimeoutError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes};

use crate::{Agent, IwsimError, observation_table, seconds, to_py, write_f64s};

/// Connects to the hub of `session` as an observer: it sees every robot's true state (for a
/// referee or a reward, never for the agent under test), and the hub does not count it. With
/// `zenoh` (an endpoint), to a hub on another machine through its bridge, which must serve
/// observers (`iwsim zenoh --observers world`, or an episode host's).
#[pyfunction]
#[pyo3(signature = (session, timeout = 5.0, zenoh = None))]
fn observe(session: &str, timeout: f64, zenoh: Option<&str>) -> PyResult<Observer> {
    let timeout = seconds("timeout", timeout)?;
    let name = format!("python-observer-{}", std::process::id());
    let o = match zenoh {
        Some(endpoint) => {
            observer::Observer::connect_zenoh(&agent_sdk::remote::Remote::new(endpoint), session, timeout)
        }
        None => observer::Observer::connect_within(session, &name, timeout),
    };
    o.map(|o| Observer { sdk: Some(o) }).map_err(to_py)
}

/// An episode host on another machine (`iwsim env-host` there), for environments whose hub
/// runs there: each episode is started and ended with a query.
#[pyclass(unsendable, module = "iwsim._iwsim.referee")]
#[derive(Debug)]
pub struct EpisodeHost {
    host: agent_sdk::remote::EpisodeHost,
}

#[pymethods]
impl EpisodeHost {
    /// Opens a Zenoh session to the host at `endpoint` (`tcp/HOST:7447`), waiting up to
    /// `timeout` seconds for it.
    #[new]
    #[pyo3(signature = (endpoint, timeout = 20.0))]
    fn new(py: Python<'_>, endpoint: &str, timeout: f64) -> PyResult<Self> {
        let timeout = seconds("timeout", timeout)?;
        let remote = agent_sdk::remote::Remote::new(endpoint);
        py.detach(|| agent_sdk::remote::EpisodeHost::connect(&remote, timeout)).map(|host| Self { host }).map_err(to_py)
    }

    /// Starts an episode whose hub takes `args` (scenario options: `--ticks`, `--seed`,
    /// `--obstacle`, …), its lab the XML `lab_xml` unless `args` name a built-in one; returns
    /// the episode's session.
    #[pyo3(signature = (args, lab_xml = None))]
    fn start(&self, py: Python<'_>, args: Vec<String>, lab_xml: Option<Vec<u8>>) -> PyResult<String> {
        py.detach(|| self.host.start(&args, lab_xml)).map_err(to_py)
    }

    /// Ends the episode of `session`; its hub's end-of-run summary (a JSON line).
    fn end(&self, py: Python<'_>, session: &str) -> PyResult<String> {
        py.detach(|| self.host.end(session)).map_err(to_py)
    }
}

/// A read-only view of a session's truth: world snapshots.
#[pyclass(unsendable, module = "iwsim._iwsim.referee")]
pub struct Observer {
    sdk: Option<observer::Observer>,
}

impl std::fmt::Debug for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Observer").field("open", &self.sdk.is_some()).finish()
    }
}

impl Observer {
    /// Runs `f` on the world at tick `tick` or later, waiting up to `timeout` seconds for it:
    /// the snapshot is read where the hub wrote it, nothing copied.
    fn with_world_at<R>(
        &mut self,
        py: Python<'_>,
        tick: u64,
        timeout: f64,
        f: impl FnOnce(&ipc_types::WorldHeader, &[ipc_types::RobotState]) -> R,
    ) -> PyResult<R> {
        let deadline = Instant::now() + seconds("timeout", timeout)?;
        let sdk = self.sdk.as_mut().ok_or_else(|| IwsimError::new_err("the observer is closed"))?;
        let mut f = Some(f);
        loop {
            let done = sdk
                .with_world(|h, robots| if h.tick >= tick { f.take().map(|f| f(h, robots)) } else { None })
                .map_err(to_py)?;
            if let Some(done) = done {
                return Ok(done);
            }
            if Instant::now() >= deadline {
                return Err(PyTimeoutError::new_err(format!("no world of tick {tick} within {timeout} s")));
            }
            // The hub publishes a tick's world before it rings the agents, so this is rare
            // and short: yield rather than sleep a scheduler quantum.
            py.detach(std::thread::yield_now);
            py.check_signals()?;
        }
    }
}

#[pymethods]
impl Observer {
    /// The world at tick `tick` or later (waiting up to `timeout` seconds for it): (tick,
    /// [(robot id, x m, y m, heading degrees, collision count)]), in the hub's robot order.
    #[pyo3(signature = (tick = 0, timeout = 5.0))]
    fn robots(&mut self, py: Python<'_>, tick: u64, timeout: f64) -> PyResult<RobotStates> {
        self.with_world_at(py, tick, timeout, |h, robots| {
            (h.tick, robots.iter().map(|r| (r.id, r.x_m, r.y_m, r.heading_deg, r.collision_count)).collect())
        })
    }

    /// The true poses of robots `ids` at tick `tick` or later (waiting up to `timeout`
    /// seconds), for a referee: (tick, bytes of n rows of (x m, y m, heading degrees,
    /// collision count) as little-endian float64, in `ids`' order). A robot the world does
    /// not hold raises `KeyError`.
    #[pyo3(signature = (tick, ids, timeout = 5.0))]
    fn poses<'py>(
        &mut self,
        py: Python<'py>,
        tick: u64,
        ids: Vec<u32>,
        timeout: f64,
    ) -> PyResult<(u64, Bound<'py, PyBytes>)> {
        let (tick, rows) =
            self.with_world_at(py, tick, timeout, |h, robots| (h.tick, pose_rows(robots, &ids, h.tick)))?;
        let mut table = vec![0u8; ids.len() * 32];
        for (out, row) in table.chunks_exact_mut(32).zip(rows?) {
            write_f64s(out, &row);
        }
        Ok((tick, PyBytes::new(py, &table)))
    }

    /// Stops observing. Closing twice does nothing.
    fn close(&mut self) {
        self.sdk = None;
    }
}

/// One step of `iwsim.env` in one call: `agent` answers `tick` with `powers` (see
/// [`Agent::step`]) and waits for the next tick; returns `None` once the run has finished, else
/// (tick, simulated seconds, the chairs' observations (see [`Agent::observations`]), `judge`'s
/// table of that tick (see [`Judge`]), both in the agent's registration order). The truth from
/// `observer` never reaches the agent: it goes to the judge, whose table goes back to the
/// environment's Python code for rewards and terminations.
#[pyfunction]
#[pyo3(signature = (agent, observer, judge, tick, powers, max_range, timeout = None, spin = 0.0))]
#[allow(clippy::too_many_arguments)] // one call per step is the point: each argument is a part of it
fn env_step<'py>(
    py: Python<'py>,
    agent: &Bound<'py, Agent>,
    observer: &Bound<'py, Observer>,
    judge: &Bound<'py, Judge>,
    tick: u64,
    powers: &[u8],
    max_range: f32,
    timeout: Option<f64>,
    spin: f64,
) -> PyResult<Option<EnvStep<'py>>> {
    let mut agent = agent.borrow_mut();
    let Some((tick, sim_time_s)) = agent.step(py, tick, powers, timeout, spin)? else { return Ok(None) };
    let sdk = agent.sdk()?;
    let observations = PyByteArray::new(py, &observation_table(sdk, max_range));
    // The referee reads the snapshot in the hub's shared memory; only the poses asked for leave it.
    let poses = observer
        .borrow_mut()
        .with_world_at(py, tick, timeout.unwrap_or(20.0), |h, robots| pose_rows(robots, sdk.robots(), h.tick))??;
    let j = judge.borrow_mut().judge(&poses).map_err(PyValueError::new_err)?;
    let ended = j.done.contains(&true);
    Ok(Some((tick, sim_time_s, observations, PyBytes::new(py, &j.table), j.rewards, j.done, j.contacts, ended)))
}

/// What [`env_step`] returns: tick, simulated seconds, observations, then the [`Judged`] parts
/// and whether any chair is done.
type EnvStep<'py> = (u64, f64, Bound<'py, PyByteArray>, Bound<'py, PyBytes>, Vec<f64>, Vec<bool>, Vec<u32>, bool);

/// A [`Judge`]'s verdict on one tick, per chair in the chairs' order. The lists go to Python as
/// lists, ready for the env's dicts: each NumPy call that would make them costs as much as a
/// chair's whole judgement.
#[derive(Debug, Clone, PartialEq)]
struct Judged {
    /// Little-endian float64 rows (x, y, heading degrees, contacts, next checkpoint, reward).
    table: Vec<u8>,
    /// `progress_reward`'s reward for the tick.
    rewards: Vec<f64>,
    /// Whether the chair has passed the last checkpoint (never, without checkpoints).
    done: Vec<bool>,
    /// Contacts so far.
    contacts: Vec<u32>,
}

/// The columns of a [`Judge`]'s table.
const JUDGED: usize = 6;

/// The referee of `iwsim.env`: from each tick's true poses, where each chair is, its contacts,
/// the checkpoint it drives to next (a chair may pass several in one tick) and the default
/// reward (`iwsim.env.progress_reward`: metres gained towards the next checkpoint, -1 per new
/// contact, +10 on reaching the last; 0 once done). Judged here, in one pass over the chairs,
/// rather than by a dozen NumPy calls per step: the env's own Python work per step is what
/// sets its speed against an agent in Rust.
#[pyclass(module = "iwsim._iwsim.referee")]
#[derive(Debug, Clone)]
pub struct Judge {
    checkpoints: Vec<[f64; 3]>,
    /// Per chair: the index of its next checkpoint (`checkpoints.len()` once done).
    next: Vec<usize>,
    /// Per chair: (x, y, heading, contacts) as last judged.
    last: Vec<[f64; 4]>,
}

#[pymethods]
impl Judge {
    /// A judge of chairs driving through `checkpoints` ((x, y, radius) in metres) in order.
    #[new]
    fn new(checkpoints: Vec<(f64, f64, f64)>) -> Self {
        Self { checkpoints: checkpoints.into_iter().map(|(x, y, r)| [x, y, r]).collect(), next: vec![], last: vec![] }
    }

    /// Starts an episode at the poses of `observer` at `tick` or later for robots `ids`
    /// (waiting up to `timeout` seconds): every chair drives to the first checkpoint (or past
    /// those it starts in); returns the table as [`env_step`] does.
    fn start<'py>(
        &mut self,
        py: Python<'py>,
        observer: &Bound<'py, Observer>,
        tick: u64,
        ids: Vec<u32>,
        timeout: f64,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let poses =
            observer.borrow_mut().with_world_at(py, tick, timeout, |h, robots| pose_rows(robots, &ids, h.tick))??;
        self.next = vec![0; poses.len()];
        self.last = poses.clone();
        let judged = self.judge(&poses).map_err(PyValueError::new_err)?;
        Ok(PyBytes::new(py, &judged.table))
    }
}

impl Judge {
    /// Judges one tick's `poses` (per chair: x, y, heading, contacts) against the last.
    ///
    /// # Errors
    /// When the poses are not of as many chairs as [`Judge::start`] began with (or it was
    /// never called): which chair is which would be a guess.
    fn judge(&mut self, poses: &[[f64; 4]]) -> Result<Judged, String> {
        let m = self.checkpoints.len();
        let n = poses.len();
        if n != self.next.len() {
            return Err(format!(
                "the judge has {} chair(s) from its start() but was given the poses of {n}: call start() \
                 with the robots of the episode first",
                self.next.len()
            ));
        }
        let mut j = Judged {
            table: vec![0u8; n * JUDGED * 8],
            rewards: Vec::with_capacity(n),
            done: Vec::with_capacity(n),
            contacts: Vec::with_capacity(n),
        };
        for (k, (row, &[x, y, heading, contacts])) in j.table.chunks_exact_mut(JUDGED * 8).zip(poses).enumerate() {
            let [bx, by, _, before_contacts] = self.last[k];
            let before = self.next[k];
            let mut next = before;
            while let Some(&[cx, cy, r]) = self.checkpoints.get(next) {
                if (x - cx).hypot(y - cy) > r {
                    break;
                }
                next += 1;
            }
            // progress_reward's arithmetic, in its order, so the two agree to the bit (a test
            // compares them).
            let contact = -(contacts - before_contacts);
            let reward = match self.checkpoints.get(before) {
                _ if m == 0 => contact,
                None => 0.0,
                Some(&[cx, cy, _]) => {
                    let gained = (bx - cx).hypot(by - cy) - (x - cx).hypot(y - cy);
                    gained + contact + if next >= m { 10.0 } else { 0.0 }
                }
            };
            write_f64s(row, &[x, y, heading, contacts, next as f64, reward]);
            j.rewards.push(reward);
            j.done.push(m > 0 && next >= m);
            // A collision count is a u32 in the world snapshot: the f64 holds it exactly.
            j.contacts.push(contacts as u32);
            self.next[k] = next;
            self.last[k] = [x, y, heading, contacts];
        }
        Ok(j)
    }
}

/// What [`Observer::robots`] returns.
type RobotStates = (u64, Vec<(u32, f64, f64, f64, u32)>);

/// The true poses of robots `ids` in `robots` (see [`Observer::poses`]): per robot (x m, y m,
/// heading degrees, collision count).
fn pose_rows(robots: &[ipc_types::RobotState], ids: &[u32], tick: u64) -> PyResult<Vec<[f64; 4]>> {
    ids.iter()
        .enumerate()
        .map(|(k, id)| {
            // The hub keeps robots in registration order: a referee's ids usually line up with it.
            let r = robots
                .get(k)
                .filter(|r| r.id == *id)
                .or_else(|| robots.iter().find(|r| r.id == *id))
                .ok_or_else(|| PyKeyError::new_err(format!("robot {id} is not in the world of tick {tick}")))?;
            Ok([r.x_m, r.y_m, r.heading_deg, f64::from(r.collision_count)])
        })
        .collect()
}

/// Fills the submodule `referee` of the native module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(observe, m)?)?;
    m.add_function(wrap_pyfunction!(env_step, m)?)?;
    m.add_class::<Observer>()?;
    m.add_class::<Judge>()?;
    m.add_class::<EpisodeHost>()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_judge_not_started_or_given_another_number_of_chairs_says_so_instead_of_panicking() {
        let mut judge = Judge::new(vec![(1.0, 0.0, 0.5)]);
        let e = judge.judge(&[[0.0, 0.0, 0.0, 0.0]]).expect_err("never started");
        assert!(e.contains("0 chair(s)") && e.contains("poses of 1") && e.contains("start()"), "{e}");
        judge.next = vec![0; 2];
        judge.last = vec![[0.0; 4]; 2];
        let e = judge.judge(&[[0.0; 4]; 3]).expect_err("three chairs for two");
        assert!(e.contains("2 chair(s)") && e.contains("poses of 3"), "{e}");
        // The right number is judged: the first chair reaches the checkpoint, +10 with its
        // metre of progress.
        let j = judge.judge(&[[1.0, 0.0, 0.0, 0.0], [0.25, 0.0, 0.0, 0.0]]).expect("two chairs");
        assert_eq!(j.done, vec![true, false]);
        assert_eq!(j.rewards, vec![11.0, 0.25]);
    }
}
