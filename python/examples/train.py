"""A short training loop on many chairs at once: evolution strategies (no framework, NumPy
only) teach a linear policy to drive east across an open floor. Every chair of one
ChairsParallelEnv tries its own perturbation of the policy in the same episode; the returns
weigh the perturbations into the next policy. The reward is a custom one (metres driven east,
-1 per contact), to show that the reward function is swappable.

    IWSIM_BIN=target/release/iwsim python python/examples/train.py [--chairs 32] [--iterations 15]
"""

import argparse
import os
import tempfile

import numpy as np

from iwsim.env import ChairState, ChairsParallelEnv, Scenario


def east(before: ChairState, after: ChairState, checkpoints) -> float:
    return (after.x - before.x) - (after.contacts - before.contacts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chairs", type=int, default=32)
    ap.add_argument("--iterations", type=int, default=15)
    ap.add_argument("--seconds", type=float, default=8.0)
    args = ap.parse_args()
    n = args.chairs
    # An open floor, one row per chair, 1.5 m apart.
    lab = os.path.join(tempfile.mkdtemp(prefix="iwsim-train-"), "open.xml")
    height = 2.0 + 1.5 * n
    with open(lab, "w") as f:
        f.write(f'<Lab Name="open" Width="30" Height="{height}"></Lab>\n')
    scenario = Scenario(lab=lab, checkpoints=[], obstacles=[], starts=[(2.0, 1.0 + 1.5 * i, 0.0) for i in range(n)],
                        seconds=args.seconds, noise=True)
    env = ChairsParallelEnv(n, scenario, reward=east)
    rng = np.random.default_rng(0)
    dims = env.observation_space("chair0").shape[0] + 1  # the observation and a bias
    theta = np.zeros((2, dims))
    sigma, lr = 0.5, 0.3
    try:
        for it in range(args.iterations):
            eps = rng.standard_normal((n, 2, dims))
            policies = theta + sigma * eps
            returns = np.zeros(n)
            obs, _ = env.reset(seed=it)
            while env.agents:
                actions = {}
                for a in env.agents:
                    i = int(a[5:])
                    x = np.append(obs[a] / np.array([3.0] * 8 + [1.0, 1.0]), 1.0)
                    actions[a] = np.tanh(policies[i] @ x).astype(np.float32)
                obs, rewards, _, _, _ = env.step(actions)
                for a, r in rewards.items():
                    returns[int(a[5:])] += r
            ranked = (returns - returns.mean()) / (returns.std() + 1e-9)
            theta += lr / (n * sigma) * np.einsum("i,ijk->jk", ranked, eps)
            print(f"iteration {it:2d}: return mean {returns.mean():6.2f} m, best {returns.max():6.2f} m")
    finally:
        env.close()


if __name__ == "__main__":
    main()
