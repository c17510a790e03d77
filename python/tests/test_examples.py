"""The examples under python/examples run as their docstrings show (shortened), and do what
they say."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"


def run(script: str, *args: str) -> str:
    from conftest import iwsim_bin

    env = {**os.environ, "IWSIM_BIN": iwsim_bin()}
    out = subprocess.run([sys.executable, str(EXAMPLES / script), *args], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def test_the_reactive_avoider_drives_the_slalom_to_checkpoint_2_without_touching_anything():
    # Under A, over B, into checkpoint 2 (about 50 s simulated, well under a second of wall clock).
    out = run("avoider.py", "--seed", "1", "--seconds", "70")
    m = re.search(r"reached checkpoint 2 after \d+ steps \([0-9.]+ s\), return (-?[0-9.]+), (\d+) contacts", out)
    assert m, out
    assert float(m.group(1)) > 19.0 and int(m.group(2)) == 0, out


def test_the_training_loop_improves_its_policy():
    out = run("train.py", "--chairs", "16", "--iterations", "8", "--seconds", "5")
    means = [float(v) for v in re.findall(r"return mean\s+(-?[0-9.]+) m", out)]
    assert len(means) == 8, out
    assert means[-1] > means[0] + 1.0, out


def test_the_speed_bench_runs_and_times_every_variant_by_the_hub():
    import json

    script = pathlib.Path(__file__).resolve().parents[1] / "benches" / "speed.py"
    from conftest import iwsim_bin

    env = {**os.environ, "IWSIM_BIN": iwsim_bin()}
    out = subprocess.run([sys.executable, str(script), "--runs", "1", "--ticks", "40", "--chairs", "2", "--json"],
                         env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    result = json.loads(out.stdout)["2"]
    assert set(result) == {"python env", "rust sdk", "rust sdk busy-poll", "python udp", "env python us per step"}
    for kind, spread in result.items():
        assert spread["runs"] == 1 and spread["median"] > 0, (kind, spread)
