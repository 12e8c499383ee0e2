"""The training recipes' flags: one dataclass, one validated argument parser.

Every recipe (:mod:`~uasep_env.training.ppo_shared`, :mod:`~uasep_env.training.ppo_residual_apf`,
:mod:`~uasep_env.training.mappo`) reads its options from :class:`Args` (one ``--kebab-case``
flag per field) through :func:`parse_args`; the drivers of ``train/`` (``seeds.py``,
``reproduce.py``, ``compare_recipes.py``) use the same validators for the flags they share.
A bad value is refused before anything runs with one line that names the flag
(``uasep-train: error: argument --checkpoint-every: must be an integer >= 1, got '-5'``),
never a traceback, and ``--help`` lists every flag with its default.

This module imports neither torch nor stable-baselines3.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from uasep_env.config.groups import ACTION_MODES

__all__ = [
    "FIELDS",
    "PER_RUN",
    "Args",
    "HelpFormatter",
    "OneLineParser",
    "budget_notice",
    "build_parser",
    "choice",
    "device_problem",
    "finite_float",
    "hidden_sizes",
    "network_problem",
    "non_negative_float",
    "non_negative_int",
    "out_path",
    "parse_args",
    "plain_text",
    "positive_float",
    "positive_int",
    "rollout_steps",
    "rounded_budget",
    "threads_problem",
    "to_argv",
    "torch_device",
    "trial_run",
    "unit_interval",
]


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (not the whole usage)."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` and a pointer to ``--help``; exit with status 2."""
        message = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


#: A Sphinx cross-reference: ``:role:`target```, ``:role:`~a.b.name``` or ``:role:`text <target>```.
_ROLE = re.compile(r":(?:py:)?[a-z]+:`(~?)([^`<]*?)\s*(?:<([^`>]+)>)?`")


def _role_text(match: re.Match) -> str:
    short, text, target = match.groups()
    if target is not None:  # :role:`text <target>`: the text
        return text
    return text.rsplit(".", 1)[-1] if short else text  # ~: the last name, as Sphinx shows it


def plain_text(text: str) -> str:
    """``text`` (a docstring in reStructuredText) as a person reads it on a terminal.

    Cross-references become their target as Sphinx shows it (``:class:`~a.B``` -> ``B``,
    ``:mod:`a.b``` -> ``a.b``), inline literals and strong emphasis lose their markup, and a
    paragraph's literal-block marker ``::`` becomes ``:``. Indentation and line breaks stay.
    """
    text = _ROLE.sub(_role_text, text)
    text = re.sub(r"``(.+?)``", r"\1", text, flags=re.S)
    text = re.sub(r"\*\*(.+?)\*\*", r"\1", text, flags=re.S)
    text = re.sub(r"\s*::$", ":", text, flags=re.M)
    return text


def _refill(text: str, width: int) -> str:
    """``text``'s paragraphs and bullets re-wrapped to ``width``; examples as they are.

    The markup :func:`plain_text` drops leaves the docstring's lines ragged.
    """
    blocks = []
    for block in text.split("\n\n"):
        lines = block.splitlines()
        indented = any(line[:1].isspace() for line in lines)
        if not lines or (indented and not lines[0].startswith("* ")):  # an example: as written
            blocks.append(block)
            continue
        items: list[list[str]] = []  # a paragraph, or one list item each
        for line in lines:
            if line.startswith("* ") or not items:
                items.append([line])
            elif line[:1].isspace() or not items[-1][0].startswith("* "):
                items[-1].append(line.strip())
            else:
                items.append([line])
        blocks.append(
            "\n".join(
                textwrap.fill(
                    " ".join(item),
                    width,
                    subsequent_indent="  " if item[0][:2] == "* " else "",
                    break_long_words=False,
                    break_on_hyphens=False,  # a flag stays whole
                )
                for item in items
            )
        )
    return "\n\n".join(blocks)


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """``--help`` with every flag's default, the description's lines as written, in plain text.

    The recipes' descriptions are their module docstrings (reStructuredText): the markup is
    for the API pages, so the terminal gets :func:`plain_text`.
    """

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return super()._fill_text(_refill(plain_text(text), width), width, indent)

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = super()._get_help_string(action)
        return None if text is None else plain_text(text)


def _number(kind: type, text: str) -> Any:
    try:
        value = kind(text)
    except (TypeError, ValueError):
        noun = "an integer" if kind is int else "a number"
        raise argparse.ArgumentTypeError(f"expected {noun}, got {text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _bounded(kind: type, low: float, high: float | None = None, strict: bool = False) -> Any:
    """An argparse type: ``kind`` from text, finite, ``>= low`` (``> low``: strict), ``<= high``."""
    noun = "an integer" if kind is int else "a number"
    bound = f"> {low:g}" if strict else f">= {low:g}"
    if high is not None:
        bound = f"in {'(' if strict else '['}{low:g}, {high:g}]"

    def parse(text: str) -> Any:
        value = _number(kind, text)
        if (value <= low if strict else value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {noun} {bound}, got {text!r}")
        return value

    parse.__name__ = f"{kind.__name__} {bound}"  # argparse names the type in some errors
    return parse


positive_int = _bounded(int, 1)
non_negative_int = _bounded(int, 0)
positive_float = _bounded(float, 0.0, strict=True)
non_negative_float = _bounded(float, 0.0)
unit_interval = _bounded(float, 0.0, 1.0)


def _int(text: str) -> int:
    return int(_number(int, text))


def finite_float(text: str) -> float:
    """An argparse type: any finite number."""
    return float(_number(float, text))


def choice(*names: str) -> Callable[[str], str]:
    """An argparse type: one of ``names`` (the error lists them)."""

    def parse(text: str) -> str:
        if text not in names:
            raise argparse.ArgumentTypeError(f"must be one of {', '.join(names)}, got {text!r}")
        return text

    return parse


def hidden_sizes(text: str) -> str:
    """An argparse type: comma-separated layer widths, each >= 1 (``"128,128"``)."""
    try:
        sizes = [int(h) for h in text.split(",") if h.strip()]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"comma-separated layer widths >= 1, got {text!r}")
    return text


def formation_sizes_option(text: str) -> str:
    """An argparse type: comma-separated formation sizes, each 2-64 (``"3,4,5,6,7,8"``), or ""."""
    if not text.strip():
        return ""
    try:
        sizes = [int(n) for n in text.split(",")]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 2 or max(sizes) > 64:
        raise argparse.ArgumentTypeError(
            f"comma-separated formation sizes, each 2-64 (3,4,5,6,7,8), got {text!r}"
        )
    return ",".join(str(n) for n in sizes)


def torch_device(text: str) -> str:
    """An argparse type: a torch device name, ``cpu``, ``cuda`` or ``cuda:N`` (not checked here).

    Whether torch sees that device is :func:`device_problem`'s question, asked once the
    options are parsed (it imports torch).
    """
    kind, _, index = text.partition(":")
    if text in ("cpu", "cuda") or (kind == "cuda" and index.isdigit()):
        return text
    raise argparse.ArgumentTypeError(f"must be cpu, cuda or cuda:N, got {text!r}")


def device_problem(name: str) -> str | None:
    """Why torch cannot compute on the device ``name`` here (a message), or None when it can."""
    if name == "cpu":
        return None
    try:
        import torch
    except ImportError:
        return f"{name}: torch is not installed (the train extra)"
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    _, _, index = name.partition(":")
    if count == 0:
        return f"{name}: torch {torch.__version__} sees no CUDA device here"
    if index and int(index) >= count:
        return f"{name}: torch sees {count} CUDA device(s) here (cuda:0 to cuda:{count - 1})"
    return None


def out_path(text: str) -> str:
    """An argparse type: a folder to write to (not empty, not an existing file)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a folder path, got ''")
    if Path(text).exists() and not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} exists and is not a folder")
    return text


def config_overrides(text: str) -> str:
    """An argparse type: space-separated ``KEY=VALUE`` env overrides (checked for syntax)."""
    from uasep_env.evaluation.overrides import parse_config_overrides

    try:
        parse_config_overrides(text.split())
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return text


@dataclass
class Args:
    """Command-line options (``--total-timesteps``, ``--n-envs``, ...)."""

    action_mode: str = "direct"  # "direct" (pure policy) or a residual mode (ACTION_MODES)
    residual_scale: float = 0.5  # residual_apf: largest correction, fraction of max_accel
    scenario: str = "random"
    n_uavs: int = 3
    n_obstacles: int = 1
    # Fixed K (observation.k_uavs / k_obstacles): the observation's width does not depend on
    # n_uavs or n_obstacles, so the policy flies any formation size / obstacle count.
    # Formation sizes the lean loop's rollouts take in turn ("3,4,5,6,7,8"); "": n_uavs only.
    formation_sizes: str = ""
    k_uavs: int = 2  # nearest other UAVs observed (all of them at 3 UAVs)
    k_obstacles: int = 1  # nearest obstacles observed (by distance to its predicted region)
    episode_duration: float = 200.0  # s
    config: str = ""  # more env overrides, space-separated KEY=VALUE ("reward.collision=0.5")
    total_timesteps: int = 150_000_000  # agent-steps (the wall budget usually ends a run first)
    max_minutes: float = 55.0  # wall-clock budget; training stops when it is spent
    n_envs: int = 32
    n_steps: int = 256  # rollout length per sub-environment
    batch_size: int = 8192
    n_epochs: int = 5
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    target_kl: float = 0.0  # stop an update's epochs past this KL (0: no limit)
    critic_warmup: int = 0  # first PPO iterations that train the critic only
    log_std_init: float = -0.5
    hidden: str = "128,128"
    activation: str = "tanh"
    arch: str = "mlp"  # "mlp" (slot MLP) or "set" (permutation-invariant; the lean loop's)
    norm_obs: bool = True
    norm_reward: bool = False  # on, the rare -max_steps collisions swamp the scale
    seed: int = 0
    checkpoint_every: int = 2_000_000  # agent-steps
    eval_episodes: int = 50
    out_dir: str = "runs/ppo_shared"
    resume: str = ""  # a checkpoint directory to continue from (its progress, exactly)
    overwrite: bool = False  # replace a previous run's files in out_dir (else: refused)
    tensorboard: bool = False
    torch_threads: int = 1
    device: str = "cpu"  # where torch computes: SB3's whole policy, or the lean loop's update
    trainer: str = "default"  # "default" (SB3's PPO; skrl's MAPPO) or "lean" (ppo_lean)
    shield: str = "none"  # "cbf": train under the CBF shield (lean loop; shield_loop)
    progress: bool = True


def _scenario(text: str) -> str:
    from uasep_env.scenarios import scenario_names

    return choice(*scenario_names())(text)


#: Each field's validator (argparse ``type=``; None for an on/off flag) and help text.
FIELDS: dict[str, tuple[Callable[[str], Any] | None, str]] = {
    "action_mode": (
        choice(*ACTION_MODES),
        "direct (pure policy), or a residual on a base: " + ", ".join(ACTION_MODES[1:]),
    ),
    "residual_scale": (positive_float, "residual modes: largest correction, fraction of max_accel"),
    "scenario": (_scenario, "scenario family of the training encounters"),
    "n_uavs": (positive_int, "formation size"),
    "formation_sizes": (
        formation_sizes_option,
        "formation sizes the rollouts take in turn, comma-separated (3,4,5,6,7,8; --trainer "
        "lean only); validation and the exported policy's config keep --n-uavs",
    ),
    "n_obstacles": (non_negative_int, "obstacles per encounter"),
    "k_uavs": (positive_int, "nearest other UAVs observed (observation.k_uavs)"),
    "k_obstacles": (positive_int, "nearest obstacles observed (observation.k_obstacles)"),
    "episode_duration": (positive_float, "seconds per episode"),
    "config": (config_overrides, "more env overrides, space-separated KEY=VALUE"),
    "total_timesteps": (
        positive_int,
        "agent-steps to train, rounded up to whole rollouts of --n-envs x UAVs x --n-steps "
        "(the wall budget usually ends a run first)",
    ),
    "max_minutes": (positive_float, "wall-clock budget in minutes"),
    "n_envs": (positive_int, "batched environments"),
    "n_steps": (positive_int, "rollout length per sub-environment"),
    "batch_size": (positive_int, "minibatch size (agent-steps)"),
    "n_epochs": (positive_int, "epochs per update"),
    "learning_rate": (positive_float, "Adam step size"),
    "gamma": (unit_interval, "discount factor"),
    "gae_lambda": (unit_interval, "GAE lambda"),
    "clip_range": (positive_float, "PPO ratio clip"),
    "ent_coef": (non_negative_float, "entropy bonus weight"),
    "target_kl": (non_negative_float, "stop an update's epochs past this KL (0: no limit)"),
    "critic_warmup": (non_negative_int, "first PPO iterations that train the critic only"),
    "log_std_init": (finite_float, "initial log standard deviation of the actions"),
    "hidden": (hidden_sizes, "hidden layer widths, comma-separated"),
    "activation": (choice("tanh", "relu"), "hidden layers' activation"),
    "arch": (
        choice("mlp", "set"),
        "mlp (the K neighbour slots in order) or set (permutation-invariant over the "
        "neighbours, attention pooled; acts with any K; --trainer lean only)",
    ),
    "norm_obs": (None, "normalise observations (running mean and variance)"),
    "norm_reward": (None, "normalise returns"),
    "seed": (non_negative_int, "training seed (environments: seed + e)"),
    "checkpoint_every": (positive_int, "agent-steps between checkpoints"),
    "eval_episodes": (non_negative_int, "validation encounters at the end"),
    "out_dir": (out_path, "the run's folder"),
    # Checked when the run starts (rundir.check_checkpoint: one line, status 1, naming what
    # the folder lacks), as it always was.
    "resume": (str, "a checkpoint folder to continue from"),
    "overwrite": (None, "replace a previous run's files in --out-dir"),
    "tensorboard": (None, "also write TensorBoard logs (out_dir/tb)"),
    "torch_threads": (positive_int, "torch CPU threads"),
    "device": (torch_device, "torch device: cpu, cuda or cuda:N (SB3: all; lean loop: update)"),
    "trainer": (
        choice("default", "lean"),
        "default (SB3's PPO; skrl's MAPPO) or lean (uasep_env.training.ppo_lean)",
    ),
    "shield": (
        choice("none", "cbf"),
        "cbf: every action flies through the CBF filter while training (--trainer lean "
        "only; evaluated as <policy>+cbf)",
    ),
    "progress": (None, "progress bar on stderr"),
    # MAPPO's own (uasep_env.training.mappo.Args).
    "value_loss_scale": (non_negative_float, "weight of the critic's loss"),
    "grad_norm_clip": (non_negative_float, "gradient norm clip (0: none)"),
    "value_norm": (None, "the critic learns returns normalised by their running statistics"),
}


def trial_run(prog: str, more: str = "") -> str:
    """``--help``'s last words: the command of a short trial run of ``prog`` (``more`` flags)."""
    return (
        "A short trial run (a minute or two: checks the install and the flags, learns little):\n"
        f"  {prog} --total-timesteps 20000 --max-minutes 2 --eval-episodes 5{more} \\\n"
        "      --out-dir runs/trial --overwrite"
    )


def rollout_steps(args: Args, n_uavs: int) -> int:
    """Agent-steps of one rollout: every UAV of ``--n-envs`` environments, ``--n-steps`` each."""
    return args.n_envs * n_uavs * args.n_steps


def rounded_budget(args: Args, n_uavs: int, start: int = 0) -> int:
    """The agent-steps a run trains to: from ``start``, whole rollouts past ``--total-timesteps``.

    Every trainer (SB3's, skrl's, the lean loop) checks the budget between rollouts only;
    ``--max-minutes`` may end the run before.
    """
    per = rollout_steps(args, n_uavs)
    left = args.total_timesteps - start
    return start + -(-left // per) * per if left > 0 else start


def budget_notice(args: Args, n_uavs: int, start: int = 0) -> str | None:
    """The line a run prints at its start when its step budget is rounded up, or None."""
    if getattr(args, "formation_sizes", ""):
        return None  # rollouts of several sizes: the budget is passed by less than one
    end = rounded_budget(args, n_uavs, start)
    if start >= args.total_timesteps or end == args.total_timesteps:
        return None  # nothing left to train, or nothing rounded
    return (
        f"--total-timesteps {args.total_timesteps} rounded up to {end}: whole rollouts of "
        f"{rollout_steps(args, n_uavs)} agent-steps (--n-envs {args.n_envs} x {n_uavs} UAVs "
        f"x --n-steps {args.n_steps})"
    )


#: Fields of the env config: an invalid environment is reported against these flags.
_ENV_FLAGS = ("n_uavs", "n_obstacles", "k_uavs", "k_obstacles", "episode_duration",
              "residual_scale", "scenario")  # fmt: skip


def build_parser(
    defaults: Args | None = None, prog: str | None = None, description: str | None = None
) -> OneLineParser:
    """The parser of a recipe: one validated ``--kebab-case`` flag per field of ``defaults``.

    A field listed in :data:`FIELDS` gets its validator and help; a subclass's other fields
    take them from their metadata (``dataclasses.field(metadata={"type": validator,
    "help": text})``; ``"type": None`` for an on/off flag), else are parsed by their
    annotation (``int``, a finite ``float``, ``bool`` on/off, ``str``).

    Args:
        defaults: The recipe's defaults (an :class:`Args` or a subclass's instance).
        prog: The program name in messages (default: the script's).
        description: ``--help``'s text.

    Returns:
        The parser (its ``parse_args`` gives a namespace of the fields).
    """
    base = defaults or Args()
    parser = OneLineParser(
        prog=prog,
        description=description,
        # A Lagrangian recipe measures the APF's budget on 1,000 encounters first.
        epilog=trial_run(
            prog or "uasep-train RECIPE",
            " --budget-episodes 5" if hasattr(base, "budget_episodes") else "",
        ),
        formatter_class=HelpFormatter,
    )
    for f in dataclasses.fields(base):
        flag = "--" + f.name.replace("_", "-")
        default = getattr(base, f.name)
        # A recipe's own field without an entry in FIELDS is typed by its annotation.
        kind = getattr(f.type, "__name__", f.type)  # a type, or its name under PEP 563
        fallback = {"bool": None, "int": _int, "float": finite_float}.get(str(kind), str)
        validator, text = FIELDS.get(f.name) or (
            f.metadata.get("type", fallback),
            f.metadata.get("help", f.name.replace("_", " ")),
        )
        if validator is None:
            parser.add_argument(
                flag, action=argparse.BooleanOptionalAction, default=default, help=text
            )
        else:
            parser.add_argument(flag, type=validator, default=default, help=text)
    return parser


def parse_args(
    argv: list[str] | None = None,
    defaults: Args | None = None,
    prog: str | None = None,
    description: str | None = None,
    check: Callable[[Any], str | None] | None = None,
) -> Any:
    """Build the recipe's :class:`Args` from the command line, or exit with one line.

    Besides each flag's own range, the training seeds must lie in
    :data:`~uasep_env.scenarios.TRAINING_SEEDS` and the flags must give a valid environment.

    Args:
        argv: The arguments (default ``sys.argv[1:]``).
        defaults: The recipe's defaults; the result has their class.
        prog: The program name in messages.
        description: ``--help``'s text.
        check: The recipe's own check: an error message naming the flag, or None.

    Returns:
        The options.
    """
    from uasep_env.scenarios import check_training_seeds

    base = defaults or Args()
    parser = build_parser(base, prog, description)
    args = type(base)(**vars(parser.parse_args(argv)))
    try:
        check_training_seeds(args.seed, args.n_envs)
    except ValueError as err:
        parser.error(f"argument --seed: {err}")
    try:
        make_env_config(args)
    except (TypeError, ValueError) as err:
        names = [n for n in _ENV_FLAGS if n in str(err)] or ["config"]
        parser.error(f"argument --{names[0].replace('_', '-')}: {err}")
    problem = check(args) if check is not None else None
    if problem:
        parser.error(problem)
    problem = device_problem(args.device)
    if problem:
        parser.error(f"argument --device: {problem}")
    problem = network_problem(args)
    if problem:
        parser.error(f"argument --hidden: {args.hidden!r} {problem}; use narrower layers")
    problem = threads_problem()
    if problem:
        parser.error(problem)
    return args


def network_problem(args: Args) -> str | None:
    """Why the actor and critic of ``--hidden`` cannot be trained here (memory), or None.

    Checked before torch allocates them (a width of 10^9 would otherwise end in torch's
    allocation error, many lines long).
    """
    from uasep_env.interface.observation_layout import ObservationLayout
    from uasep_env.runtime.capacity import memory_problem, network_bytes

    n_in = ObservationLayout.from_config(make_env_config(args)).dim
    # The critic may read more than the observation (MAPPO's global state): a generous 4x.
    need = network_bytes(hidden(args), n_in, 3, args.batch_size)
    need += network_bytes(hidden(args), 4 * n_in, 1, args.batch_size)
    return memory_problem(need, "the actor and the critic, their gradients and Adam's state")


def formation_sizes(args: Args) -> list[int]:
    """The formation sizes a run trains with: ``--formation-sizes``, else ``[--n-uavs]``."""
    text = getattr(args, "formation_sizes", "")
    return [int(n) for n in text.split(",")] if text else [args.n_uavs]


def sizes_problem(args: Args, recipe: str | None = None) -> str | None:
    """Why ``--formation-sizes`` cannot train with these flags (one line naming it), or None.

    ``recipe``: a recipe that trains with one formation size a run (its name, said in the
    message), or None for the PPO recipes.
    """
    if not getattr(args, "formation_sizes", ""):
        return None
    flag = f"argument --formation-sizes: {args.formation_sizes!r}"
    if recipe is not None:
        return f"{flag} is not for {recipe} (one formation size a run)"
    if args.trainer != "lean":
        return f"{flag} trains with --trainer lean only"
    sizes = formation_sizes(args)
    if len(set(sizes)) != len(sizes) or max(sizes) != args.n_uavs:
        # The network, its normalisation and the exported policy keep --n-uavs's layout:
        # the widest (smaller formations' observations are padded to it).
        return f"{flag} must be distinct sizes, the largest --n-uavs ({args.n_uavs})"
    if args.arch != "set" and min(sizes) <= args.k_uavs:
        return (
            f"{flag}: {min(sizes)} UAVs observe fewer than --k-uavs {args.k_uavs} others; the "
            "slot MLP reads a fixed K (--arch set reads any number)"
        )
    # Per-row state that assumes one formation size: the return's running statistics and
    # the shield's filter (built for one formation).
    if args.norm_reward:
        return f"{flag} is not with --norm-reward (its returns are tracked per agent row)"
    if args.shield != "none":
        return f"{flag} is not with --shield (the filter is built for one formation size)"
    return None


def shield_problem(args: Args) -> str | None:
    """Why ``--shield`` cannot train with these flags (one line naming the flag), or None."""
    if args.shield != "none" and args.trainer != "lean":
        return f"argument --shield: {args.shield!r} trains with --trainer lean only"
    return None


def threads_problem() -> str | None:
    """A bad ``UASEP_THREADS`` or ``UASEP_WORKERS`` (one line naming it), or None."""
    from uasep_env.runtime.cores import check_variables

    try:
        check_variables()
    except ValueError as err:
        return str(err)
    return None


#: The fields that say where one run goes and how it is driven, not what it learns.
PER_RUN = ("seed", "out_dir", "resume", "overwrite", "tensorboard", "progress")


def to_argv(values: dict[str, Any], skip: tuple[str, ...] = ()) -> list[str]:
    """The flags that give a recipe the options ``values`` (an ``Args`` as a dict).

    Every field is written out, so that the command means the same under later defaults
    (a report's recipe, retrained by ``train/reproduce.py`` after a recipe's defaults moved).

    Args:
        values: Field name -> value (``dataclasses.asdict`` of an :class:`Args`).
        skip: Fields left out (those the caller sets itself).
    """
    argv: list[str] = []
    for name, value in values.items():
        if name in skip:
            continue
        flag = name.replace("_", "-")
        if isinstance(value, bool):
            argv.append(f"--{flag}" if value else f"--no-{flag}")
        else:
            argv += [f"--{flag}", str(value)]
    return argv


def make_env_config(args: Args) -> Any:
    """The environment config of a run (reward weights at their defaults unless overridden)."""
    from uasep_env import make_config
    from uasep_env.evaluation import parse_config_overrides

    base = make_config(
        scenario=args.scenario,
        n_uavs=args.n_uavs,
        n_obstacles=args.n_obstacles,
        episode_duration=args.episode_duration,
        action={"mode": args.action_mode, "residual_scale": args.residual_scale},
        observation={"k_uavs": args.k_uavs, "k_obstacles": args.k_obstacles},
    )
    return base.replace(**parse_config_overrides(args.config.split()))


def hidden(args: Args) -> list[int]:
    """The hidden layer widths of ``args.hidden``."""
    return [int(h) for h in args.hidden.split(",") if h.strip()]
