"""The referee's view of an iwsim session: every robot's true pose, for judging a run (the
environments' rewards and terminations, a scoring script), never for the agent under test.

An agent uses :mod:`iwsim` (``iwsim.connect``): its own robots' sensors and the agents' map,
nothing else. The truth is here, apart, so that agent code that never imports this module
cannot reach it through the agent API; ``iwsim.env`` is the one module of the package that
does (an architecture invariant the test suite checks). Python cannot keep a module from code
in the same process: an agent is judged fairly when it runs in its own process (``iwsim run``
starts each agent so) or, in an environment, when its policy sees only the observations.
"""

from __future__ import annotations

from ._iwsim import referee as _native

from typing import Optional

Observer = _native.Observer
EpisodeHost = _native.EpisodeHost
env_step = _native.env_step
Judge = _native.Judge


def observe(session: str, timeout: float = 5.0, zenoh: Optional[str] = None) -> Observer:
    """Attaches to the hub of ``session`` as an observer (the hub does not count it as an agent);
    with ``zenoh`` (an endpoint, ``"tcp/HOST:7447"``), to a hub on another machine through its
    Zenoh bridge, which must serve observers (``iwsim zenoh --observers world`` there).

    ``robots(tick, timeout)`` gives ``(tick, [(id, x m, y m, heading °, collisions)])`` at that
    tick or later; ``poses(tick, ids, timeout)`` the same for ``ids`` as packed float64 rows.
    """
    return _native.observe(session, timeout, zenoh)


__all__ = ["EpisodeHost", "Judge", "Observer", "env_step", "observe"]
