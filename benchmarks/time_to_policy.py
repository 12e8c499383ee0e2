"""Time to a policy: train a recipe until its validation figures reach the shipped checkpoint's.

Usage::

    python benchmarks/time_to_policy.py --recipe residual_apf [--max-minutes 60]
        [--episodes 100] [--check-every 2000000] [--out FILE] [--force] [--overwrite]
        [--held-out N] [--trainer default|lean] [--seeds N] [-- recipe flags]
    python benchmarks/time_to_policy.py --held-out N --of RECORD.json [--workers W]

The shipped checkpoint of the recipe (``baselines/checkpoints/<name>.zip``) plays the first
``--episodes`` validation encounters (:data:`uasep_env.scenarios.VALIDATION_SEEDS`; never
the held-out bank) and sets the bar: **no more collisions than the shipped policy** on them
(none for the residual recipe's), a loss-of-separation rate no higher than the upper end of
the shipped policy's 95 % Wilson interval, and a mean max deviation no higher than the upper
end of its 95 % Student-t interval. The recipe then trains from
scratch (its own defaults; flags after ``--`` go to it, ``uasep-train RECIPE --help``), and
every ``--check-every`` agent-steps its current actor plays the same encounters; the run
stops as soon as the figures clear the bar, or when ``--max-minutes`` of training time are
spent.

Printed, and written to ``--out`` (JSON, atomically; an existing file is kept unless
``--force``): whether the bar was reached, the training wall minutes and agent-steps when it
was (evaluation time excluded and reported apart), every check's figures, and where the
training time went: the environment (the vector env's step), the rest of the rollout
(policy inference, normalisation, the buffer) and the learner (PPO's update epochs).
With ``--held-out N``, a policy that reached the bar then plays the first ``N`` encounters of
the held-out bank (:data:`uasep_env.scenarios.HELD_OUT_SEEDS`, as ``train/seeds.py``'s
held-out stage), beside the APF and the shipped checkpoint, and the record gets their
figures with 95 % intervals (``held_out``): whether a policy reached this fast is as good as
the shipped one where no selection looked. ``--of RECORD`` adds them to an earlier record
whose run folder still holds its policy (``check.zip``, the last check's; its SHA-256 is
recorded).

With ``--seeds N`` the recipe trains ``N`` training seeds at once (``--seed`` 0, 1000, ...:
``train/seeds.py``'s), each in its own process sharing the cores (``UASEP_WORKERS=N``), each
checked as above; the first whose check clears the bar stops them all, and the record is
that run's, with ``side_by_side`` holding which seed reached, the agent-steps of all the
runs, the wall minutes and every run's own record (their folders ``seed_K`` under the run
folder). The shared and MAPPO recipes' shipped checkpoints are each the best checkpoint of
three training seeds (``baselines/results/seeds_shared.md``, ``seeds_mappo.md``): this
measures the time to a policy as good as theirs by the same road, whichever seed it comes
from (side by side, not in turn, so that the seeds' order does not matter).

The run folder (``--run-dir``, default ``runs/time_to_policy/<recipe>``) keeps the recipe's
usual files (``progress.csv``, checkpoints); a used one is refused before anything runs,
unless ``--overwrite`` (which replaces those files).

Recipes: ``residual_apf`` (shipped ``ppo_residual_apf.zip``) and ``shared``
(``ppo_shared.zip``), the SB3 recipes of :mod:`uasep_env.training`, and ``mappo``
(``mappo.zip``, skrl's MAPPO; its rollout time is the training less the env, the learner and
the checks, skrl having no rollout method to time); on the lean loop only,
``residual_apf_set`` (``ppo_residual_apf_set.zip``: the residual recipe with the set
network's shipped flags, :data:`SET_FLAGS`, trained at 3-8 UAVs and checked on validation
encounters at the held-out bank's 3, where the APF does not clear its bar) and
``lagrangian_residual`` (``ppo_lagrangian.zip``: the residual PPO-Lagrangian, its cost limit
measured before the clock starts). ``--trainer lean`` trains a PPO recipe
with :mod:`uasep_env.training.ppo_lean` (SB3's PPO arithmetic without SB3's per-step layers)
in place of SB3, and MAPPO with the same loop's centralised critic in place of skrl; the
record says which (``trainer``). Needs the ``train`` extra. Speed
figures are machine-dependent: the file records the machine.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CHECKPOINTS = ROOT / "baselines" / "checkpoints"


class Recipe(NamedTuple):
    """A recipe this benchmark trains.

    Attributes:
        shipped: Its shipped checkpoint's name (``baselines/checkpoints/<shipped>.zip``).
        module: The module holding its defaults.
        attr: Their name there (an ``Args`` instance, or the class: its defaults).
        reader: The module whose ``parse_args`` reads its flags and whose loop trains it
            (:data:`TRAINERS`): SB3's PPO, skrl's MAPPO or the PPO-Lagrangian's.
        flags: The shipped run's own flags, read before the caller's (after ``--``): a
            policy shipped from flags of another recipe (the set network's) is timed with
            them.
        checks: Flags' values (``Args`` fields) the checks' encounters are played with in
            place of the training run's: the set network's run validates at 8 UAVs, where
            the APF itself clears its shipped policy's bar on validation encounters, and is
            checked at the held-out bank's 3.
    """

    shipped: str
    module: str
    attr: str
    reader: str
    flags: tuple[str, ...] = ()
    checks: tuple[tuple[str, Any], ...] = ()


_PPO, _MAPPO = "uasep_env.training.ppo_shared", "uasep_env.training.mappo"
_LAGRANGIAN = "uasep_env.training.ppo_lagrangian"
#: The set network's shipped run (``baselines/results/seeds_residual_apf_set_mix_v3.md``).
SET_FLAGS = ("--trainer", "lean", "--arch", "set", "--hidden", "32,64", "--n-uavs", "8",
             "--k-uavs", "7", "--formation-sizes", "3,4,5,6,7,8", "--n-envs", "64",
             "--n-steps", "64", "--batch-size", "8192", "--n-epochs", "1",
             "--learning-rate", "0.0003400372129740376")  # fmt: skip
#: ``--recipe`` -> the recipe.
RECIPES = {
    "residual_apf": Recipe(
        "ppo_residual_apf", "uasep_env.training.ppo_residual_apf", "RESIDUAL_DEFAULTS", _PPO
    ),
    "residual_apf_set": Recipe(
        "ppo_residual_apf_set",
        "uasep_env.training.ppo_residual_apf",
        "RESIDUAL_DEFAULTS",
        _PPO,
        flags=SET_FLAGS,
        checks=(("n_uavs", 3), ("k_uavs", 2)),
    ),
    "shared": Recipe("ppo_shared", "uasep_env.training.args", "Args", _PPO),
    "mappo": Recipe("mappo", _MAPPO, "Args", _MAPPO),
    "lagrangian_residual": Recipe(
        "ppo_lagrangian", _LAGRANGIAN, "RESIDUAL_LAGRANGIAN_DEFAULTS", _LAGRANGIAN
    ),
}


@dataclass(frozen=True, kw_only=True)
class Bar:
    """The figures a trained policy must reach (from the shipped checkpoint's).

    Attributes:
        episodes: Validation encounters played.
        collision: Highest collision rate: the shipped policy's own on these encounters
            (records made before this field asked for none: 0).
        loss_of_separation: Highest loss-of-separation rate (the shipped policy's Wilson
            interval's upper end).
        max_deviation: Highest mean max deviation, m (its Student-t interval's upper end).
        shipped: The shipped policy's own figures.
    """

    episodes: int
    loss_of_separation: float
    max_deviation: float
    shipped: dict[str, float]
    collision: float = 0.0


def figures(aggregate: dict[str, Any]) -> dict[str, float]:
    """Collision and loss-of-separation rates and mean max deviation of an aggregate."""
    return {
        "collision": float(aggregate["episode.collision"]["rate"]),
        "loss_of_separation": float(aggregate["episode.loss_of_separation"]["rate"]),
        "max_deviation": float(aggregate["episode.max_deviation"]["mean"]),
    }


def make_bar(aggregate: dict[str, Any], episodes: int) -> Bar:
    """The bar set by the shipped checkpoint's aggregate on the validation encounters."""
    return Bar(
        episodes=episodes,
        collision=float(aggregate["episode.collision"]["rate"]),
        loss_of_separation=float(aggregate["episode.loss_of_separation"]["ci_high"]),
        max_deviation=float(aggregate["episode.max_deviation"]["ci_high"]),
        shipped=figures(aggregate),
    )


def reached(fig: dict[str, float], bar: Bar) -> bool:
    """Whether ``fig`` clears ``bar``: collisions, the rate and the deviation within it."""
    return (
        fig["collision"] <= bar.collision
        and fig["loss_of_separation"] <= bar.loss_of_separation
        and fig["max_deviation"] <= bar.max_deviation
    )


@dataclass(kw_only=True)
class Clock:
    """Seconds spent in each part of training (wrapped around the parts' calls)."""

    env_s: float = 0.0
    rollout_s: float = 0.0
    learner_s: float = 0.0
    eval_s: float = 0.0
    marks: dict[str, float] = field(default_factory=dict)

    def wrap(self, owner: Any, name: str, slot: str) -> None:
        """Time every call of ``owner.name`` into ``slot`` (an instance attribute)."""
        inner = getattr(owner, name)

        @functools.wraps(inner)
        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                setattr(self, slot, getattr(self, slot) + time.perf_counter() - t0)

        setattr(owner, name, timed)


def _recipe_args(recipe: str, run_dir: Path, extra: list[str]) -> Any:
    import importlib

    r = RECIPES[recipe]
    defaults = getattr(importlib.import_module(r.module), r.attr)
    defaults = defaults() if isinstance(defaults, type) else defaults
    argv = ["--out-dir", str(run_dir), "--no-progress", "--max-minutes", "1e6", *r.flags, *extra]
    return importlib.import_module(r.reader).parse_args(argv, defaults)


def _resolved(recipe: str, run_dir: Path, extra: list[str], trainer: str) -> tuple[Any, str]:
    """The recipe's arguments and its trainer, lean if either of its two sources says so.

    The script's ``--trainer`` and the recipe's (its shipped flags' or after ``--``) say the
    same thing.
    """
    args = _recipe_args(recipe, run_dir, extra)
    if "lean" in (trainer, args.trainer):
        return replace(args, trainer="lean"), "lean"
    return args, trainer


def _evaluate(policy: Any, config: Any, seeds: list[int]) -> dict[str, Any]:
    from uasep_env.evaluation import evaluate

    return evaluate({"p": policy}, config, seeds).results["p"].aggregate


@dataclass(kw_only=True)
class Checker:
    """Plays the validation encounters every ``check_every`` agent-steps; records each check.

    Attributes:
        bar: The figures to reach.
        seeds: The validation encounters.
        eval_cfg: The config they are played with (direct actions).
        check_every: Agent-steps between checks.
        max_minutes: Training-time budget (evaluations excluded).
        clock: Where the evaluation time is counted.
        checks: Every check's figures, in order.
        done: Whether a check cleared the bar.
        t0: When training started (``time.perf_counter``; the trainer sets it).
        next: The agent-steps at which the next check runs.
        stop_file: Side by side (``--seeds``): the file a run that clears the bar creates
            and whose existence stops the others; None when the run is alone.
        stopped_by_another: Whether the stop file, not this run's bar or budget, ended it.
    """

    bar: Bar
    seeds: list[int]
    eval_cfg: Any
    check_every: int
    max_minutes: float
    clock: Clock
    checks: list[dict[str, Any]] = field(default_factory=list)
    done: bool = False
    t0: float = field(default_factory=time.perf_counter)
    next: int = 0
    stop_file: Path | None = None
    stopped_by_another: bool = False

    def __post_init__(self) -> None:
        self.next = self.check_every

    def training_s(self) -> float:
        """Wall seconds since the start, evaluations excluded."""
        return time.perf_counter() - self.t0 - self.clock.eval_s

    def spent(self) -> bool:
        """Whether training should stop: the bar cleared or the budget spent.

        Side by side, also when another run has cleared the bar (its stop file exists).
        """
        if self.done or self.training_s() >= self.max_minutes * 60.0:
            return True
        self.stopped_by_another = self.stop_file is not None and self.stop_file.exists()
        return self.stopped_by_another

    def maybe_check(self, agent_steps: int, export: Any) -> None:
        """At a rollout's end: play the encounters when ``check_every`` more steps are done.

        Args:
            agent_steps: Agent-steps trained so far.
            export: Writes the current actor as a policy file; returns its path.
        """
        from uasep_env.policies import load_policy

        if agent_steps < self.next:
            return
        self.next += self.check_every
        e0 = time.perf_counter()
        fig = figures(_evaluate(load_policy(export(), self.eval_cfg), self.eval_cfg, self.seeds))
        self.clock.eval_s += time.perf_counter() - e0
        ok = reached(fig, self.bar)
        minutes = self.training_s() / 60.0
        # The wall clock (seconds since the epoch) orders the checks of runs side by side.
        self.checks.append({"agent_steps": int(agent_steps), "training_minutes": minutes, **fig,
                            "reached": ok, "unix_time": time.time()})  # fmt: skip
        print(f"{agent_steps:>12,} agent-steps {minutes:6.1f} min: "
              f"collisions {fig['collision']:.1%}, loss of separation "
              f"{fig['loss_of_separation']:.1%}, max deviation {fig['max_deviation']:.1f} m"
              f"{'  reached' if ok else ''}", flush=True)  # fmt: skip
        self.done = ok
        if ok and self.stop_file is not None:
            self.stop_file.touch()


def _train_sb3(args: Any, config: Any, run_dir: Path, checker: Checker) -> int:
    """Train an SB3 recipe under ``checker``; the agent-steps done."""
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    from uasep_env.training import ppo_shared

    venv, model = ppo_shared.build(args, config)
    clock = checker.clock
    clock.wrap(venv.venv.venv, "step_wait", "env_s")  # the batched env under the wrappers
    clock.wrap(model, "collect_rollouts", "rollout_s")
    clock.wrap(model, "train", "learner_s")
    progress = ppo_shared.make_callback(args, config, venv, 0.0, args.total_timesteps)

    class Check(BaseCallback):
        def _on_step(self) -> bool:
            return not checker.spent()

        def _on_rollout_end(self) -> None:
            export = functools.partial(ppo_shared.export_policy, self.model, venv, config,
                                       args, run_dir / "check.zip", {})  # fmt: skip
            checker.maybe_check(int(self.num_timesteps), export)

    checker.t0 = time.perf_counter()
    model.learn(args.total_timesteps, callback=CallbackList([Check(), progress]))
    # The checks run inside the rollout (at its end): not rollout time.
    clock.rollout_s -= clock.eval_s
    return int(model.num_timesteps)


def _train_skrl(args: Any, config: Any, run_dir: Path, checker: Checker) -> int:
    """Train the skrl MAPPO recipe under ``checker``; the agent-steps done."""
    from uasep_env.training import mappo

    clock = checker.clock

    class Hooks(mappo.Hooks):
        steps = 0  # agent-steps at the last rollout's end

        def start(self, agent: Any, env: Any, out: Path, resumed: dict) -> None:
            self.agent, self.venv = agent, env.venv
            clock.wrap(env.base, "step_wait", "env_s")  # the batched env under the wrappers
            clock.wrap(agent, "update", "learner_s")  # once per agent, after each rollout
            checker.t0 = time.perf_counter()

        def rollout_end(self, agent_steps: int) -> None:
            self.steps = agent_steps
            export = functools.partial(mappo.export_policy, self.agent, self.venv, config,
                                       args, run_dir / "check.zip", {})  # fmt: skip
            checker.maybe_check(agent_steps, export)

        def stop(self) -> bool:
            return checker.spent()

    hooks = Hooks()
    mappo.train(args, config, run_dir, hooks)
    # No rollout method to time: the rollout is the training less the env, the learner and
    # the checks (skrl's own step, the normalisation, the buffer).
    clock.rollout_s = checker.training_s() - clock.learner_s
    return hooks.steps


def _train_lean(
    args: Any,
    config: Any,
    run_dir: Path,
    checker: Checker,
    central: bool = False,
    constrained: bool = False,
) -> int:
    """Train a recipe with the lean loop (:mod:`uasep_env.training.ppo_lean`).

    ``central``: MAPPO's centralised critic (the MAPPO recipe's lean trainer).
    ``constrained``: the PPO-Lagrangian's multiplier shapes the rewards, as its recipe's
    run does (:meth:`uasep_env.training.ppo_lagrangian.Constraint.start_lean`; its cost
    limit measured before the clock starts).
    """
    from uasep_env.training import ppo_lean

    clock = checker.clock
    cost = None
    if constrained:
        from uasep_env.training.ppo_lagrangian import Constraint

        cost = Constraint(args).start_lean(run_dir, config, {})

    class Hooks(ppo_lean.Hooks):
        def start(self, nets: Any, norm: Any) -> None:
            self.nets, self.norm = nets, norm
            if cost is not None:
                cost.start(args.n_envs * config.n_uavs)
            checker.t0 = time.perf_counter()

        def rollout_end(self, agent_steps: int) -> None:
            if cost is not None:
                cost.rollout_end(agent_steps)  # the multiplier moves before the check
            export = functools.partial(ppo_lean.export_policy, self.nets, self.norm, config,
                                       args, run_dir / "check.zip", {})  # fmt: skip
            checker.maybe_check(agent_steps, export)

        def shape(self, res: Any, reward: Any, dones: Any) -> Any:
            return reward if cost is None else cost.shape(res, reward, dones)

        def stop(self) -> bool:
            return checker.spent()

    try:
        _, _, facts = ppo_lean.train(args, config, Hooks(), central=central)
    finally:
        if cost is not None:
            cost.close()
    # The loop times its own parts (the checks in none of them); the rollout's figure holds
    # the environment, as SB3's collect_rollouts does.
    clock.env_s, clock.learner_s = facts["env_s"], facts["learner_s"]
    clock.rollout_s = facts["env_s"] + facts["rollout_s"]
    return int(facts["agent_steps"])


#: Each recipe's training loop, by :attr:`Recipe.reader`.
TRAINERS = {_PPO: _train_sb3, _MAPPO: _train_skrl}
#: ``--trainer lean``: the lean loop in place of SB3's PPO and skrl's MAPPO.
LEAN = {
    _PPO: _train_lean,
    _MAPPO: functools.partial(_train_lean, central=True),
    _LAGRANGIAN: functools.partial(_train_lean, constrained=True),
}


def _loop(recipe: str, trainer: str) -> Any:
    """The training loop of ``recipe`` under ``trainer`` (``"default"`` or ``"lean"``).

    Raises:
        ValueError: ``trainer`` does not train ``recipe`` (a recipe without a lean loop).
    """
    reader = RECIPES[recipe].reader
    loops = LEAN if trainer == "lean" else TRAINERS
    if reader not in loops:
        raise ValueError(f"trainer {trainer!r}: not for the {recipe!r} recipe")
    return loops[reader]


def run(
    recipe: str,
    episodes: int,
    check_every: int,
    max_minutes: float,
    run_dir: Path,
    extra: list[str],
    overwrite: bool = False,
    trainer: str = "default",
    stop_file: Path | None = None,
) -> dict[str, Any]:
    """Train until the bar is reached or the budget is spent; the record (see the module).

    ``trainer``: ``"default"`` (SB3's PPO, or skrl's MAPPO) or ``"lean"`` (the recipe on
    :mod:`uasep_env.training.ppo_lean`). ``stop_file``: side by side, the file that a run
    clearing the bar creates and that stops the others (:attr:`Checker.stop_file`).
    """
    import torch

    from uasep_env.policies import load_policy
    from uasep_env.scenarios import VALIDATION_SEEDS
    from uasep_env.training import ppo_shared
    from uasep_env.training.rundir import prepare_out_dir

    args, trainer = _resolved(recipe, run_dir, extra, trainer)
    train = _loop(recipe, trainer)
    if getattr(args, "shield", "none") != "none":
        # The checks play the bare policy: a policy trained under the shield is deployed with it.
        raise SystemExit(
            f"time_to_policy.py: error: argument --shield: {args.shield!r} is not timed here "
            "(the checks play the policy without the shield)"
        )
    prepare_out_dir(run_dir, "", overwrite)  # before the bar's evaluation: refused at once
    torch.set_num_threads(args.torch_threads)
    config = ppo_shared.make_env_config(args)
    played_with = dict(RECIPES[recipe].checks)
    played = ppo_shared.make_env_config(replace(args, **played_with)) if played_with else config
    eval_cfg = played.replace(action={"mode": "direct"})
    seeds = list(VALIDATION_SEEDS)[:episodes]
    shipped = CHECKPOINTS / f"{RECIPES[recipe].shipped}.zip"
    bar = make_bar(_evaluate(load_policy(shipped, eval_cfg), eval_cfg, seeds), episodes)
    # The residual starts at the APF: a bar the APF clears measures nothing.
    apf = figures(_evaluate("apf", eval_cfg, seeds))
    if reached(apf, bar):
        print(f"warning: the APF clears the bar on these {episodes} encounters ({apf}); "
              "more --episodes narrow it", file=sys.stderr)  # fmt: skip
    print(f"bar ({episodes} validation encounters, {shipped.name}): collisions <= "
          f"{bar.collision:.2%}, loss of separation <= {bar.loss_of_separation:.1%}, "
          "mean max deviation <= "
          f"{bar.max_deviation:.1f} m", flush=True)  # fmt: skip

    clock = Clock()
    checker = Checker(bar=bar, seeds=seeds, eval_cfg=eval_cfg, check_every=check_every,
                      max_minutes=max_minutes, clock=clock, stop_file=stop_file)  # fmt: skip
    steps = train(args, config, run_dir, checker)
    gpu = gpu_name(args.device)
    train_s = checker.training_s()
    checks = checker.checks
    hit = next((c for c in checks if c["reached"]), None)
    return {
        "recipe": recipe,
        "trainer": trainer,
        "shipped": f"baselines/checkpoints/{shipped.name}",
        "bar": asdict(bar),
        # The training run's flags the checks' encounters replace (Recipe.checks).
        "checks_played_with": played_with,
        "apf": apf,
        "apf_clears_bar": reached(apf, bar),
        "reached": hit is not None,
        # Side by side: stopped because another run cleared the bar (not its budget).
        "stopped_by_another": checker.stopped_by_another,
        "training_minutes": (hit["training_minutes"] if hit else train_s / 60.0),
        "agent_steps": hit["agent_steps"] if hit else steps,
        "time_s": {
            "training": train_s,
            "env": clock.env_s,
            "rollout_other": clock.rollout_s - clock.env_s,
            "learner": clock.learner_s,
            "evaluation": clock.eval_s,
        },
        "checks": checks,
        "recipe_args": asdict(args),
        "machine": machine(torch.__version__, gpu),
    }


def cpu_model(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The processor's model name (Linux's ``/proc/cpuinfo``), else Python's best guess.

    ``platform.processor()`` says ``x86_64`` on Linux, which tells two machines apart no
    better than nothing: speed figures are only comparable on the same model.
    """
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def gpu_name(device: str) -> str | None:
    """The name of the GPU ``device`` (a recipe's ``--device``), None for the CPU."""
    if device == "cpu":
        return None
    import torch

    return torch.cuda.get_device_name(torch.device(device))


def machine(torch_version: str, gpu: str | None = None) -> dict[str, Any]:
    """Where a record was measured: the cores, the processor and the versions that set speed.

    ``gpu``: the name of the GPU the learner ran on (``--device cuda``); None on the CPU.
    """
    try:
        from numba import __version__ as numba_version
    except ImportError:  # numba is optional (the numpy references run)
        numba_version = None
    return {
        "cpus": os.cpu_count(),
        "affinity": len(os.sched_getaffinity(0)),
        "processor": platform.processor() or platform.machine(),
        "cpu_model": cpu_model(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba_version,
        "torch": torch_version,
        "gpu": gpu,
    }


def seeds_driver() -> Any:
    """``train/seeds.py``, the three-seed driver (its held-out stage, its argument split)."""
    if str(ROOT / "train") not in sys.path:
        sys.path.insert(0, str(ROOT / "train"))
    import seeds

    return seeds


#: The held-out figures recorded, with their intervals.
HELD_OUT_KEYS = ("episode.collision", "episode.loss_of_separation", "episode.max_deviation")


def held_out(record: dict[str, Any], episodes: int, workers: int = 1) -> dict[str, Any]:
    """The policy a record reached, the APF and the shipped checkpoint on the held-out bank.

    Args:
        record: A time-to-policy record that reached its bar; its run folder
            (``recipe_args["out_dir"]``) still holds the policy (``check.zip``).
        episodes: Held-out encounters (the bank's first).
        workers: Evaluation processes (the figures do not depend on them).

    Returns:
        ``{"episodes", "env_version", "policy_sha256", "figures": {label: {key: {value,
        ci_low, ci_high}}}}`` for the labels ``apf``, ``shipped`` and ``reached``.

    Raises:
        ValueError: The record did not reach its bar, or its policy file is gone.
    """
    import hashlib

    if not record.get("reached"):
        raise ValueError("the record did not reach its bar: no policy to play")
    policy = Path(record["recipe_args"]["out_dir"]) / "check.zip"
    if not policy.is_file():
        raise ValueError(f"{policy} is gone: the run folder no longer holds the policy")
    # train/seeds.py's own held-out stage (its config and encounters), so that the figures
    # compare with the published seeds reports.
    res = seeds_driver().held_out([ROOT / record["shipped"], policy], episodes, workers)
    figs = {}
    for label, theirs in (("apf", "apf"), ("shipped", "seed_0"), ("reached", "seed_1")):
        agg = res.results[theirs].aggregate
        figs[label] = {
            key.removeprefix("episode."): {
                "value": float(agg[key]["rate" if agg[key]["kind"] == "rate" else "mean"]),
                "ci_low": float(agg[key]["ci_low"]),
                "ci_high": float(agg[key]["ci_high"]),
            }
            for key in HELD_OUT_KEYS
        }
    from uasep_env.policies.env_version import current_version

    return {
        "episodes": episodes,
        # The env the bank was played in (records without it: -v2's, before -v3).
        "env_version": current_version(),
        "policy_sha256": hashlib.sha256(policy.read_bytes()).hexdigest(),
        "figures": figs,
    }


def _is_record(record: Any) -> bool:
    """Whether ``record`` has what :func:`held_out` reads (a record :func:`run` wrote)."""
    return (
        isinstance(record, dict)
        and record.get("recipe") in RECIPES
        and isinstance(record.get("shipped"), str)
        and isinstance(record.get("reached"), bool)
        and isinstance(record.get("recipe_args"), dict)
        and isinstance(record["recipe_args"].get("out_dir"), str)
    )


def _print_held_out(h: dict[str, Any]) -> None:
    print(f"held-out bank, first {h['episodes']} encounters:")
    for label, f in h["figures"].items():
        c, los, dev = f["collision"], f["loss_of_separation"], f["max_deviation"]
        print(f"  {label:8s} collisions {c['value']:.1%} [{c['ci_low']:.1%}, {c['ci_high']:.1%}]"
              f", loss of separation {los['value']:.1%} [{los['ci_low']:.1%}, "
              f"{los['ci_high']:.1%}], max deviation {dev['value']:.1f} m "
              f"[{dev['ci_low']:.1f}, {dev['ci_high']:.1f}]")  # fmt: skip


def first_to_reach(runs: list[dict[str, Any]]) -> int | None:
    """The index of the run side by side whose bar-clearing check came first (wall clock).

    Several can clear it at about the same time (each sees the others' stop file only at
    its next step): the earliest check wins. None when no run reached the bar.
    """
    hits = [(run["checks"][-1]["unix_time"], k) for k, run in enumerate(runs) if run["reached"]]
    return min(hits)[1] if hits else None


def merge_runs(runs: list[dict[str, Any]], seeds: list[int], wall_s: float) -> dict[str, Any]:
    """The record of training seeds side by side (``--seeds``) from each run's own record.

    Args:
        runs: Each seed's record (:func:`run`), in the order of ``seeds``.
        seeds: Their training seeds (the recipe's ``--seed``).
        wall_s: Wall seconds from their start to the last one's end (the bars' and the
            checks' evaluations included).

    Returns:
        A record with the fields of a single run's (``recipe``, ``bar``, ``reached``,
        ``training_minutes``, ``agent_steps``, ``recipe_args``: those of the run that cleared
        the bar first, else of the first seed's with the longest training) and
        ``side_by_side``: the seeds, which one reached (``reached_by``, its seed), the
        agent-steps of all the runs together when they stopped, the wall minutes and every
        run's record (``runs``).
    """
    k = first_to_reach(runs)
    lead = runs[k] if k is not None else max(runs, key=lambda r: r["training_minutes"])
    record = {key: value for key, value in lead.items() if key != "command"}
    record["side_by_side"] = {
        "seeds": list(seeds),
        "reached_by": seeds[k] if k is not None else None,
        # A run that reached stopped at that check: its agent-steps are the check's.
        "agent_steps_all": int(sum(r["agent_steps"] for r in runs)),
        "wall_minutes": wall_s / 60.0,
        "runs": runs,
    }
    return record


def _relay(prefix: str, stream: Any) -> None:
    """Print a child's output lines as they come, each after ``prefix``."""
    for line in stream:
        print(f"{prefix}{line}", end="", flush=True)


def side_by_side(a: argparse.Namespace, run_dir: Path, extra: list[str]) -> dict[str, Any]:
    """Train ``a.seeds`` training seeds at once, each in its own process; their record.

    Each process is this script alone (``--seed 1000 k`` after ``--``, its own ``seed_k``
    folder and record under ``run_dir``), with ``UASEP_WORKERS`` set so that they share
    the cores (:mod:`uasep_env.runtime.cores`); the first whose check clears the bar creates the
    stop file (``<run folder>/stop``) and the others stop at their next step.

    Raises:
        ValueError: The run folder holds files and ``a.overwrite`` is off.
        RuntimeError: A run's process failed (its output was printed).
    """
    import subprocess
    import threading

    driver = seeds_driver()
    seeds = [driver.SEED_STRIDE * k for k in range(a.seeds)]
    folders = [driver.seed_dir(run_dir, k) for k in range(a.seeds)]
    stop = run_dir / "stop"
    if run_dir.exists() and any(run_dir.iterdir()) and not a.overwrite:
        raise ValueError(f"{run_dir} is not empty (--overwrite replaces its runs)")
    run_dir.mkdir(parents=True, exist_ok=True)
    stop.unlink(missing_ok=True)
    own = ["--recipe", a.recipe, "--trainer", a.trainer, "--episodes", str(a.episodes),
           "--check-every", str(a.check_every), "--max-minutes", repr(a.max_minutes)]  # fmt: skip
    env = {**os.environ, "UASEP_WORKERS": str(a.seeds)}
    procs, relays = [], []
    t0 = time.perf_counter()
    for k, (seed, folder) in enumerate(zip(seeds, folders, strict=True)):
        out = run_dir / f"seed_{k}.json"
        out.unlink(missing_ok=True)  # under --overwrite: a stale record is not this run's
        cmd = [sys.executable, str(Path(__file__).resolve()), *own, "--run-dir", str(folder),
               "--out", str(out), "--stop-file", str(stop),
               *(["--overwrite"] if a.overwrite else []),
               "--", *extra, "--seed", str(seed)]  # fmt: skip
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, bufsize=1)  # fmt: skip
        relay = threading.Thread(target=_relay, args=(f"[seed {seed}] ", proc.stdout))
        relay.start()
        procs.append(proc)
        relays.append(relay)
    codes = [proc.wait() for proc in procs]
    for relay in relays:
        relay.join()
    wall_s = time.perf_counter() - t0
    failed = [seed for seed, code in zip(seeds, codes, strict=True) if code != 0]
    if failed:
        raise RuntimeError(f"the run(s) of training seed(s) {failed} failed (their output above)")
    runs = [json.loads((run_dir / f"seed_{k}.json").read_text()) for k in range(a.seeds)]
    return merge_runs(runs, seeds, wall_s)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Parse, run, print the summary and write the record."""
    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.training.args import non_negative_float, positive_int

    argv, extra = seeds_driver().split_recipe_args(argv)
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--recipe", choices=sorted(RECIPES))
    p.add_argument("--episodes", type=positive_int, default=100, help="validation encounters")
    p.add_argument("--check-every", type=positive_int, default=2_000_000, help="agent-steps")
    p.add_argument("--max-minutes", type=non_negative_float, default=60.0,
                   help="training time budget (evaluations excluded)")  # fmt: skip
    p.add_argument("--run-dir", type=Path, default=None)
    p.add_argument("--out", type=Path, default=None, help="the JSON record")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a previous run's files in --run-dir")  # fmt: skip
    p.add_argument("--held-out", type=positive_int, default=None, metavar="N",
                   help="then play the first N held-out encounters (see above)")  # fmt: skip
    p.add_argument("--of", type=Path, default=None, metavar="RECORD",
                   help="add --held-out figures to this earlier record (no training)")  # fmt: skip
    p.add_argument("--trainer", choices=("default", "lean"), default="default",
                   help="lean: the recipe on uasep_env.training.ppo_lean")  # fmt: skip
    p.add_argument("--workers", type=positive_int, default=1,
                   help="held-out evaluation processes")  # fmt: skip
    p.add_argument("--seeds", type=positive_int, default=None, metavar="N",
                   help="train seeds 0, 1000, ... side by side (see above)")  # fmt: skip
    p.add_argument("--stop-file", type=Path, default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.of is not None:
        if a.held_out is None or a.recipe or extra or a.seeds is not None:
            p.error("argument --of: takes --held-out N (and --workers) only")
        try:
            record = json.loads(a.of.read_text())
        except (OSError, ValueError) as err:  # missing, unreadable, not JSON
            p.error(f"argument --of: cannot read {a.of} ({err})")
        if not _is_record(record):
            p.error(f"argument --of: {a.of} is not a time-to-policy record")
        try:
            record["held_out"] = held_out(record, a.held_out, a.workers)
        except ValueError as err:
            p.error(f"argument --of: {err}")
        _print_held_out(record["held_out"])
        atomic_write(a.of, json.dumps(record, indent=2) + "\n")
        return record
    if a.recipe is None:
        p.error("the following arguments are required: --recipe")
    try:
        _loop(a.recipe, _resolved(a.recipe, ROOT, extra, a.trainer)[1])
    except ValueError as err:
        p.error(f"argument --trainer: {err}")
    out = a.out or ROOT / "benchmarks" / "results" / f"time_to_policy_{a.recipe}.json"
    if out.exists() and not a.force:
        p.error(f"argument --out: {out} exists (--force replaces it)")
    # Absolute: a later --of finds the policy from any folder.
    default = a.recipe if a.seeds is None else f"{a.recipe}_seeds"
    run_dir = (a.run_dir or ROOT / "runs" / "time_to_policy" / default).resolve()
    if a.seeds is not None:
        if a.stop_file is not None:
            p.error("argument --stop-file: not with --seeds (each run side by side gets one)")
        given = [f for f in extra if f.split("=", 1)[0] == "--seed"]
        if given:
            p.error(f"argument --seeds: sets each run's --seed itself, got {given[0]} after --")
        if a.seeds > seeds_driver().MAX_SEEDS:
            p.error(f"argument --seeds: at most {seeds_driver().MAX_SEEDS} "
                    "(seed k trains on 1000*k + e)")  # fmt: skip
        try:
            record = side_by_side(a, run_dir, extra)
        except ValueError as err:
            p.error(f"argument --run-dir: {err}")
    else:
        record = run(a.recipe, a.episodes, a.check_every, a.max_minutes, run_dir, extra,
                     a.overwrite, a.trainer, a.stop_file)  # fmt: skip
    record["command"] = seeds_driver().command_line("benchmarks/time_to_policy.py", argv, extra)
    t = record["time_s"]
    share = {k: t[k] / t["training"] if t["training"] else 0.0
             for k in ("env", "rollout_other", "learner")}  # fmt: skip
    print(f"{a.recipe}: {'reached' if record['reached'] else 'NOT reached'} in "
          f"{record['training_minutes']:.1f} training minutes, {record['agent_steps']:,} "
          f"agent-steps; time: env {share['env']:.0%}, rest of the rollout "
          f"{share['rollout_other']:.0%}, learner {share['learner']:.0%} (evaluation "
          f"{t['evaluation'] / 60:.1f} min apart)")  # fmt: skip
    if "side_by_side" in record:
        sbs = record["side_by_side"]
        by = "none" if sbs["reached_by"] is None else f"training seed {sbs['reached_by']}"
        print(f"side by side, training seeds {sbs['seeds']}: reached by {by}; "
              f"{sbs['agent_steps_all']:,} agent-steps in all; {sbs['wall_minutes']:.1f} wall "
              "minutes (bars and checks included)")  # fmt: skip
    if a.held_out is not None and record["reached"]:
        record["held_out"] = held_out(record, a.held_out, a.workers)
        _print_held_out(record["held_out"])
    elif a.held_out is not None:
        print("--held-out: the bar was not reached, so there is no policy to play", flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, json.dumps(record, indent=2) + "\n")
    return record


if __name__ == "__main__":
    main()
