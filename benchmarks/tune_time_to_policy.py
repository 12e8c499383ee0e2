"""Tune a PPO recipe's flags for time to a policy: an Optuna study of time_to_policy's runs.

Usage::

    python benchmarks/tune_time_to_policy.py --recipe residual_apf --trials 10 --max-minutes 5
        --study-dir runs/tune/residual_apf [--episodes 400] [--check-every 4000000]
        [--seed 0] [--startup 4] [--trainer lean|default] [--no-stop-at-best]
        [--out FILE] [--force] [-- fixed recipe flags]

Each trial is one run of ``benchmarks/time_to_policy.py`` (its bar from the shipped checkpoint,
its checks every ``--check-every`` agent-steps on ``--episodes`` validation encounters, its
clock) with the flags Optuna's TPE sampler suggests from :data:`SPACE`. Its value is the
training minutes to the bar (evaluations excluded); a trial that does not reach the bar within
its budget gets ``2 x --max-minutes``, worse than any that did. The first trial is
:data:`BASELINE` (the fast flags ``docs/speed.md`` measures), so the study starts from what it
must beat; the next ``--startup - 1`` are drawn at random, the rest by TPE. With stop-at-best
(the default) a trial's budget is the best value so far: a trial that has trained as long as
the best without reaching the bar cannot beat it.

The study lives in ``--study-dir``: Optuna's journal (``journal.log``, JSON lines, no
pickle), each trial's time-to-policy record (``trial_NNN.json``) and run folder
(``trial_NNN/``). The same command again resumes it: finished trials are kept, a trial that a
killed or interrupted process left unfinished is tried again first (its flags, as a new
trial), and trials run until ``--trials`` have finished. A folder holding a study of other
settings is refused, and so is one that another live process is running.
The summary (``--out``, JSON written atomically; an existing file is kept unless ``--force``)
holds the budget, the search space, the sampler, the machine, every trial and the best.
Timing: run it alone on the machine (each trial's minutes are wall time). Needs the ``train``
and ``tune`` extras.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parent))

import time_to_policy as ttp

ROOT = ttp.ROOT


class Param(NamedTuple):
    """One searched flag.

    Attributes:
        kind: ``"categorical"`` (one of ``values``), ``"int"`` or ``"log_float"`` (in
            ``[values[0], values[1]]``, log-uniform for the float).
    """

    kind: str
    values: tuple


#: The searched flags: the recipe flags that set an update's size and step (the levers of
#: ``docs/speed.md``). ``n_minibatches`` sets ``--batch-size`` to the rollout
#: (``n_envs x n_steps x n_uavs`` samples) divided by it, rounded up.
SPACE: dict[str, Param] = {
    "n_envs": Param("categorical", (64, 128, 256)),
    "n_steps": Param("categorical", (32, 64, 128)),
    "n_minibatches": Param("categorical", (1, 2, 3, 4, 6)),
    "n_epochs": Param("int", (1, 4)),
    "learning_rate": Param("log_float", (5e-5, 1e-3)),
}
#: The first trial: the fast flags (``--n-envs 128 --n-steps 64 --batch-size 8192 --n-epochs 2
#: --learning-rate 2.5e-4`` at 3 UAVs).
BASELINE: dict[str, Any] = {
    "n_envs": 128,
    "n_steps": 64,
    "n_minibatches": 3,
    "n_epochs": 2,
    "learning_rate": 2.5e-4,
}
#: The recipe flags a trial sets (not to be given after ``--``).
TUNED_FLAGS = ("--n-envs", "--n-steps", "--batch-size", "--n-epochs", "--learning-rate")


def suggest(trial: Any) -> dict[str, Any]:
    """One value per :data:`SPACE` entry, from an Optuna trial."""
    params = {}
    for name, p in SPACE.items():
        if p.kind == "categorical":
            params[name] = trial.suggest_categorical(name, list(p.values))
        elif p.kind == "int":
            params[name] = trial.suggest_int(name, *p.values)
        else:
            params[name] = trial.suggest_float(name, *p.values, log=True)
    return params


def to_flags(params: dict[str, Any], n_uavs: int) -> list[str]:
    """The recipe flags of a trial's parameters (``n_uavs``: the agents of an environment)."""
    rollout = params["n_envs"] * params["n_steps"] * n_uavs
    batch = math.ceil(rollout / params["n_minibatches"])
    return [
        "--n-envs", str(params["n_envs"]),
        "--n-steps", str(params["n_steps"]),
        "--batch-size", str(batch),
        "--n-epochs", str(params["n_epochs"]),
        "--learning-rate", repr(float(params["learning_rate"])),
    ]  # fmt: skip


def tuned_in(fixed: list[str]) -> list[str]:
    """The flags of ``fixed`` that a trial sets itself (``--flag`` or ``--flag=value``)."""
    return [f for f in fixed if f.split("=", 1)[0] in TUNED_FLAGS]


def value_of(record: dict[str, Any], max_minutes: float) -> float:
    """A trial's value: training minutes to the bar, or ``2 x max_minutes`` if not reached."""
    return float(record["training_minutes"]) if record["reached"] else 2.0 * max_minutes


def settings_of(a: argparse.Namespace, fixed: list[str]) -> dict[str, Any]:
    """What makes two studies comparable (kept in the study; a resume must match it)."""
    return {
        "recipe": a.recipe,
        "trainer": a.trainer,
        "episodes": a.episodes,
        "check_every": a.check_every,
        "max_minutes": a.max_minutes,
        "seed": a.seed,
        "startup": a.startup,
        "stop_at_best": a.stop_at_best,
        "fixed": list(fixed),
        "space": {k: [p.kind, list(p.values)] for k, p in SPACE.items()},
        "baseline": dict(BASELINE),
    }


def open_study(study_dir: Path, settings: dict[str, Any]) -> Any:
    """Create the study in ``study_dir``, or load it (its settings must be ``settings``).

    Trials that a killed process left running are marked failed, and their parameters queued
    again as those of trials interrupted (``KeyboardInterrupt``) are, once each; a new study
    queues :data:`BASELINE` first. The caller holds the folder (one process a study).

    Raises:
        ValueError: The folder's study was made with other settings.
    """
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend
    from optuna.trial import TrialState

    study_dir.mkdir(parents=True, exist_ok=True)
    storage = JournalStorage(JournalFileBackend(str(study_dir / "journal.log")))
    sampler = optuna.samplers.TPESampler(seed=settings["seed"],
                                         n_startup_trials=settings["startup"])  # fmt: skip
    name = f"time_to_policy_{settings['recipe']}"
    study = optuna.create_study(study_name=name, storage=storage, direction="minimize",
                                sampler=sampler, load_if_exists=True)  # fmt: skip
    kept = study.user_attrs.get("settings")
    if kept is None:
        study.set_user_attr("settings", settings)
        study.enqueue_trial(dict(BASELINE))
    elif kept != settings:
        diff = sorted(k for k in settings if kept.get(k) != settings[k])
        raise ValueError(f"{study_dir} holds a study made with other settings ({', '.join(diff)})")
    requeued = set(study.user_attrs.get("requeued", []))
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING, TrialState.FAIL)):
        if t.number in requeued:
            continue
        if t.state == TrialState.RUNNING:  # its process is gone (the folder's lock says so)
            study.tell(t.number, state=TrialState.FAIL)
        elif not t.user_attrs.get("interrupted"):
            continue  # it failed on an error: not tried again
        study.enqueue_trial(dict(t.params), skip_if_exists=False)
        requeued.add(t.number)
    study.set_user_attr("requeued", sorted(requeued))
    return study


def objective_for(study_dir: Path, a: argparse.Namespace, fixed: list[str], n_uavs: int) -> Any:
    """The objective of a study: one time-to-policy run per trial (see the module)."""
    from uasep_env.runtime.atomic import atomic_write

    def objective(trial: Any) -> float:
        params = suggest(trial)
        flags = to_flags(params, n_uavs)
        budget = a.max_minutes
        done = [v for v in _values(trial.study) if v < 2.0 * a.max_minutes]
        if a.stop_at_best and done:
            budget = min(budget, min(done))
        tag = f"trial_{trial.number:03d}"
        try:
            record = ttp.run(a.recipe, a.episodes, a.check_every, budget, study_dir / tag,
                             [*fixed, *flags], trainer=a.trainer)  # fmt: skip
        except KeyboardInterrupt:
            trial.set_user_attr("interrupted", True)  # Optuna fails it; a resume retries it
            raise
        record["tuning"] = {"trial": trial.number, "params": params, "budget_minutes": budget}
        atomic_write(study_dir / f"{tag}.json", json.dumps(record, indent=2) + "\n")
        kept = {"flags": flags, "budget_minutes": budget, "checks": len(record["checks"])}
        for key in ("reached", "training_minutes", "agent_steps", "time_s"):
            kept[key] = record[key]
        for key, val in kept.items():
            trial.set_user_attr(key, val)
        value = value_of(record, a.max_minutes)
        print(f"trial {trial.number}: {' '.join(flags)} -> "
              f"{'reached' if record['reached'] else 'not reached'} "
              f"({record['training_minutes']:.2f} training min, budget {budget:.2f}); "
              f"value {value:.2f}", flush=True)  # fmt: skip
        return value

    return objective


def _values(study: Any) -> list[float]:
    """The values of the study's finished trials."""
    from optuna.trial import TrialState

    return [t.value for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))]


def summary(study: Any) -> dict[str, Any]:
    """Every trial of ``study`` and the best (the one of lowest value that reached the bar)."""
    import optuna

    trials = []
    for t in study.get_trials(deepcopy=False):
        took = (t.datetime_complete - t.datetime_start).total_seconds() if (
            t.datetime_complete and t.datetime_start) else None  # fmt: skip
        trials.append({"number": t.number, "state": t.state.name, "value": t.value,
                       "params": dict(t.params), "wall_s": took,
                       **dict(t.user_attrs)})  # fmt: skip
    reached = [t for t in trials if t["state"] == "COMPLETE" and t.get("reached")]
    best = min(reached, key=lambda t: (t["value"], t["number"])) if reached else None
    return {
        "settings": study.user_attrs["settings"],
        "sampler": type(study.sampler).__name__,
        "optuna": optuna.__version__,
        "trials": trials,
        "best": best,
        "study_minutes": sum(t["wall_s"] or 0.0 for t in trials) / 60.0,
    }


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Parse, run (or resume) the study, print its trials and write the summary."""
    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.training.args import non_negative_int, positive_float, positive_int

    argv, fixed = ttp.seeds_driver().split_recipe_args(argv)
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--recipe", choices=sorted(ttp.RECIPES), required=True)
    p.add_argument("--trials", type=positive_int, required=True, help="finished trials wanted")
    p.add_argument("--max-minutes", type=positive_float, required=True,
                   help="a trial's training-time budget (evaluations excluded)")  # fmt: skip
    p.add_argument("--study-dir", type=Path, required=True)
    p.add_argument("--episodes", type=positive_int, default=400, help="validation encounters")
    p.add_argument("--check-every", type=positive_int, default=4_000_000, help="agent-steps")
    p.add_argument("--seed", type=non_negative_int, default=0, help="the sampler's seed")
    p.add_argument("--startup", type=positive_int, default=4,
                   help="trials before TPE (the baseline, then random draws)")  # fmt: skip
    p.add_argument("--trainer", choices=("default", "lean"), default="lean")
    p.add_argument("--no-stop-at-best", dest="stop_at_best", action="store_false",
                   help="give every trial the whole --max-minutes")  # fmt: skip
    p.add_argument("--out", type=Path, default=None, help="the JSON summary")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    a = p.parse_args(argv)
    try:
        ttp._loop(a.recipe, a.trainer)
    except ValueError as err:
        p.error(f"argument --trainer: {err}")
    if ttp.RECIPES[a.recipe].reader != ttp._PPO:
        p.error(f"argument --recipe: {a.recipe!r} is not a PPO recipe (the space is PPO's flags)")
    if clash := tuned_in(fixed):
        p.error(f"fixed flags {clash}: a trial sets these itself ({', '.join(TUNED_FLAGS)})")
    out = a.out or ROOT / "benchmarks" / "results" / f"tune_{a.recipe}_{a.trainer}.json"
    if out.exists() and not a.force:
        p.error(f"argument --out: {out} exists (--force replaces it)")
    study_dir = a.study_dir.resolve()
    recipe_args = ttp._recipe_args(a.recipe, study_dir, fixed)  # the fixed flags checked
    n_uavs = recipe_args.n_uavs
    import optuna

    from uasep_env.runtime.runlock import RunFolderBusy, claim_run_folder

    optuna.logging.set_verbosity(optuna.logging.WARNING)  # each trial prints its own line
    try:
        claim_run_folder(study_dir)  # one process a study: its running trials are its own
        study = open_study(study_dir, settings_of(a, fixed))
    except (ValueError, RunFolderBusy) as err:
        p.error(f"argument --study-dir: {err}")
    t0 = time.perf_counter()
    left = a.trials - len(_values(study))
    if left > 0:
        study.optimize(objective_for(study_dir, a, fixed, n_uavs), n_trials=left)
    result = summary(study)
    result["command"] = ttp.seeds_driver().command_line(
        "benchmarks/tune_time_to_policy.py", argv, fixed
    )
    import torch

    result["machine"] = ttp.machine(torch.__version__, ttp.gpu_name(recipe_args.device))
    result["this_call_minutes"] = (time.perf_counter() - t0) / 60.0
    for t in result["trials"]:
        mark = "reached" if t.get("reached") else "-"
        val = "" if t["value"] is None else f"{t['value']:6.2f}"
        print(f"{t['number']:3d} {t['state']:8s} {val:>6s} {mark:8s} {t['params']}")
    if result["best"]:
        b = result["best"]
        print(f"best: trial {b['number']}, {b['training_minutes']:.2f} training minutes, "
              f"{b['agent_steps']:,} agent-steps: {' '.join(b['flags'])}")  # fmt: skip
    else:
        print("best: no trial reached the bar")
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, json.dumps(result, indent=2) + "\n")
    return result


if __name__ == "__main__":
    main()
