"""JaxMARL's MPE ``simple_spread_v3`` on the CPU: the peer figure of issue 30's first goal.

Usage (in an environment with JaxMARL; it is not one of this project's dependencies)::

    python -m venv /tmp/peers-venv
    /tmp/peers-venv/bin/pip install "jax[cpu]" jaxmarl
    /tmp/peers-venv/bin/python benchmarks/bench_jaxmarl.py [--envs 4096] [--steps 200]

JaxMARL's own way to run fast: the step ``jax.vmap``-ed over ``--envs`` environments and
``jax.lax.scan``-ned over ``--steps`` steps inside one ``jax.jit`` (episodes end after 25
steps and reset inside the step, as JaxMARL's ``step`` does), with uniform random continuous
actions drawn on the device. Compilation is paid once before timing. Prints one JSON line:
``{"jaxmarl_agent_steps_per_s": ..., "envs": ..., "agents": 3, "jax": "<version>"}``.
``benchmarks/bench_peers.py --jaxmarl-python /tmp/peers-venv/bin/python`` runs this script
beside its own measurements and prints the ratio.

This file imports nothing of uasep-env (it runs in JaxMARL's environment).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

# Pin the number of CPU threads XLA may use, like the other peers (see --threads).
_p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
_p.add_argument("--envs", type=int, default=4096)
_p.add_argument("--steps", type=int, default=200, help="steps per jit-ed scan")
_p.add_argument("--repeats", type=int, default=5, help="timed scans (their mean is kept)")
_p.add_argument(
    "--threads", type=int, default=0, help="XLA CPU threads (0: XLA's default, every core)"
)


def main() -> None:
    """Time the scanned, vmapped step and print the JSON line."""
    args = _p.parse_args()
    if args.threads > 0:
        os.environ["XLA_FLAGS"] = (
            os.environ.get("XLA_FLAGS", "")
            + f" --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads={args.threads}"
        )
    import jax
    import jax.numpy as jnp
    import jaxmarl

    env = jaxmarl.make("MPE_simple_spread_v3", action_type="Continuous")
    agents = env.agents
    dim = env.action_space(agents[0]).shape[0]

    def one_step(carry: Any, _: Any) -> tuple[Any, None]:
        key, state = carry
        key, k_act, k_step = jax.random.split(key, 3)
        acts = jax.random.uniform(k_act, (len(agents), args.envs, dim))
        actions = {a: acts[i] for i, a in enumerate(agents)}
        keys = jax.random.split(k_step, args.envs)
        _, state, _, _, _ = jax.vmap(env.step)(keys, state, actions)
        return (key, state), None

    @jax.jit
    def rollout(key: Any, state: Any) -> tuple[Any, Any]:
        (key, state), _ = jax.lax.scan(one_step, (key, state), None, length=args.steps)
        return key, state

    key = jax.random.PRNGKey(0)
    _, state = jax.vmap(env.reset)(jax.random.split(key, args.envs))
    key, state = rollout(key, state)  # compile
    jax.block_until_ready(state)
    start = time.perf_counter()
    for _ in range(args.repeats):
        key, state = rollout(key, state)
        jax.block_until_ready(state)
    seconds = time.perf_counter() - start
    rate = args.repeats * args.envs * args.steps * len(agents) / seconds
    print(
        json.dumps(
            {
                "jaxmarl_agent_steps_per_s": rate,
                "envs": args.envs,
                "agents": len(agents),
                "steps": args.steps,
                "jax": jax.__version__,
                "jnp_float": str(jnp.zeros(1).dtype),
            }
        )
    )


if __name__ == "__main__":
    main()
