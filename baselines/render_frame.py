"""Render the README's frame: the paper scenario under the APF, near the encounter.

Usage: ``python baselines/render_frame.py [--time 112] [--out docs/frame.png]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import uasep_env
from uasep_env.policies import APF


def main() -> None:
    """Fly the paper scenario with the APF until ``--time`` and save an RGB frame."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--time", type=float, default=112.0, help="simulated time (s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path(__file__).parents[1] / "docs/frame.png")
    args = parser.parse_args()
    import matplotlib.image

    env = uasep_env.parallel_env(scenario="paper", render_mode="rgb_array")
    obs, _ = env.reset(seed=args.seed)
    apf = APF(env.config)
    while env.world.time[0] < args.time and env.agents:
        obs, *_ = env.step({a: apf(obs[a]) for a in env.agents})
        if env.world.time[0] > args.time - 30.0:
            env.render()  # builds the trails of the last 30 s
    frame = env.render()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(args.out, frame)
    print(f"wrote {args.out} ({frame.shape[1]}x{frame.shape[0]}) at t = {env.world.time[0]:.1f} s")


if __name__ == "__main__":
    main()
