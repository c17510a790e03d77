"""Multi-agent environments on an iwsim hub: a PettingZoo ``ParallelEnv`` (each chair an agent)
and a Gymnasium ``Env`` for one chair.

The hub owns the world: ``reset(seed=…)`` starts a lock-step hub process for that seed (``iwsim
hub``, from ``$IWSIM_BIN`` or ``iwsim`` on the PATH) and the environment is a client of it. Each
chair sees only its own sensors, as any agent does: an observation is its 8 proximity readings
in metres (the Intellwheels chair's, ``iwsim.CHAIR_SENSORS``: IR at 0°, +25°, -25°, sonars at
+60°, -60°, +90°, -90°, 180°) and its compass as (cos, sin) (zeros when the
run has no compass), float32, shape (10,). Rewards and
terminations are judged by an *observer* of the hub, from the true poses, never from what a
chair says. Same seed and same actions give the same observations, bit for bit.

The reward is a function you can swap (``reward=``); the default, ``progress_reward``, pays
the metres gained towards the chair's next checkpoint, ``-1`` per new contact, and ``+10``
on reaching the last checkpoint.
"""

from __future__ import annotations

import atexit
import json
import math
import os
import shutil
import subprocess
import uuid
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from . import CHAIR_BODY, CHAIR_MOTORS, CHAIR_SENSORS, IwsimError, Tick, _iwsim, connect
from . import referee

def _die_with_parent() -> None:
    """Run in the hub's child before exec: the kernel sends it SIGTERM when this process dies,
    however it dies (SIGKILL included), so a killed trainer leaves no hub running with its
    shared memory. The hub ends on SIGTERM as on a Stop, removing what it made."""
    import ctypes
    import signal

    pr_set_pdeathsig = 1
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(pr_set_pdeathsig, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # pragma: no cover - not Linux: the atexit hook remains
        return
    # The parent may have died between fork and prctl: then nobody would send the signal.
    if os.getppid() == 1:
        os.kill(os.getpid(), signal.SIGTERM)


try:  # the spaces both libraries use
    from gymnasium import Env, spaces
except ImportError as e:  # pragma: no cover - told plainly
    raise ImportError("iwsim.env needs gymnasium (pip install gymnasium pettingzoo)") from e
from pettingzoo import ParallelEnv

#: Proximity readings are clipped to this many metres in observations (the hub's longest reach).
MAX_RANGE_M = 20.0

_STOP = (0.0, 0.0)

#: How long a step polls for the hub's next tick before its thread sleeps: the hub's answer
#: usually comes sooner than a sleeping thread wakes (see ``iwsim.Agent.step``).
SPIN_S = 0.0005


@dataclass
class Scenario:
    """What an episode runs on: the lab, the checkpoints every chair drives through in order,
    static obstacles, the chairs' start poses, the tick and the time limit."""

    lab: str = "builtin:liacc"
    checkpoints: list[tuple[float, float, float]] = field(default_factory=lambda: [(10.0, 6.1, 0.5), (20.0, 6.1, 0.5)])
    obstacles: list[tuple[float, float, float, float]] = field(default_factory=list)
    starts: list[tuple[float, float, float]] = field(default_factory=lambda: [(10.0, 6.1, 0.0)])
    seconds: float = 60.0
    cycle_ms: int = 100
    noise: bool = True
    #: How long (ms) a lock-step tick waits for the chairs' actions: a learner may think (or
    #: train) between steps, so a minute unless the scenario file sets its own.
    deadline_ms: int = 60_000

    @classmethod
    def load(cls, path: str) -> "Scenario":
        """A scenario file of ``iwsim run`` (TOML, or ``builtin:NAME``): its lab, checkpoints,
        obstacles, time, tick, noise, deadline and the start poses of its agents' robots
        (``options.pose``). Read by ``iwsim run FILE --describe``, the reader ``iwsim run``
        itself uses, so a file means the same here and there and a mistake is reported with
        its line and column."""
        out = subprocess.run([_iwsim_bin(), "run", str(path), "--describe"], capture_output=True, text=True)
        if out.returncode != 0:
            raise IwsimError(out.stderr.strip() or f"iwsim run {path} --describe failed ({out.returncode})")
        d = json.loads(out.stdout)
        return cls(
            lab=d["lab"],
            checkpoints=[tuple(c) for c in d["checkpoints"]],
            obstacles=[tuple(o) for o in d["obstacles"]],
            starts=[tuple(p) for p in d["starts"]] or [(10.0, 6.1, 0.0)],
            seconds=float(d["seconds"]),
            cycle_ms=int(d["cycle_ms"]),
            noise=bool(d["noise"]),
            deadline_ms=int(d["deadline_ms"] or 60_000),
        )

    def ticks(self) -> int:
        return max(1, round(self.seconds * 1000 / self.cycle_ms))


@dataclass
class ChairState:
    """What the referee knows of the chairs after a tick (truth, from the observer): one entry
    per chair, in ``possible_agents`` order, as NumPy arrays, so a reward is computed for all
    chairs in one call."""

    x: np.ndarray
    y: np.ndarray
    heading_deg: np.ndarray
    contacts: np.ndarray
    #: The index of the checkpoint each chair drives to next (``len(checkpoints)`` once done).
    next_checkpoint: np.ndarray


def progress_reward(before: ChairState, after: ChairState, checkpoints) -> np.ndarray:
    """Metres gained towards the next checkpoint, -1 per new contact, +10 at the last one;
    one reward per chair (0 once a chair is done)."""
    m = len(checkpoints)
    contact = -(after.contacts - before.contacts)
    if m == 0:
        return contact
    cps = np.asarray(checkpoints, dtype=np.float64)
    going = before.next_checkpoint < m
    k = np.minimum(before.next_checkpoint, m - 1)
    cx, cy = cps[k, 0], cps[k, 1]
    gained = np.hypot(before.x - cx, before.y - cy) - np.hypot(after.x - cx, after.y - cy)
    done = going & (after.next_checkpoint >= m)
    return np.where(going, gained + contact + 10.0 * done, 0.0)


def _iwsim_bin() -> str:
    path = os.environ.get("IWSIM_BIN") or shutil.which("iwsim")
    if not path:
        raise IwsimError("no iwsim binary: set IWSIM_BIN or put iwsim on the PATH (cargo install --path .)")
    return path


class ChairsParallelEnv(ParallelEnv):
    """``n`` chairs of ``scenario`` (default: the LIACC corridor, checkpoints 10 m apart), one
    PettingZoo agent each, stepped in lock-step with one hub process per episode.

    With ``zenoh`` (an endpoint, ``"tcp/HOST:7447"``), the hubs run on another machine: each
    episode is started there by its episode host (``iwsim env-host``), and the chairs and the
    referee reach it through Zenoh. Nothing else changes."""

    metadata = {"name": "iwsim_chairs_v0", "render_modes": []}

    def __init__(
        self,
        n: int = 1,
        scenario: Scenario | str | None = None,
        reward: Callable[[ChairState, ChairState, list], np.ndarray] = progress_reward,
        spacing_m: float = 1.5,
        zenoh: Optional[str] = None,
    ) -> None:
        self.scenario = Scenario.load(scenario) if isinstance(scenario, str) else (scenario or Scenario())
        if n < 1:
            raise ValueError(f"n must be at least 1, not {n}")
        starts = list(self.scenario.starts)
        # More chairs than start poses: the rest line up behind the last, spacing_m apart.
        while len(starts) < n:
            x, y, h = starts[-1]
            starts.append((x - spacing_m * math.cos(math.radians(h)), y - spacing_m * math.sin(math.radians(h)), h))
        self._starts = starts[:n]
        self.reward_fn = reward
        self._judge = None
        self.possible_agents = [f"chair{i}" for i in range(n)]
        self._index = {a: k for k, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        low = np.array([0.0] * _iwsim.MAX_PROXIMITY + [-1.0, -1.0], dtype=np.float32)
        high = np.array([MAX_RANGE_M] * _iwsim.MAX_PROXIMITY + [1.0, 1.0], dtype=np.float32)
        self._obs_space = spaces.Box(low, high, dtype=np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._hub: Optional[subprocess.Popen] = None
        self._zenoh = zenoh
        self._host = None
        self._agent = None
        self._observer = None
        self._session: Optional[str] = None
        #: The hub's end-of-run summary of the last episode (its ``--json``: ticks, run_s,
        #: state_hash, …), once the episode is closed; ``None`` before.
        self.last_run: Optional[dict] = None
        atexit.register(self.close)

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Box:
        return self._act_space

    # -- the episode ---------------------------------------------------------------------

    def reset(self, seed: Optional[int] = None, options: Optional[dict] = None):
        self.close()
        s = self.scenario
        scenario = ["--cycle-ms", str(s.cycle_ms), "--ticks", str(s.ticks()),
                    "--seed", str(int.from_bytes(os.urandom(4), "little") if seed is None else int(seed)),
                    "--deadline-ms", str(s.deadline_ms)]
        if not s.noise:
            scenario.append("--no-noise")
        for o in s.obstacles:
            scenario += ["--obstacle", ",".join(map(str, o))]
        for c in s.checkpoints:
            scenario += ["--checkpoint", ",".join(map(str, c))]
        if self._zenoh is None:
            self._session = f"env-{os.getpid()}-{uuid.uuid4().hex[:8]}"
            args = [_iwsim_bin(), "hub", "--session", self._session, "--lockstep", "--wait-agents", "1",
                    "--lab", s.lab, "--json", *scenario]
            self._hub = subprocess.Popen(
                args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, preexec_fn=_die_with_parent
            )
        else:
            if self._host is None:
                self._host = referee.EpisodeHost(self._zenoh, 20)
            # A lab of this machine travels with the request; a built-in one is named.
            lab_xml = None
            if s.lab.startswith("builtin:"):
                scenario += ["--lab", s.lab]
            else:
                with open(s.lab, "rb") as f:
                    lab_xml = f.read()
            self._session = self._host.start(scenario, lab_xml)
        self._agent = connect(self._session, "iwsim-env", timeout=20, zenoh=self._zenoh)
        self._ids = {}
        for name, pose in zip(self.possible_agents, self._starts):
            self._ids[name] = self._agent.register(
                name, body=CHAIR_BODY, pose=pose, motors=CHAIR_MOTORS, sensors=CHAIR_SENSORS
            )
        self._id_list = [self._ids[n] for n in self.possible_agents]
        self._observer = referee.observe(self._session, 20, zenoh=self._zenoh)
        self._agent.ready()
        self._tick = self._agent.wait_tick(timeout=60)
        if self._tick is None:
            raise IwsimError("the hub ended the run before its first tick")
        self.agents = list(self.possible_agents)
        # Judged by the scenario as it is now: a user may change it between episodes.
        self._judge = referee.Judge([tuple(map(float, c)) for c in s.checkpoints])
        self._last_tick = s.ticks()
        self._judged = self._judge.start(self._observer, self._tick.tick, self._id_list, 20)
        return dict(zip(self.agents, self._observation_table())), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if self._tick is None or not self.agents:
            raise IwsimError("step() needs a running episode: call reset() first")
        # One native call: send every chair's action, wait for the hub's next tick, read the
        # chairs' observations and the referee's true poses.
        table = self._action_table(actions)
        try:
            stepped = referee.env_step(self._agent._native, self._observer, self._judge, self._tick.tick,
                                       table.tobytes(), MAX_RANGE_M, 60, SPIN_S)
        except ValueError:
            # The native side checks every power is finite before anything is sent: name the chair.
            bad = np.flatnonzero(~np.isfinite(table).all(axis=1))
            if not len(bad):
                raise
            k = int(bad[0])
            raise ValueError(f"{self.possible_agents[k]}: action {table[k]} is not finite") from None
        if stepped is None:
            # The hub's last tick has passed: the run's time limit.
            live = self.agents
            result = ({a: self._last_obs[self._index[a]] for a in live}, dict.fromkeys(live, 0.0),
                      dict.fromkeys(live, False), dict.fromkeys(live, True), {a: {} for a in live})
            self.agents = []
            return result
        tick, sim_time_s, raw_obs, raw_judged, rewards, done, contacts, any_done = stepped
        self._tick = Tick(tick, sim_time_s)
        n = len(self.possible_agents)
        table = self._last_obs = np.frombuffer(raw_obs, dtype=np.float32).reshape(n, -1)
        before, self._judged = self._judged, raw_judged
        if self.reward_fn is not progress_reward:  # else the judge's rewards are progress_reward's
            after = self._state(raw_judged)
            rewards = np.asarray(self.reward_fn(self._state(before), after, self.scenario.checkpoints), dtype=np.float64)
            if rewards.shape != (n,):
                raise ValueError(f"the reward function returned shape {rewards.shape}: one reward per chair expected")
            rewards = rewards.tolist()
        last = tick >= self._last_tick
        live = self.agents
        # The dicts PettingZoo asks for, from the judge's lists with as few Python steps per
        # chair as can be: this is most of what a step costs beside the hub's tick.
        if len(live) == n:
            obs = dict(zip(live, table))
            rewards = dict(zip(live, rewards))
            terminations = dict(zip(live, done))
        else:
            rows = [self._index[a] for a in live]
            obs = {a: table[k] for a, k in zip(live, rows)}
            rewards = {a: rewards[k] for a, k in zip(live, rows)}
            terminations = {a: done[k] for a, k in zip(live, rows)}
            contacts = [contacts[k] for k in rows]
        if last:
            truncations = {a: not t for a, t in terminations.items()}
        else:
            truncations = dict.fromkeys(live, False)
        infos = {a: {"tick": tick, "contacts": c} for a, c in zip(live, contacts)}
        if last or any_done:
            self.agents = [a for a in live if not (terminations[a] or truncations[a])]
        return obs, rewards, terminations, truncations, infos

    def _action_table(self, actions: dict) -> np.ndarray:
        """The actions as one (n, 2) float64 table in ``possible_agents`` order (chairs that are
        done, or not given, stop), checked to be a pair per chair (the native step checks that
        they are finite)."""
        names = self.possible_agents
        if len(self.agents) == len(names):
            rows = [actions.get(a, _STOP) for a in names]
        else:
            live = set(self.agents)
            rows = [actions.get(a, _STOP) if a in live else _STOP for a in names]
        try:
            table = np.array(rows, dtype=np.float64)
        except (ValueError, TypeError):
            table = None
        if table is None or table.shape != (len(names), 2):
            for name, r in zip(names, rows):
                if np.shape(r) != (2,):
                    raise ValueError(f"{name}: an action is (left, right), not shape {np.shape(r)}")
            raise ValueError("the actions are not one (left, right) pair per chair")
        return table

    def close(self) -> None:
        for part in (self._observer, self._agent):
            if part is not None:
                part.close()
        self._observer = self._agent = None
        if self._host is not None and self._session is not None:
            session, self._session = self._session, None
            out = self._host.end(session)
            self.last_run = json.loads(out) if out.startswith("{") else None
        if self._hub is not None:
            if self._hub.poll() is None:
                self._hub.terminate()
            try:
                out, _ = self._hub.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                self._hub.kill()
                out, _ = self._hub.communicate()
            self._hub = None
            self.last_run = next((json.loads(l) for l in out.splitlines() if l.startswith("{")), None)
        self.agents = []

    # -- what the chairs see, and what the referee sees --------------------------------

    def _observation_table(self) -> np.ndarray:
        # All chairs at once, one row each in registration order (possible_agents' order),
        # built natively from this tick's sensor blocks.
        self._last_obs = self._agent.observations(MAX_RANGE_M)
        return self._last_obs

    def _state(self, judged: bytes) -> ChairState:
        """The referee's view of one tick from the judge's table (``iwsim._iwsim.referee.Judge``:
        rows of x, y, heading, contacts, next checkpoint, reward), for a reward function of the
        user's."""
        x, y, heading, contacts, nxt, _ = np.frombuffer(judged, dtype=np.float64).reshape(-1, 6).T
        return ChairState(x, y, heading, contacts, nxt.astype(np.int64))


class ChairEnv(Env):
    """One chair of ``ChairsParallelEnv`` as a Gymnasium ``Env`` (``zenoh`` as there)."""

    metadata = {"render_modes": []}

    def __init__(
        self, scenario: Scenario | str | None = None, reward=progress_reward, zenoh: Optional[str] = None
    ) -> None:
        self._env = ChairsParallelEnv(1, scenario, reward, zenoh=zenoh)
        self._name = self._env.possible_agents[0]
        self.observation_space = self._env.observation_space(self._name)
        self.action_space = self._env.action_space(self._name)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        obs, infos = self._env.reset(seed=seed, options=options)
        return obs[self._name], infos[self._name]

    def step(self, action):
        obs, rewards, terms, truncs, infos = self._env.step({self._name: action})
        n = self._name
        return obs[n], rewards[n], terms[n], truncs[n], infos[n]

    def close(self) -> None:
        self._env.close()
