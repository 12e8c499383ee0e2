"""Render the README's frame: the paper scenario under the APF, near the encounter.

Usage: ``python baselines/render_frame.py [--time 112] [--out docs/frame.png]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import uasep_env
from uasep_env.policies import APF
from uasep_env.viz.frames import Renderer, save_frame


def main() -> None:
    """Fly the paper scenario with the APF until ``--time`` and save the frame as a PNG."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--time", type=float, default=112.0, help="simulated time (s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path(__file__).parents[1] / "docs/frame.png")
    args = parser.parse_args()
    env = uasep_env.parallel_env(scenario="paper")
    obs, _ = env.reset(seed=args.seed)
    apf = APF(env.config)
    renderer = Renderer(mode="rgb_array")  # what the env's render() draws with
    while env.world.time[0] < args.time and env.agents:
        obs, *_ = env.step({a: apf(obs[a]) for a in env.agents})
        if env.world.time[0] > args.time - 30.0:
            renderer.render(env.world)  # builds the trails of the last 30 s
    path = save_frame(env.world, args.out, renderer=renderer)
    renderer.close()
    print(f"wrote {path} at t = {env.world.time[0]:.1f} s")


if __name__ == "__main__":
    main()
