"""Speed side by side with the peers, measured in one run on the same machine.

Usage::

    pip install -e ".[bench]"        # MPE2 and VMAS (torch==2.13.0 installed first)
    python benchmarks/bench_peers.py [--seconds 3] [--sizes 1 64 1024 4096]
                                     [--ppo-envs 64 256] [--skip-ppo]
                                     [--jaxmarl-python /tmp/peers-venv/bin/python]

Prints steps/s and agent-steps/s of

* the PettingZoo env (3 UAVs, 1 obstacle, noise and Kalman filters on) at one environment
  against MPE2's ``simple_spread_v3`` parallel env (3 agents, continuous), stepped the same
  way (pre-drawn actions in a dict, one ``step`` per iteration, reset when done);
* the vector env (``gymnasium.make_vec``) at each size against VMAS's ``navigation``
  scenario on the CPU (3 agents, torch pinned to one thread) and the bare numpy double
  integrator at the same shapes (the ceiling), and how fast the env's noise alone can be
  drawn (a floor under the env's own step: per-environment generators, bit-reproducible);
* batched APF decisions/s;
* SB3 PPO training env-steps/s through the parameter-sharing adapter, and the share of
  its wall time spent inside the environment, for each ``--ppo-envs`` batch size;

* with ``--jaxmarl-python`` (a Python with JaxMARL, which is not a dependency of this project:
  ``benchmarks/bench_jaxmarl.py`` says how to make one), JaxMARL's MPE ``simple_spread_v3``
  at the largest size (jit, vmap and scan, random continuous actions) in a subprocess, right
  after the vector env's own figure at that size with random actions;

followed by the ratios the project's targets are stated in. Peers are optional: a missing
one is reported and skipped.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np


def _rate(fn: Callable[[], None], seconds: float, warmup: int = 3) -> float:
    """Calls of ``fn`` per second over about ``seconds``."""
    for _ in range(warmup):
        fn()
    n, start = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return n / elapsed


def _bench_parallel(env: object, pool: np.ndarray, seconds: float) -> float:
    """Steps/s of a PettingZoo parallel env fed pre-drawn actions, reset when done."""
    env.reset(seed=0)
    k = [0]

    def step() -> None:
        if not env.agents:
            env.reset()
        a = pool[k[0] % len(pool)]
        k[0] += 1
        env.step({agent: a[i] for i, agent in enumerate(env.agents)})

    return _rate(step, seconds)


def bench_pettingzoo(seconds: float) -> float:
    """Steps/s of the PettingZoo env at one environment."""
    import uasep_env

    env = uasep_env.parallel_env(n_uavs=3, n_obstacles=1, scenario="random")
    pool = np.random.default_rng(0).uniform(-1, 1, size=(1024, 3, 3)).astype(np.float32)
    return _bench_parallel(env, pool, seconds)


def bench_mpe2(seconds: float) -> float | None:
    """Steps/s of MPE2 simple_spread_v3 (3 agents, continuous) at one environment."""
    try:
        from mpe2 import simple_spread_v3
    except ImportError:
        return None
    env = simple_spread_v3.parallel_env(N=3, continuous_actions=True, max_cycles=10**9)
    pool = np.random.default_rng(0).uniform(0, 1, size=(1024, 3, 5)).astype(np.float32)
    return _bench_parallel(env, pool, seconds)


def bench_vector(n: int, seconds: float) -> float:
    """Env-steps/s of the native vector env with ``n`` environments."""
    import gymnasium

    import uasep_env  # noqa: F401

    vec = gymnasium.make_vec("uasep/Formation-v3", num_envs=n, n_uavs=3, n_obstacles=1)
    vec.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = rng.uniform(-1, 1, size=(8, *vec.action_space.shape)).astype(np.float32)
    k = [0]

    def step() -> None:
        vec.step(pool[k[0] % 8])
        k[0] += 1

    return _rate(step, seconds) * n


def bench_jaxmarl(python: str, n: int) -> float | None:
    """Agent-steps/s of JaxMARL's MPE ``simple_spread_v3`` at ``n`` envs, run by ``python``."""
    script = Path(__file__).with_name("bench_jaxmarl.py")
    try:
        done = subprocess.run(
            [python, str(script), "--envs", str(n)], capture_output=True, text=True, check=False
        )
    except OSError as err:  # not there, or not a program
        raise SystemExit(f"--jaxmarl-python {python!r}: cannot run it ({err})") from err
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    if done.returncode != 0 or not lines:
        print(f"JaxMARL: {python} failed ({done.stderr.strip().splitlines()[-1:]})")
        return None
    return float(json.loads(lines[-1])["jaxmarl_agent_steps_per_s"])


def bench_vmas(n: int, seconds: float) -> float | None:
    """Env-steps/s of VMAS navigation (3 agents, CPU, one torch thread)."""
    try:
        import torch
        import vmas
    except ImportError:
        return None
    torch.set_num_threads(1)
    env = vmas.make_env(
        scenario="navigation",
        num_envs=n,
        device="cpu",
        continuous_actions=True,
        n_agents=3,
        seed=0,
    )
    env.reset()
    actions = [torch.rand(n, 2) * 2 - 1 for _ in range(3)]

    def step() -> None:
        env.step(actions)

    return _rate(step, seconds) * n


def bench_bare_numpy(n: int, seconds: float, n_agents: int = 3, dt: float = 0.2) -> float:
    """Env-steps/s of a bare numpy double integrator (the ceiling) at ``(n, 3, 3)``."""
    pos = np.zeros((n, n_agents, 3))
    vel = np.zeros((n, n_agents, 3))
    acc = np.random.default_rng(0).uniform(-1, 1, size=(n, n_agents, 3))

    def step() -> None:
        pos[...] += dt * vel + (0.5 * dt * dt) * acc
        vel[...] += dt * acc

    return _rate(step, seconds) * n


def bench_noise(n: int, seconds: float) -> float:
    """Env-steps/s of drawing the env's noise alone (the floor under any step of it).

    One physics step's process, measurement and obstacle noise and the pilot's uniforms,
    from each environment's own generator, as :class:`uasep_env.World` draws them.
    """
    from uasep_env import World

    world = World({"n_uavs": 3, "n_obstacles": 1, "scenario": "random"}, n)
    world.reset(seed=0)
    return _rate(world._noise.draw, seconds) * n


def bench_apf(n: int, seconds: float) -> float:
    """Batched APF decisions/s (one decision = one UAV's action) on ``n`` environments."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.policies import APF

    cfg = make_config(n_uavs=3, n_obstacles=1, scenario="random")
    core = EnvCore(cfg, n_envs=n)
    obs = core.reset(seed=0)
    apf = APF(cfg)
    return _rate(lambda: apf(obs), seconds) * n * cfg.n_uavs


def bench_ppo(timesteps: int, n_envs: int) -> tuple[float, float] | None:
    """SB3 PPO env-steps/s (agent-steps) and the share of wall time spent in the env.

    One rollout-and-update is run first, untimed: it loads the compiled kernels and warms
    torch, one-off costs that would otherwise weigh on a short run.
    """
    try:
        import torch
        from stable_baselines3 import PPO
    except ImportError:
        return None
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    torch.set_num_threads(1)
    venv = UAVSharedVecEnv(n_envs=n_envs, n_uavs=3, n_obstacles=1, scenario="random", seed=0)
    env_time = [0.0]
    inner = venv.step_wait

    def timed_step_wait():  # noqa: ANN202
        t0 = time.perf_counter()
        out = inner()
        env_time[0] += time.perf_counter() - t0
        return out

    venv.step_wait = timed_step_wait  # type: ignore[method-assign]
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=4096, n_epochs=4, device="cpu", seed=0)
    model.learn(total_timesteps=model.n_steps * venv.num_envs)  # warm-up, untimed
    env_time[0], done_before = 0.0, model.num_timesteps
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps, reset_num_timesteps=False)
    wall = time.perf_counter() - start
    return (model.num_timesteps - done_before) / wall, env_time[0] / wall


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024, 4096])
    parser.add_argument("--ppo-timesteps", type=int, default=200_000)
    parser.add_argument("--ppo-envs", type=int, nargs="+", default=[64, 256])
    parser.add_argument("--skip-ppo", action="store_true")
    parser.add_argument("--jaxmarl-python", default="", help="a Python with JaxMARL installed")
    args = parser.parse_args()
    s = args.seconds
    from uasep_env import _numba

    print(f"compiled kernels (numba): {'on' if _numba.available() else 'off'}\n")
    print("== one environment, PettingZoo parallel API (3 agents) ==")
    pz = bench_pettingzoo(s)
    mpe = bench_mpe2(s)
    print(f"uasep parallel_env        {pz:>12,.0f} steps/s")
    print(f"MPE2 simple_spread_v3     {mpe:>12,.0f} steps/s" if mpe else "MPE2: not installed")

    print("\n== batched (env-steps/s; agent-steps/s = x3) ==")
    print(
        f"{'n_envs':>7} {'uasep vector':>14} {'VMAS nav':>14} {'bare numpy':>14} "
        f"{'noise only':>14} {'uasep/VMAS':>10} {'uasep/bare':>10} {'noise/bare':>10} "
        f"{'agent-steps/s':>14}"
    )
    rows = {}
    for n in args.sizes:
        ours = bench_vector(n, s)
        vm = bench_vmas(n, s)
        bare = bench_bare_numpy(n, s)
        noise = bench_noise(n, s)
        rows[n] = (ours, vm, bare)
        vm_txt = f"{vm:>14,.0f}" if vm else f"{'n/a':>14}"
        ratio = f"{ours / vm:>10.1f}" if vm else f"{'n/a':>10}"
        print(
            f"{n:>7} {ours:>14,.0f} {vm_txt} {bare:>14,.0f} {noise:>14,.0f} {ratio} "
            f"{ours / bare:>10.2%} {noise / bare:>10.1%} {ours * 3:>14,.0f}"
        )

    big = max(args.sizes)
    jax_rate = None
    if args.jaxmarl_python:
        jax_rate = bench_jaxmarl(args.jaxmarl_python, big)
        ours_big = bench_vector(big, s) * 3  # again, right beside JaxMARL's figure
        if jax_rate:
            print(
                f"\nJaxMARL MPE simple_spread_v3 at {big} envs: {jax_rate:,.0f} agent-steps/s; "
                f"uasep vector env right after it: {ours_big:,.0f}"
            )
    apf = bench_apf(big, s)
    print(f"\nbatched APF at {big} envs: {apf:,.0f} decisions/s")

    ppo = {}
    for n_envs in [] if args.skip_ppo else args.ppo_envs:
        res = bench_ppo(args.ppo_timesteps, n_envs=n_envs)
        if res is None:
            print("SB3 PPO: stable-baselines3/torch not installed")
            break
        ppo[n_envs] = res
        print(
            f"SB3 PPO ({n_envs} envs x 3 UAVs): {res[0]:,.0f} agent-steps/s, env share {res[1]:.1%}"
        )

    print("\n== targets (ratios from this run) ==")
    if mpe:
        print(f"PettingZoo env vs MPE2: {pz / mpe:.2f}x (target >= 2x)")
    ours, vm, bare = rows[big]
    print(f"vector env at {big}: {ours * 3:,.0f} agent-steps/s (target >= 3M)")
    if vm:
        print(f"vector env vs VMAS at {big}: {ours / vm:.1f}x (target >= 5x)")
    if jax_rate:
        print(f"vector env vs JaxMARL MPE at {big}: {ours_big / jax_rate:.2f}x (target >= 1x)")
    print(f"vector env vs bare numpy at {big}: {ours / bare:.1%} (target >= 60%)")
    print(f"batched APF: {apf:,.0f} decisions/s (target >= 1M)")
    for n_envs, (_, share) in ppo.items():
        print(f"env share of PPO wall time, {n_envs} envs: {share:.1%} (target < 15%)")


if __name__ == "__main__":
    main()
