"""iwsim for Python: agents that drive robots in an iwsim hub over its shared memory.

This is the Rust agent SDK bound with PyO3 (the native module ``iwsim._iwsim``), not a UDP
client: a tick's sensor blocks arrive as one NumPy structured array whose dtype is built from
the Rust layout's own offsets, and actions go back the way a Rust agent's do.

    import iwsim

    with iwsim.connect("lab1") as agent:
        me = agent.register("chair1", body=(1.1, 0.65, 0.8), pose=(10.0, 6.1, 0.0))
        agent.ready()
        while (tick := agent.wait_tick()) is not None:
            front = agent.sensors()[0]["proximity_m"][0]
            agent.send(tick, {me: (0.5, 0.5) if front > 1.0 else (0.3, -0.3)})

Errors are typed: ``SessionNotFound`` (no hub there), ``Refused`` (the hub said no),
``HubGone`` (it exited), ``NoAnswer``, all ``IwsimError``; bad arguments raise ``ValueError``.
"""

from __future__ import annotations

from typing import Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from . import _iwsim
from ._iwsim import HubGone, IwsimError, NoAnswer, Refused, SessionNotFound

__all__ = [
    "Agent",
    "CHAIR_BODY",
    "CHAIR_MOTORS",
    "CHAIR_SENSORS",
    "HubGone",
    "IwsimError",
    "NoAnswer",
    "Refused",
    "SENSOR_BLOCK",
    "SessionNotFound",
    "Tick",
    "connect",
]


def _sensor_block_dtype() -> np.dtype:
    names, formats, offsets = [], [], []
    for name, offset, code, count in _iwsim.sensor_block_layout():
        names.append(name)
        offsets.append(offset)
        formats.append((code, (count,)) if count > 1 else code)
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": _iwsim.SENSOR_BLOCK_BYTES}
    )


#: The NumPy dtype of one sensor block, from the Rust definition's offsets (``ipc-types``).
SENSOR_BLOCK: np.dtype = _sensor_block_dtype()

#: The Intellwheels chair (``sim_model::chair``): body (length, width, centre of movement),
#: motors (top speed, acceleration curve) and its 8 sensors — 3 IR beams ahead (0°, ±25°) and
#: 5 sonars (±60°, ±90°, 180°) — as ``register`` takes them.
CHAIR_BODY = _iwsim.CHAIR_BODY
CHAIR_MOTORS = _iwsim.CHAIR_MOTORS
CHAIR_SENSORS = _iwsim.CHAIR_SENSORS


class Tick(NamedTuple):
    """One tick of the hub: its number (answer it with ``Agent.send``) and simulated time."""

    tick: int
    sim_time_s: float

    def __index__(self) -> int:
        return self.tick

    def __int__(self) -> int:
        return self.tick


class Agent:
    """A connection to a hub (``iwsim.connect``); a context manager that leaves on exit."""

    def __init__(self, native: _iwsim.Agent) -> None:
        self._native = native

    def register(
        self,
        name: str,
        *,
        body: Optional[Tuple[float, float, float]] = None,
        pose: Optional[Tuple[float, float, float]] = None,
        motors: Optional[Tuple[float, float]] = None,
        sensors: Optional[Sequence[Tuple[float, float, float, float, float]]] = None,
        id: int = 0,
    ) -> int:
        """Registers a robot and returns its id.

        ``body`` is (length m, width m, centre of movement as a fraction of the length from
        the rear), ``pose`` (x m, y m, heading degrees), ``motors`` (top speed m/s,
        acceleration curve), ``sensors`` up to 8 proximity cones (x m, y m, direction degrees,
        opening degrees, range m), e.g. ``CHAIR_SENSORS``; the hub's defaults where omitted.
        Raises ``Refused`` when the
        hub refuses it (a name in use, a pose inside a wall, a full world).
        """
        return self._native.register(name, body=body, pose=pose, motors=motors, sensors=sensors, id=id)

    def ready(self) -> None:
        """Says this agent's robots are registered (a lock-step run starts when all are)."""
        self._native.ready()

    def wait_tick(self, timeout: Optional[float] = None) -> Optional[Tick]:
        """The next tick, or ``None`` once the run has finished.

        Raises ``TimeoutError`` after ``timeout`` seconds without a tick and ``HubGone`` when
        the hub exits; Ctrl-C interrupts the wait.
        """
        t = self._native.wait_tick(timeout)
        return None if t is None else Tick(*t)

    def sensors(self) -> np.ndarray:
        """This tick's sensor blocks of this agent's robots: a read-only structured array of
        ``SENSOR_BLOCK`` (one row per robot; e.g. ``["proximity_m"]`` is an (n, 8) view)."""
        return np.frombuffer(self._native.sensors_bytes(), dtype=SENSOR_BLOCK)

    def send(self, tick: int | Tick, actions: Mapping[int, Sequence[float]]) -> None:
        """Answers ``tick`` with motor powers: ``{robot_id: (left, right)}``, each in [-1, 1].

        Raises ``ValueError`` for a robot that is not this agent's, a pair that is not two
        numbers, or a power that is not finite.
        """
        ids = [int(i) for i in actions]
        powers = np.asarray([np.asarray(actions[i], dtype=np.float64) for i in actions], dtype=np.float64)
        if powers.shape != (len(ids), 2):
            raise ValueError(
                f"actions must map each robot id to (left, right): got powers of shape {powers.shape[1:]}"
            )
        self._native.send(int(tick), [(i, float(l), float(r)) for i, (l, r) in zip(ids, powers)])

    def send_powers(self, tick: int | Tick, ids: np.ndarray, powers: np.ndarray) -> None:
        """Answers ``tick`` for many robots at once: ``ids`` (n,) and ``powers`` (n, 2) arrays,
        checked as ``send`` checks them, without a Python object per robot."""
        ids = np.ascontiguousarray(ids, dtype="<u4")
        powers = np.ascontiguousarray(powers, dtype="<f8")
        if ids.ndim != 1 or powers.shape != (ids.shape[0], 2):
            raise ValueError(f"ids must be (n,) and powers (n, 2): got {ids.shape} and {powers.shape}")
        self._native.send_powers(int(tick), ids.tobytes(), powers.tobytes())

    def step(self, tick: int | Tick, powers: np.ndarray, timeout: Optional[float] = None) -> Optional[Tick]:
        """Answers ``tick`` for all this agent's robots at once and waits for the next tick (as
        ``wait_tick``): ``powers`` is (n, 2), one (left, right) row per robot in registration
        order, each finite (the hub clamps them to [-1, 1]). One native call per tick, whatever n."""
        p = np.ascontiguousarray(powers, dtype="<f8")
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"powers must be (n, 2), one (left, right) row per robot: got shape {p.shape}")
        t = self._native.step(int(tick), p.tobytes(), timeout)
        return None if t is None else Tick(*t)

    def observations(self, max_range: float = 20.0) -> np.ndarray:
        """This tick's readings as a chair's observation, (n, 10) float32, one row per robot in
        registration order: its 8 proximity readings in metres (clipped to [0, ``max_range``];
        a missing one is ``max_range``) and its compass as (cos, sin) (zeros without one)."""
        table = np.frombuffer(self._native.observations(max_range), dtype=np.float32)
        return table.reshape(-1, _iwsim.MAX_PROXIMITY + 2)

    @property
    def robots(self) -> list[int]:
        """This agent's robot ids, in registration order."""
        return self._native.robots

    @property
    def finished(self) -> bool:
        """Whether the hub has ended the run."""
        return self._native.finished

    @property
    def session(self) -> Optional[str]:
        """The session's name (``None`` once closed)."""
        return self._native.session

    def close(self) -> None:
        """Leaves the hub (its robots go with it). Closing twice does nothing."""
        self._native.close()

    def __enter__(self) -> "Agent":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def connect(session: str, name: str = "python", timeout: float = 5.0, zenoh: Optional[str] = None) -> Agent:
    """Connects to the hub of ``session``, waiting up to ``timeout`` seconds for it.

    With ``zenoh`` (an endpoint such as ``"tcp/10.0.0.5:7447"``), the hub is on another
    machine and the agent joins through its Zenoh bridge (``iwsim zenoh`` there); every call
    after this works the same.

    Raises ``SessionNotFound`` when no hub (or bridge) serves the session by then.
    """
    return Agent(_iwsim.connect(session, name, timeout, zenoh))
