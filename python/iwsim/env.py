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
import tomllib
import uuid
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from . import CHAIR_BODY, CHAIR_MOTORS, CHAIR_SENSORS, IwsimError, _iwsim, connect

try:  # the spaces both libraries use
    from gymnasium import Env, spaces
except ImportError as e:  # pragma: no cover - told plainly
    raise ImportError("iwsim.env needs gymnasium (pip install gymnasium pettingzoo)") from e
from pettingzoo import ParallelEnv

#: Proximity readings are clipped to this many metres in observations (the hub's longest reach).
MAX_RANGE_M = 20.0


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

    @classmethod
    def load(cls, path: str) -> "Scenario":
        """A scenario file of ``iwsim run`` (TOML): its lab, checkpoints, obstacles, time and
        the start poses of its agents' robots (``options.pose``)."""
        with open(path, "rb") as f:
            t = tomllib.load(f)
        lab = t.get("lab", "builtin:liacc")
        if not lab.startswith("builtin:") and not os.path.isabs(lab):
            lab = os.path.join(os.path.dirname(os.path.abspath(path)), lab)
        starts = [tuple(a["options"]["pose"]) for a in t.get("agents", []) if "pose" in a.get("options", {})]
        return cls(
            lab=lab,
            checkpoints=[(c["x"], c["y"], c.get("radius", 0.5)) for c in t.get("checkpoints", [])],
            obstacles=[(o["x0"], o["y0"], o["x1"], o["y1"]) for o in t.get("obstacles", [])],
            starts=starts or [(10.0, 6.1, 0.0)],
            seconds=float(t.get("seconds", 60.0)),
            cycle_ms=int(t.get("cycle_ms", 100)),
            noise=bool(t.get("noise", True)),
        )

    def ticks(self) -> int:
        return max(1, round(self.seconds * 1000 / self.cycle_ms))


@dataclass
class ChairState:
    """What the referee knows of one chair after a tick (truth, from the observer)."""

    x: float
    y: float
    heading_deg: float
    contacts: int
    next_checkpoint: int


def progress_reward(before: ChairState, after: ChairState, checkpoints) -> float:
    """Metres gained towards the next checkpoint, -1 per new contact, +10 at the last one."""
    if before.next_checkpoint >= len(checkpoints):
        return 0.0
    cx, cy, _ = checkpoints[before.next_checkpoint]
    gained = math.hypot(before.x - cx, before.y - cy) - math.hypot(after.x - cx, after.y - cy)
    done = after.next_checkpoint >= len(checkpoints) > before.next_checkpoint
    return gained - (after.contacts - before.contacts) + (10.0 if done else 0.0)


def _iwsim_bin() -> str:
    path = os.environ.get("IWSIM_BIN") or shutil.which("iwsim")
    if not path:
        raise IwsimError("no iwsim binary: set IWSIM_BIN or put iwsim on the PATH (cargo install --path .)")
    return path


class ChairsParallelEnv(ParallelEnv):
    """``n`` chairs of ``scenario`` (default: the LIACC corridor, checkpoints 10 m apart), one
    PettingZoo agent each, stepped in lock-step with one hub process per episode."""

    metadata = {"name": "iwsim_chairs_v0", "render_modes": []}

    def __init__(
        self,
        n: int = 1,
        scenario: Scenario | str | None = None,
        reward: Callable[[ChairState, ChairState, list], float] = progress_reward,
        spacing_m: float = 1.5,
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
        self.possible_agents = [f"chair{i}" for i in range(n)]
        self.agents: list[str] = []
        low = np.array([0.0] * _iwsim.MAX_PROXIMITY + [-1.0, -1.0], dtype=np.float32)
        high = np.array([MAX_RANGE_M] * _iwsim.MAX_PROXIMITY + [1.0, 1.0], dtype=np.float32)
        self._obs_space = spaces.Box(low, high, dtype=np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._hub: Optional[subprocess.Popen] = None
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
        self._session = f"env-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        args = [_iwsim_bin(), "hub", "--session", self._session, "--lockstep", "--wait-agents", "1",
                "--lab", s.lab, "--cycle-ms", str(s.cycle_ms), "--ticks", str(s.ticks()),
                "--seed", str(int.from_bytes(os.urandom(4), "little") if seed is None else int(seed)),
                "--deadline-ms", "60000", "--json"]
        if not s.noise:
            args.append("--no-noise")
        for o in s.obstacles:
            args += ["--obstacle", ",".join(map(str, o))]
        for c in s.checkpoints:
            args += ["--checkpoint", ",".join(map(str, c))]
        self._hub = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self._agent = connect(self._session, "iwsim-env", timeout=20)
        self._ids = {}
        for name, pose in zip(self.possible_agents, self._starts):
            self._ids[name] = self._agent.register(
                name, body=CHAIR_BODY, pose=pose, motors=CHAIR_MOTORS, sensors=CHAIR_SENSORS
            )
        self._id_array = np.array([self._ids[n] for n in self.possible_agents], dtype=np.uint32)
        self._observer = _iwsim.observe(self._session, 20)
        self._agent.ready()
        self._tick = self._agent.wait_tick(timeout=60)
        if self._tick is None:
            raise IwsimError("the hub ended the run before its first tick")
        self.agents = list(self.possible_agents)
        self._last_obs = {}
        self._state = self._truth({n: 0 for n in self.agents})
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if self._tick is None or not self.agents:
            raise IwsimError("step() needs a running episode: call reset() first")
        # One row per chair in registration order; chairs that are done (or not given) stop.
        live = set(self.agents)
        rows = [actions.get(n, (0.0, 0.0)) if n in live else (0.0, 0.0) for n in self.possible_agents]
        for name, r in zip(self.possible_agents, rows):
            if np.shape(r) != (2,):
                raise ValueError(f"{name}: an action is (left, right), not shape {np.shape(r)}")
        table = np.asarray(rows, dtype=np.float64)
        finite = np.isfinite(table).all(axis=1)
        if not finite.all():
            k = int(np.flatnonzero(~finite)[0])
            raise ValueError(f"{self.possible_agents[k]}: action {table[k]} is not finite")
        np.clip(table, -1.0, 1.0, out=table)
        self._agent.send_powers(self._tick, self._id_array, table)
        self._tick = self._agent.wait_tick(timeout=60)
        over = self._tick is None
        if over:
            # The hub's last tick has passed: the run's time limit.
            obs = {a: self._last_obs[a] for a in self.agents}
            result = (obs, {a: 0.0 for a in self.agents}, {a: False for a in self.agents},
                      {a: True for a in self.agents}, {a: {} for a in self.agents})
            self.agents = []
            return result
        before = self._state
        after = self._truth({n: before[n].next_checkpoint for n in self.agents})
        obs = self._observations()
        checkpoints = self.scenario.checkpoints
        rewards = {a: float(self.reward_fn(before[a], after[a], checkpoints)) for a in self.agents}
        # No checkpoints: no goal, the episode ends at the time limit.
        terminations = {a: bool(checkpoints) and after[a].next_checkpoint >= len(checkpoints) for a in self.agents}
        last = self._tick.tick >= self.scenario.ticks()
        truncations = {a: last and not terminations[a] for a in self.agents}
        infos = {a: {"tick": self._tick.tick, "contacts": after[a].contacts} for a in self.agents}
        self._state = {**before, **after}
        self.agents = [a for a in self.agents if not (terminations[a] or truncations[a])]
        return obs, rewards, terminations, truncations, infos

    def close(self) -> None:
        for part in (self._observer, self._agent):
            if part is not None:
                part.close()
        self._observer = self._agent = None
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

    def _observations(self) -> dict:
        # All chairs at once, from the one structured array of this tick's blocks (registration
        # order, which is possible_agents' order).
        blocks = self._agent.sensors()
        n = len(blocks)
        table = np.empty((n, _iwsim.MAX_PROXIMITY + 2), dtype=np.float32)
        p = table[:, : _iwsim.MAX_PROXIMITY]
        p[:] = blocks["proximity_m"]
        p[~np.isfinite(p)] = MAX_RANGE_M
        p[np.arange(_iwsim.MAX_PROXIMITY) >= blocks["proximity_count"][:, None]] = MAX_RANGE_M
        np.clip(p, 0.0, MAX_RANGE_M, out=p)
        c = np.radians(blocks["compass_deg"])
        has = (blocks["present"] & _iwsim.HAS_COMPASS) != 0
        table[:, -2] = np.where(has, np.cos(c), 0.0)
        table[:, -1] = np.where(has, np.sin(c), 0.0)
        row = {int(i): k for k, i in enumerate(blocks["robot_id"])}
        obs = {name: table[row[self._ids[name]]] for name in self.agents}
        self._last_obs.update(obs)
        return obs

    def _truth(self, next_checkpoint: dict) -> dict:
        _, robots = self._observer.robots(self._tick.tick, 20)
        by_id = {r[0]: r for r in robots}
        out = {}
        for name, k in next_checkpoint.items():
            _, x, y, heading, contacts = by_id[self._ids[name]]
            cps = self.scenario.checkpoints
            while k < len(cps) and math.hypot(x - cps[k][0], y - cps[k][1]) <= cps[k][2]:
                k += 1
            out[name] = ChairState(x, y, heading, contacts, k)
        return out


class ChairEnv(Env):
    """One chair of ``ChairsParallelEnv`` as a Gymnasium ``Env``."""

    metadata = {"render_modes": []}

    def __init__(self, scenario: Scenario | str | None = None, reward=progress_reward) -> None:
        self._env = ChairsParallelEnv(1, scenario, reward)
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
