"""A reactive avoider drives the thesis's slalom (builtin:slalom's lab, checkpoints and
obstacles A and B) through the Gymnasium environment: hold the compass east, turn away from
whatever the front sensors see near, keep off the side walls. No map, no plan, no pose.

    IWSIM_BIN=target/release/iwsim python python/examples/avoider.py [--seed N]
"""

import argparse
import math
import pathlib

import numpy as np

from iwsim.env import ChairEnv, Scenario

SLALOM = pathlib.Path(__file__).resolve().parents[2] / "hub/runner/scenarios/slalom.toml"


class Avoider:
    """The rule, with one bit of memory: which way it is turning round an obstacle, so sensor
    noise cannot make it dither left and right in front of one."""

    def __init__(self) -> None:
        self.side = 0.0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        heading = math.atan2(obs[9], obs[8])  # the compass, radians; east is 0
        # Where to point: east, or up to 15° off it to sidestep what the IR beams see ahead
        # (the ±25° beams count as nearer: they reach the walls farther on).
        ahead = float(min(obs[0], 1.6 * obs[1], 1.6 * obs[2]))
        if float(obs[0]) < 0.8:
            # Blocked straight ahead: choose afresh (the last sidestep may lead into this).
            self.side = 1.0 if obs[1] + obs[3] + obs[5] > obs[2] + obs[4] + obs[6] else -1.0
        elif ahead < 2.0:
            if self.side == 0.0:
                self.side = 1.0 if obs[1] + obs[3] + obs[5] > obs[2] + obs[4] + obs[6] else -1.0
        elif ahead > 2.5:
            self.side = 0.0
        target = self.side * math.radians(40 if float(obs[0]) < 0.8 else 15)
        turn = 1.5 * (target - heading)
        # Centre between what the side sonars see (+90° minus -90°), and off near corners.
        left, right = min(float(obs[5]), 1.0), min(float(obs[6]), 1.0)
        turn += 0.4 * (left - right)
        turn -= 0.9 * max(0.0, (0.6 - float(obs[3])) / 0.6) - 0.9 * max(0.0, (0.6 - float(obs[4])) / 0.6)
        turn = float(np.clip(turn, -0.5, 0.5))
        speed = 0.5 * float(np.clip((float(obs[0]) - 0.3) / 0.8, -0.3, 1.0))
        return np.clip(np.array([speed - turn, speed + turn], dtype=np.float32), -1.0, 1.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=120.0)
    args = ap.parse_args()
    scenario = Scenario.load(str(SLALOM))
    scenario.seconds = args.seconds
    env = ChairEnv(scenario)
    policy = Avoider()
    try:
        obs, _ = env.reset(seed=args.seed)
        total, steps, info = 0.0, 0, {}
        while True:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            total += reward
            steps += 1
            if terminated or truncated:
                break
        verdict = "reached checkpoint 2" if terminated else "ran out of time"
        print(f"avoider, seed {args.seed}: {verdict} after {steps} steps ({steps * scenario.cycle_ms / 1000:.1f} s), "
              f"return {total:.2f}, {info.get('contacts', 0)} contacts")
    finally:
        env.close()


if __name__ == "__main__":
    main()
