"""Env steps per second of the Python environment against the same chairs driven by the Rust
agent SDK and by a Python client over the UDP/XML bridge, in one run.

    IWSIM_BIN=target/release/iwsim python python/benches/speed.py [--runs 5] [--ticks 2000] [--json]

Every variant runs the same lock-step hub (an open 40 m x 40 m floor, chairs 3 m apart, ten
to a row, driving east at constant powers) and is timed by the hub itself: ticks over its
``run_s`` (first tick to last), so all three are measured alike. One env step is one tick.
- python env: ``iwsim.env.ChairsParallelEnv``, one step() per tick, all chairs' observations
  built and their actions checked, rewards judged by the env's observer;
- rust sdk: ``iwsim agent wheelchair --robots N`` (the Rust SDK, one process), as agents run by
  default: it sleeps until the hub rings (in lock-step with fewer agents than cores, after
  spinning as long as the hub's tick header allows);
- rust sdk busy-poll: the same with ``--busy-poll``, spinning on the tick as the env's step
  does for up to half a millisecond before it sleeps (shown so the comparison is fair both ways);
- python udp: one Python process with one UDP socket per chair, as a Ciber-Rato client has,
  parsing every <Measures> with xml.etree and answering with <Actions>.
Medians of --runs runs, with min and max; and the env's own Python work per step (the time a
step spends outside its one native call).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import tempfile
import time
import uuid
import xml.etree.ElementTree as ET

import numpy as np

import iwsim.env
from iwsim.env import ChairsParallelEnv, Scenario

SPACING = 3.0


def starts(n: int) -> list[tuple[float, float, float]]:
    return [(3.0 + SPACING * (k % 10), 3.0 + SPACING * (k // 10), 0.0) for k in range(n)]


def iwsim_bin() -> str:
    return os.environ.get("IWSIM_BIN", "iwsim")


def hub(lab: str, ticks: int, session: str) -> subprocess.Popen:
    return subprocess.Popen(
        [iwsim_bin(), "hub", "--session", session, "--lab", lab, "--lockstep", "--ticks", str(ticks),
         "--wait-agents", "1", "--json", "--deadline-ms", "60000"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )


def rate(summary: dict) -> float:
    return summary["ticks"] / max(summary["run_s"], 1e-9)


def summary_of(out: str) -> dict:
    return next(json.loads(l) for l in out.splitlines() if l.startswith("{"))


class _TimedNative:
    """``iwsim.referee`` (as ``iwsim.env`` sees it) with its ``env_step`` timed: what a step
    spends outside it is the env's own Python work."""

    def __init__(self, native) -> None:
        self._native = native
        self.inside = 0.0

    def env_step(self, *args):
        t = time.perf_counter()
        try:
            return self._native.env_step(*args)
        finally:
            self.inside += time.perf_counter() - t

    def __getattr__(self, name):
        return getattr(self._native, name)


def python_env(lab: str, n: int, ticks: int, python_us: list[float]) -> float:
    # Two checkpoints beyond where the chairs get: the referee judges every chair against one
    # each step, as in a real task.
    s = Scenario(lab=lab, checkpoints=[(38.0, 38.0, 0.5), (38.0, 2.0, 0.5)], starts=starts(n), seconds=ticks / 10,
                 noise=True)
    env = ChairsParallelEnv(n, s)
    action = np.array([0.3, 0.28], dtype=np.float32)
    timed = _TimedNative(iwsim.env.referee)
    try:
        env.reset(seed=1)
        iwsim.env.referee = timed
        steps, start = 0, time.perf_counter()
        while env.agents:
            env.step({a: action for a in env.agents})
            steps += 1
        python_us.append((time.perf_counter() - start - timed.inside) / steps * 1e6)
    finally:
        iwsim.env.referee = timed._native
        env.close()
    return rate(env.last_run)


def rust_sdk(lab: str, n: int, ticks: int, busy_poll: bool = False) -> float:
    session = f"bench-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    h = hub(lab, ticks, session)
    agent = subprocess.run(
        [iwsim_bin(), "agent", "wheelchair", "--session", session, "--robots", str(n), "--pose", "3,3,0",
         "--spacing", str(SPACING), "--powers", "0.3,0.28", "--connect-timeout", "30"]
        + (["--busy-poll"] if busy_poll else []),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=600,
    )
    out, _ = h.communicate(timeout=60)
    assert agent.returncode == 0, "the Rust agent failed"
    return rate(summary_of(out))


def python_udp(lab: str, n: int, ticks: int) -> float:
    session = f"bench-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    h = hub(lab, ticks, session)
    bridge = subprocess.Popen([iwsim_bin(), "udp", "--session", session, "--port", "0", "--connect-timeout", "30"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        while True:
            line = bridge.stderr.readline()
            if not line:
                raise RuntimeError("the UDP bridge ended before announcing its port")
            if "registrations on " in line:
                host, port = line.split("registrations on ")[1].strip().rsplit(":", 1)
                server = (host, int(port))
                break
        socks = []
        for k, (x, y, d) in enumerate(starts(n)):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            s.settimeout(30)
            s.sendto(f'<Robot Name="udp{k}" X="{x}" Y="{y}" Dir="{d}"/>'.encode(), server)
            reply, peer = s.recvfrom(4096)
            assert reply.startswith(b'<Reply Status="Ok"'), reply
            s.connect(peer)
            socks.append(s)
        answered = 0
        while True:
            try:
                for s in socks:
                    s.settimeout(30 if answered == 0 else 1.5)
                    data = s.recv(4096)
                    m = ET.fromstring(data.rstrip(b"\0"))  # parsed as a stock client does
                    _ = [float(ir.get("Value", "0")) for ir in m.iter("IRSensor")]
                    b = m.find("Buttons")
                    if answered and b is not None and b.get("Start") == "Off" and b.get("Stop") == "Off":
                        raise EOFError  # the run is over (the bridge goes on until its clients leave)
                    s.send(b'<Actions LeftMotor="0.3" RightMotor="0.28"/>')
                    answered += 1
            except (socket.timeout, ConnectionRefusedError, EOFError):
                break
        out, _ = h.communicate(timeout=60)
        return rate(summary_of(out))
    finally:
        bridge.terminate()
        bridge.wait(timeout=20)
        if h.poll() is None:
            h.terminate()
            h.wait(timeout=20)


def spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "runs": len(values)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=2000)
    ap.add_argument("--chairs", type=int, nargs="*", default=[1, 10, 100])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    lab = os.path.join(tempfile.mkdtemp(prefix="iwsim-bench-"), "open.xml")
    with open(lab, "w") as f:
        f.write('<Lab Name="open" Width="40" Height="40"></Lab>\n')
    results = {}
    for n in args.chairs:
        runs = {"python env": [], "rust sdk": [], "rust sdk busy-poll": [], "python udp": []}
        python_us: list[float] = []
        for _ in range(args.runs):  # interleaved, so a slow moment hits all alike
            runs["python env"].append(python_env(lab, n, args.ticks, python_us))
            runs["rust sdk"].append(rust_sdk(lab, n, args.ticks))
            runs["rust sdk busy-poll"].append(rust_sdk(lab, n, args.ticks, busy_poll=True))
            runs["python udp"].append(python_udp(lab, n, args.ticks))
        results[n] = {k: spread(v) for k, v in runs.items()}
        results[n]["env python us per step"] = spread(python_us)
    if args.json:
        print(json.dumps(results))
        return
    print(f"env steps/s (lock-step ticks/s, by the hub), median [min, max] of {args.runs} runs of {args.ticks} ticks")
    kinds = ("python env", "rust sdk", "rust sdk busy-poll", "python udp")
    print(f"{'chairs':>6}" + "".join(f"  {k:>24}" for k in kinds) + "  env/rust  env/rust-busy  env/udp")
    for n, r in results.items():
        cell = lambda s: f"{s['median']:8.0f} [{s['min']:.0f}, {s['max']:.0f}]"
        e, rs, rb, u = (r[k]["median"] for k in kinds)
        print(f"{n:>6}" + "".join(f"  {cell(r[k]):>24}" for k in kinds)
              + f"  {e / rs:8.2f}  {e / rb:13.2f}  {e / u:7.1f}")
    print("the env's own Python work per step (outside its one native call), median µs: "
          + ", ".join(f"{n} chairs {r['env python us per step']['median']:.1f}" for n, r in results.items()))


if __name__ == "__main__":
    main()
