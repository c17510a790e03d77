"""The environments, checked by PettingZoo's and Gymnasium's own API tests, and for determinism."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from iwsim.env import ChairEnv, ChairsParallelEnv, Scenario

SLALOM = pathlib.Path(__file__).resolve().parents[2] / "hub/runner/scenarios/slalom.toml"


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
