"""A reactive avoider drives the thesis's slalom (builtin:slalom's lab, checkpoints and
obstacles A and B) through the Gymnasium environment: keep to one side of the corridor, and
when something blocks the way ahead, cross to the side with more room. No map, no plan, no pose.

    IWSIM_BIN=target/release/iwsim python python/examples/avoider.py [--seed N]
"""

import argparse
import math
import pathlib
from collections import deque

import numpy as np

from iwsim.env import ChairEnv, Scenario

SLALOM = pathlib.Path(__file__).resolve().parents[2] / "runner/scenarios/slalom.toml"

BLOCKED_M = 0.9  # the front IR this near (mean of 3 readings): change sides now
GAP_M = 0.16  # the gap kept between the chair's side and the wall it keeps to
NOSE_M = 0.13  # the least gap for the front corner, 0.88 m ahead of the pose point
GENTLE, STEEP = math.radians(10), math.radians(32)


class Avoider:
    """Keep to one side, at ``GAP_M`` from whatever is there, wall or obstacle: to the right at
    first, so it slips under A (A is then just the thing on the left). When the front IR finds
    the way blocked (B, dead ahead in that lane), cross to the side where the sensors see more
    room, steeply, and level out as that side comes near, before the nose reaches it.

    Memory: the side kept to, whether it got there by a lane change (which may steer steeper),
    and the last few readings (the sonars' noise is 0.1 m, about the whole margin under A)."""

    def __init__(self) -> None:
        self.side = -1.0  # +1 keeps to the left, -1 to the right
        self.lane_change = False
        self.ahead: deque = deque(maxlen=3)
        self.gap: deque = deque(maxlen=4)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        heading = math.atan2(obs[9], obs[8])  # the compass, radians; east is 0
        self.ahead.append(float(obs[0]))
        # Only while pointing along the way: steering to a side, the front IR sees that wall.
        if np.mean(self.ahead) < BLOCKED_M and abs(heading) < GENTLE:
            side = 1.0 if obs[1] + obs[3] + obs[5] > obs[2] + obs[4] + obs[6] else -1.0
            if side != self.side:
                self.side, self.lane_change = side, True
                self.gap.clear()
        s = self.side
        t = s * heading  # how much the chair points towards its side
        r90, r60 = (float(obs[5]), float(obs[3])) if s > 0 else (float(obs[6]), float(obs[4]))
        # The side's gap as if the chair pointed along the wall, from both sonars on that side:
        # each reading made perpendicular (the cone's nearest ray: 90° sonar ±10°, 60° sonar ±5°)
        # and moved back from its mount (0.33 m and 0.88 m ahead of the pose point).
        cos_t = 0.325 * (math.cos(t) - 1.0)
        g90 = r90 * math.cos(max(0.0, abs(t) - math.radians(10))) + 0.33 * math.sin(t) + cos_t
        g60 = r60 * math.cos(max(0.0, abs(t - math.radians(30)) - math.radians(5))) + 0.88 * math.sin(t) + cos_t
        self.gap.append((g90 + g60) / 2.0)
        gap = float(np.mean(self.gap))
        # Point towards the side in proportion to the surplus gap, but never so steeply that the
        # nose would come within NOSE_M of it: the chair turns about a point 0.88 m behind its
        # front, so a steep climb ends with the nose against the wall and a flank on the corner.
        toward = min(1.2 * (gap - GAP_M), math.asin(float(np.clip((gap - NOSE_M) / 0.88, 0.0, 1.0))))
        # Drifting to its side it goes gently; a lane change must be done within a chair length.
        toward = float(np.clip(toward, -STEEP, STEEP if self.lane_change else GENTLE))
        turn = float(np.clip(1.5 * (s * toward - heading), -0.4, 0.4))
        speed = 0.4
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
