"""The Python agent API against a real hub over shared memory."""

from __future__ import annotations

import math
import subprocess

import numpy as np
import pytest

import iwsim


def test_the_sensor_block_dtype_is_the_rust_layout():
    # Built from ipc-types' offsets, not mirrored by hand: its size is the Rust struct's.
    assert iwsim.SENSOR_BLOCK.itemsize == iwsim._iwsim.SENSOR_BLOCK_BYTES == 864
    assert iwsim.SENSOR_BLOCK["proximity_m"].shape == (iwsim._iwsim.MAX_PROXIMITY,)
    assert iwsim.SENSOR_BLOCK.fields["tick"][1] == 0


def test_the_agent_api_has_no_call_that_returns_the_truth(hub_factory):
    # The truth is the referee's (iwsim.referee), apart from the agent API: neither the
    # package nor its native module offers an observer at the top, and an Agent has no call
    # that returns a true pose.
    for api in (iwsim, iwsim._iwsim):
        assert not hasattr(api, "observe") and not hasattr(api, "Observer") and not hasattr(api, "env_step")
    assert not any("world" in n or "pose" in n or "observe" in n for n in dir(iwsim._iwsim.Agent))
    # The referee sees the true pose the agent registered.
    from iwsim import referee

    hub = hub_factory("--lockstep", "--ticks", "5", "--wait-agents", "1", "--no-noise")
    with iwsim.connect(hub.session, "pytest", timeout=20) as agent:
        me = agent.register("chair1", body=(1.1, 0.65, 0.8), pose=(10.0, 6.1, 0.0), motors=(0.49, 0.83))
        judge = referee.observe(hub.session, 20)
        agent.ready()
        tick = agent.wait_tick(timeout=20)
        _, robots = judge.robots(tick.tick, 20)
        judge.close()
        assert [(r[0], r[1], r[2]) for r in robots] == [(me, 10.0, 6.1)]


def test_a_python_agent_drives_a_chair_in_lock_step_and_reads_its_sensors(hub_factory):
    hub = hub_factory("--lockstep", "--ticks", "30", "--wait-agents", "1", "--no-noise")
    with iwsim.connect(hub.session, "pytest", timeout=20) as agent:
        me = agent.register("chair1", body=(1.1, 0.65, 0.8), pose=(10.0, 6.1, 0.0), motors=(0.49, 0.83))
        assert agent.robots == [me]
        agent.ready()
        ticks, encoders = [], []
        while (tick := agent.wait_tick(timeout=20)) is not None:
            blocks = agent.sensors()
            assert blocks.dtype == iwsim.SENSOR_BLOCK and blocks.shape == (1,)
            assert not blocks.flags.writeable
            b = blocks[0]
            assert b["robot_id"] == me and b["tick"] == tick.tick
            encoders.append(tuple(b["encoder_ticks"]))
            ticks.append(tick.tick)
            agent.send(tick, {me: (1.0, 1.0)})
        assert agent.finished
    assert ticks == list(range(31)), ticks
    # Full power on both wheels: both encoders count up, equally (no noise).
    left, right = encoders[-1]
    assert left > 100 and left == right, encoders[-5:]
    # The hub's own end-of-run report agrees that the chair moved ahead, from x = 10.
    out = hub.stop()
    x = float(out.split("robot 1: x ")[1].split(" m")[0])
    assert x > 10.5, out


def test_proximity_readings_see_the_wall_ahead(hub_factory):
    # builtin:liacc's corridor: from (10, 6.1) facing south, the south wall (y 5.13) is 0.97 m off.
    hub = hub_factory("--lockstep", "--ticks", "3", "--wait-agents", "1", "--no-noise")
    with iwsim.connect(hub.session, timeout=20) as agent:
        me = agent.register("c", body=(1.1, 0.65, 0.8), pose=(10.0, 6.1, -90.0))
        agent.ready()
        tick = agent.wait_tick(timeout=20)
        front = agent.sensors()[0]["proximity_m"]
        agent.send(tick, {me: (0.0, 0.0)})
    assert float(front.min()) < 0.5, front


def test_a_session_without_a_hub_is_a_clear_error():
    with pytest.raises(iwsim.SessionNotFound) as e:
        iwsim.connect("py-no-such-session", timeout=0.2)
    assert "py-no-such-session" in str(e.value)
    assert isinstance(e.value, iwsim.IwsimError)


def test_bad_actions_and_registrations_raise_and_the_run_goes_on(hub_factory):
    hub = hub_factory("--lockstep", "--ticks", "5", "--wait-agents", "1")
    with iwsim.connect(hub.session, timeout=20) as agent:
        me = agent.register("chair1", pose=(10.0, 6.1, 0.0))
        with pytest.raises(iwsim.Refused, match="DuplicateId"):
            agent.register("chair2", pose=(12.0, 6.1, 0.0), id=me)
        with pytest.raises(ValueError, match="1 to"):
            agent.register("")
        agent.ready()
        tick = agent.wait_tick(timeout=20)
        with pytest.raises(ValueError, match="finite"):
            agent.send(tick, {me: (math.nan, 0.0)})
        with pytest.raises(ValueError, match="shape"):
            agent.send(tick, {me: (0.5, 0.5, 0.5)})
        with pytest.raises(ValueError, match="not one of this agent's robots"):
            agent.send(tick, {me + 99: (0.5, 0.5)})
        agent.send(tick, {me: (0.5, 0.5)})
        seen = [tick.tick]
        while (tick := agent.wait_tick(timeout=20)) is not None:
            agent.send(tick, {me: (0.5, 0.5)})
            seen.append(tick.tick)
        # Every tick of the run came, the refused calls cost none: 5 steps, states 0 to 5.
        assert seen == list(range(6))


def test_step_answers_every_robot_at_once_and_observations_are_its_sensors(hub_factory):
    # Two chairs in the LIACC corridor: one facing the south wall, one facing east.
    hub = hub_factory("--lockstep", "--ticks", "10", "--wait-agents", "1", "--no-noise")
    with iwsim.connect(hub.session, timeout=20) as agent:
        south = agent.register("south", body=iwsim.CHAIR_BODY, pose=(10.0, 6.1, -90.0), sensors=iwsim.CHAIR_SENSORS)
        east = agent.register("east", body=iwsim.CHAIR_BODY, pose=(14.0, 6.1, 0.0), sensors=iwsim.CHAIR_SENSORS)
        agent.ready()
        tick = agent.wait_tick(timeout=20)
        obs = agent.observations(max_range=5.0)
        blocks = agent.sensors()
        assert obs.shape == (2, 10) and obs.dtype == np.float32
        # Rows in registration order: the proximity readings (clipped to 5 m) and the compass.
        for row, block in zip(obs, blocks):
            want = np.minimum(block["proximity_m"][: block["proximity_count"]], 5.0).astype(np.float32)
            assert np.array_equal(row[: len(want)], want), (row, want)
            c = math.radians(float(block["compass_deg"]))
            assert np.allclose(row[-2:], [math.cos(c), math.sin(c)], atol=1e-6)
        assert blocks["robot_id"].tolist() == [south, east]
        # Compass as (cos, sin): south and east; the south chair has the wall within a metre.
        assert np.allclose(obs[:, -2:], [[0.0, -1.0], [1.0, 0.0]], atol=1e-6), obs
        assert obs[0, :8].min() < 1.0, obs
        with pytest.raises(ValueError, match="finite"):
            agent.step(tick, [[0.5, 0.5], [math.nan, 0.5]])
        with pytest.raises(ValueError, match="expected n × 2"):
            agent.step(tick, [[0.5, 0.5]])
        with pytest.raises(ValueError, match=r"\(n, 2\)"):
            agent.step(tick, [0.5, 0.5])
        seen = [tick.tick]
        # The refused calls sent nothing; one call per tick now drives both chairs.
        while (tick := agent.step(tick, np.array([[0.0, 0.0], [1.0, 1.0]]), timeout=20)) is not None:
            seen.append(tick.tick)
    assert seen == list(range(11)), seen
    out = hub.stop()
    x_east = float(out.split("robot 2: x ")[1].split(" m")[0])
    x_south = float(out.split("robot 1: x ")[1].split(" m")[0])
    assert x_east > 14.3 and abs(x_south - 10.0) < 0.01, out


def test_a_hub_that_dies_mid_run_raises_hub_gone(hub_factory):
    hub = hub_factory("--lockstep", "--wait-agents", "1")
    agent = iwsim.connect(hub.session, timeout=20)
    me = agent.register("chair1", pose=(10.0, 6.1, 0.0))
    agent.ready()
    tick = agent.wait_tick(timeout=20)
    agent.send(tick, {me: (0.0, 0.0)})
    hub.proc.kill()
    hub.proc.wait(timeout=20)
    with pytest.raises(iwsim.HubGone):
        while True:
            tick = agent.wait_tick(timeout=20)
            assert tick is not None
            agent.send(tick, {me: (0.0, 0.0)})
    agent.close()
    agent.close()  # twice is fine
    with pytest.raises(iwsim.IwsimError, match="closed"):
        agent.wait_tick()


def test_the_guides_example_runs_as_shown(hub_factory):
    import pathlib
    import re

    page = (pathlib.Path(__file__).resolve().parents[2] / "docs" / "python.md").read_text()
    example = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    assert 'iwsim.connect("lab1"' in example
    hub = hub_factory("--lockstep", "--ticks", "20", "--wait-agents", "1", "--no-noise")
    exec(compile(example.replace('"lab1"', repr(hub.session)), "docs/python.md", "exec"), {})
    out = hub.stop()
    x = float(out.split("robot 1: x ")[1].split(" m")[0])
    assert x > 10.2, out  # the example drove the chair ahead


def test_a_python_agent_and_a_rust_agent_share_one_lock_step_run(hub_factory):
    import re
    import subprocess

    from conftest import iwsim_bin

    hub = hub_factory("--lockstep", "--ticks", "30", "--wait-agents", "2", "--no-noise")
    rust = subprocess.Popen(
        [iwsim_bin(), "agent", "wheelchair", "--session", hub.session, "--connect-timeout", "20",
         "--name", "rust", "--pose", "12.5,6.1,0", "--powers", "0.5,0.5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        with iwsim.connect(hub.session, "python", timeout=20) as agent:
            me = agent.register("python", pose=(10.0, 6.1, 0.0))
            agent.ready()
            ticks = []
            while (tick := agent.wait_tick(timeout=20)) is not None:
                ticks.append(tick.tick)
                agent.send(tick, {me: (0.5, 0.5)})
        assert ticks == list(range(31))
        assert rust.wait(timeout=20) == 0, rust.communicate()
    finally:
        if rust.poll() is None:
            rust.kill()
            rust.wait()
    # Both chairs drove in the one world: the hub's report has each ahead of its start.
    out = hub.stop()
    xs = {int(i): float(x) for i, x in re.findall(r"robot (\d+): x ([0-9.]+) m", out)}
    assert len(xs) == 2, out
    assert sorted(xs.values())[0] > 10.2 and sorted(xs.values())[1] > 12.7, out


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_python_agent_through_zenoh_drives_as_it_does_in_shared_memory(hub_factory):
    from conftest import iwsim_bin

    def drive(zenoh):
        hub = hub_factory("--lockstep", "--ticks", "30", "--wait-agents", "1", "--no-noise")
        bridge = None
        if zenoh:
            bridge = subprocess.Popen(
                [iwsim_bin(), "zenoh", "--session", hub.session, "--listen", zenoh, "--connect-timeout", "20"],
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            )
        try:
            with iwsim.connect(hub.session, "pytest", timeout=20, zenoh=zenoh) as agent:
                me = agent.register("chair1", body=(1.1, 0.65, 0.8), pose=(10.0, 6.1, 0.0), motors=(0.49, 0.83))
                agent.ready()
                encoders = []
                while (tick := agent.wait_tick(timeout=20)) is not None:
                    b = agent.sensors()[0]
                    assert b["robot_id"] == me and b["tick"] == tick.tick
                    encoders.append(tuple(b["encoder_ticks"]))
                    agent.send(tick, {me: (1.0, 0.5)})
        finally:
            if bridge is not None:
                assert bridge.wait(timeout=20) == 0, bridge.stderr.read()
        out = hub.stop()
        return encoders, [line for line in out.splitlines() if line.startswith(("robot 1:", "tick "))]

    here = drive(None)
    remote = drive(f"tcp/127.0.0.1:{_free_port()}")
    assert len(here[0]) == 31 and remote == here, (remote, here)
