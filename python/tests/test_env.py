"""The environments, checked by PettingZoo's and Gymnasium's own API tests, and for determinism."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from iwsim import IwsimError
from iwsim.env import ChairEnv, ChairsParallelEnv, Scenario

SLALOM = pathlib.Path(__file__).resolve().parents[2] / "runner/scenarios/slalom.toml"


@pytest.fixture(autouse=True)
def iwsim_on_path(monkeypatch):
    from conftest import iwsim_bin

    monkeypatch.setenv("IWSIM_BIN", iwsim_bin())


def short(seconds: float = 3.0) -> Scenario:
    s = Scenario.load(str(SLALOM))
    s.seconds = seconds
    return s


def test_the_slalom_file_gives_its_lab_checkpoints_obstacles_and_start():
    s = Scenario.load(str(SLALOM))
    assert s.lab == "builtin:liacc"
    assert [c[:2] for c in s.checkpoints] == [(10.0, 6.1), (20.0, 6.1)]
    assert len(s.obstacles) == 2 and s.starts[0] == (10.0, 6.1, 0.0)
    assert s.deadline_ms == 60_000, "the file sets none: a learner's minute"


def test_a_scenario_file_is_read_by_iwsims_own_reader_with_its_errors(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('name = "s"\nseconds = 5\ndeadline_ms = 900\nlab = "builtin:ward"\n'
                 '[[agents]]\nkind = "navigator"\noptions = { pose = [3, 4, 90] }\n')
    s = Scenario.load(str(f))
    assert (s.lab, s.seconds, s.deadline_ms, s.starts) == ("builtin:ward", 5.0, 900, [(3.0, 4.0, 90.0)])
    f.write_text('name = "s"\nseconds = 5\n[[agents]]\nkind = "navigator"\nbogus = 1\n')
    with pytest.raises(IwsimError, match="line 5"):
        Scenario.load(str(f))


def test_pettingzoos_parallel_api_test_passes():
    from pettingzoo.test import parallel_api_test

    env = ChairsParallelEnv(3, short())
    try:
        parallel_api_test(env, num_cycles=40)
    finally:
        env.close()


def test_gymnasiums_env_checker_passes():
    from gymnasium.utils.env_checker import check_env

    env = ChairEnv(short())
    try:
        check_env(env, skip_render_check=True)
    finally:
        env.close()


def test_one_seed_and_one_action_sequence_give_identical_observations():
    rng = np.random.default_rng(7)
    actions = [{f"chair{i}": rng.uniform(-1, 1, 2).astype(np.float32) for i in range(2)} for _ in range(25)]

    def episode(seed):
        env = ChairsParallelEnv(2, short())
        try:
            obs, _ = env.reset(seed=seed)
            seen = [np.stack([obs[a] for a in sorted(obs)])]
            rewards = []
            for act in actions:
                if not env.agents:
                    break
                obs, rew, _, _, _ = env.step({a: act[a] for a in env.agents})
                seen.append(np.stack([obs[a] for a in sorted(obs)]))
                rewards.append(sorted(rew.items()))
            return np.concatenate(seen), rewards
        finally:
            env.close()

    a, ra = episode(3)
    b, rb = episode(3)
    assert a.tobytes() == b.tobytes() and ra == rb, "same seed, same actions: same run, bit for bit"
    c, _ = episode(4)
    assert a.tobytes() != c.tobytes(), "another seed draws other sensor noise"


def test_driving_ahead_is_rewarded_and_a_bad_action_is_refused():
    env = ChairsParallelEnv(1, short(5.0))
    try:
        env.reset(seed=1)
        total = 0.0
        for _ in range(20):
            _, rew, _, _, _ = env.step({"chair0": np.array([1.0, 1.0], dtype=np.float32)})
            total += rew["chair0"]
        assert total > 0.5, f"20 ticks at full power towards checkpoint 2 gained {total}"
        with pytest.raises(ValueError, match="not finite"):
            env.step({"chair0": np.array([np.nan, 0.0])})
        with pytest.raises(ValueError, match="shape"):
            env.step({"chair0": np.array([0.5, 0.5, 0.5])})
        env.step({"chair0": np.array([0.0, 0.0])})  # the episode goes on
    finally:
        env.close()


def test_a_swapped_reward_sees_every_chair_at_once_and_a_wrong_shape_is_refused():
    from iwsim.env import ChairState

    seen = []

    def east(before: ChairState, after: ChairState, checkpoints):
        seen.append((before.x.shape, after.next_checkpoint.shape))
        return (after.x - before.x) - (after.contacts - before.contacts)

    env = ChairsParallelEnv(2, short(), reward=east)
    try:
        env.reset(seed=2)
        _, rew, _, _, _ = env.step({"chair0": np.array([1.0, 1.0]), "chair1": np.array([0.0, 0.0])})
        _, rew, _, _, _ = env.step({"chair0": np.array([1.0, 1.0]), "chair1": np.array([0.0, 0.0])})
        assert seen == [((2,), (2,))] * 2
        assert rew["chair0"] > 0.0 and rew["chair1"] == 0.0, rew
        env.reward_fn = lambda before, after, checkpoints: 1.0
        with pytest.raises(ValueError, match="one reward per chair"):
            env.step({"chair0": np.array([0.0, 0.0]), "chair1": np.array([0.0, 0.0])})
    finally:
        env.close()


def test_the_judges_default_reward_is_progress_reward_to_the_bit():
    # The default reward is judged natively; progress_reward, given as a reward of one's own,
    # runs in NumPy on the same states. Chair 0 passes both checkpoints (the +10 and its
    # termination); chair 1 drives into it from the east (contacts, -1 each).
    from iwsim.env import progress_reward

    s = Scenario(lab="builtin:liacc", checkpoints=[(10.0, 6.1, 0.5), (12.0, 6.1, 0.5)],
                 starts=[(9.5, 6.1, 0.0), (15.5, 6.1, 180.0)], seconds=12.0)

    def episode(reward):
        env = ChairsParallelEnv(2, s, reward=reward)
        try:
            env.reset(seed=5)
            steps = []
            while env.agents:
                steps.append(env.step({a: np.array([1.0, 1.0]) for a in env.agents})[1:])
            return steps
        finally:
            env.close()

    native = episode(progress_reward)
    numpy = episode(lambda before, after, checkpoints: progress_reward(before, after, checkpoints))
    assert native == numpy, "the same rewards, terminations, truncations and infos, step by step"
    rewards = [r for rew, *_ in native for r in rew.values()]
    assert max(rewards) > 10.0, "chair 0 reached the last checkpoint"
    assert any(t["chair0"] for _, t, *_ in native if "chair0" in t), "and was done there"
    assert max(info["chair1"]["contacts"] for *_, infos in native for info in [infos] if "chair1" in info) > 0, \
        "chair 1 ran into chair 0"
    assert min(rewards) < -0.5, "a contact costs its -1"


def _running(pid: int) -> bool:
    """Whether process `pid` exists and has not exited (a zombie waiting for its reaper has)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def test_a_trainer_killed_outright_takes_its_hub_with_it(tmp_path):
    # SIGKILL runs no atexit hook: the hub's parent-death signal must end it.
    import os
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "trainer.py"
    script.write_text(
        "import time\n"
        "from iwsim.env import ChairEnv, Scenario\n"
        f"s = Scenario.load({str(SLALOM)!r}); s.seconds = 600\n"
        "env = ChairEnv(s)\n"
        "env.reset(seed=1)\n"
        "print(env._env._hub.pid, flush=True)\n"
        "time.sleep(600)\n"
    )
    trainer = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    hub_pid = None
    try:
        hub_pid = int(trainer.stdout.readline())
        assert _running(hub_pid), "the hub runs"
        trainer.send_signal(signal.SIGKILL)
        trainer.wait(timeout=20)
        deadline = time.monotonic() + 20
        while _running(hub_pid) and time.monotonic() < deadline:
            time.sleep(0.05)  # polling the process table until the deadline, not a fixed wait
        assert not _running(hub_pid), "the hub outlived the trainer killed with SIGKILL"
    finally:
        if trainer.poll() is None:
            trainer.kill()
        if hub_pid is not None and _running(hub_pid):
            os.kill(hub_pid, signal.SIGKILL)


@pytest.fixture
def other_host():
    """An episode host (``iwsim env-host``) on another host as far as the network goes: a
    network namespace joined to this one by a veth pair (root makes them; CI runs as root). It
    yields the endpoint the environments connect to, and is stopped (SIGTERM) at the end,
    which must leave nothing running and nothing in /dev/shm."""
    import os
    import pathlib
    import subprocess

    from conftest import iwsim_bin

    if os.geteuid() != 0:
        pytest.fail("the remote environment test makes a network namespace (`ip netns add`): run it as root")
    tag = f"iwpy{os.getpid() % 100000}"
    ns, link, peer = f"{tag}n", f"{tag}h", f"{tag}p"
    subnet = f"10.251.{os.getpid() % 250}"

    def ip(*args):
        subprocess.run(["ip", *args], check=True, capture_output=True)

    ip("netns", "add", ns)
    try:
        ip("link", "add", link, "type", "veth", "peer", "name", peer)
        ip("link", "set", peer, "netns", ns)
        ip("addr", "add", f"{subnet}.1/30", "dev", link)
        ip("link", "set", link, "up")
        ip("-n", ns, "addr", "add", f"{subnet}.2/30", "dev", peer)
        ip("-n", ns, "link", "set", peer, "up")
        ip("-n", ns, "link", "set", "lo", "up")
        endpoint = f"tcp/{subnet}.2:7447"
        host = subprocess.Popen(
            ["ip", "netns", "exec", ns, iwsim_bin(), "env-host", "--listen", endpoint],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            # Its first line says it serves.
            line = host.stderr.readline()
            assert "episodes served under" in line, line
            yield endpoint, host.pid
        finally:
            host.terminate()
            _, err = host.communicate(timeout=60)
            assert host.returncode == 0, err
            left = [p.name for p in pathlib.Path("/dev/shm").glob("iwsim_*") if f"env-{host.pid}-" in p.name]
            assert not left, f"left in /dev/shm: {left}"
    finally:
        subprocess.run(["ip", "link", "del", link], capture_output=True)
        subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def test_an_env_whose_hubs_run_on_another_host_passes_parallel_api_test_and_runs_as_here(other_host):
    from pettingzoo.test import parallel_api_test

    endpoint, _ = other_host
    env = ChairsParallelEnv(3, short(), zenoh=endpoint)
    try:
        parallel_api_test(env, num_cycles=40)
    finally:
        env.close()

    rng = np.random.default_rng(11)
    actions = [{f"chair{i}": rng.uniform(-1, 1, 2).astype(np.float32) for i in range(2)} for _ in range(25)]

    def episode(zenoh):
        env = ChairsParallelEnv(2, short(), zenoh=zenoh)
        try:
            obs, _ = env.reset(seed=5)
            seen = [np.stack([obs[a] for a in sorted(obs)])]
            rewards = []
            for act in actions:
                obs, rew, _, _, _ = env.step({a: act[a] for a in env.agents})
                seen.append(np.stack([obs[a] for a in sorted(obs)]))
                rewards.append(sorted(rew.items()))
        finally:
            env.close()
        return np.concatenate(seen), rewards, env.last_run

    here, rewards_here, run_here = episode(None)
    there, rewards_there, run_there = episode(endpoint)
    # The same seed and actions: the same sensor readings and rewards (judged from the truth the
    # referee read over the link), bit for bit.
    assert here.tobytes() == there.tobytes()
    assert rewards_here == rewards_there
    # The host answered the episode's end with its hub's summary.
    assert run_there is not None and run_there["ticks"] >= len(actions), run_there


def test_an_env_host_refuses_what_an_episode_may_not_set(other_host):
    from iwsim import IwsimError
    from iwsim import referee

    endpoint, _ = other_host
    host = referee.EpisodeHost(endpoint, 20)
    with pytest.raises(IwsimError, match="not an option an episode may set"):
        host.start(["--record", "/etc/x.mcap"])
    with pytest.raises(IwsimError, match="the hub did not start"):
        host.start(["--obstacle", "nonsense"])
    with pytest.raises(IwsimError, match="no episode"):
        host.end("env-0-0")
