"""The recipes' and drivers' flags: a bad value is refused with one line naming the flag.

No torch needed: the parsers run before anything is imported from the train extra.
"""

import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import HANG_GUARD_S

from uasep_env.training import RECIPES as COMMANDS
from uasep_env.training import mappo, ppo_shared
from uasep_env.training.ppo_residual_apf import RESIDUAL_DEFAULTS

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "train"))

#: (flag, bad value): each must be refused by every recipe.
BAD = [
    ("--checkpoint-every", "-5"),
    ("--checkpoint-every", "0"),
    ("--total-timesteps", "-100"),
    ("--n-envs", "0"),
    ("--n-steps", "-1"),
    ("--batch-size", "x"),
    ("--n-epochs", "0"),
    ("--max-minutes", "0"),
    ("--max-minutes", "inf"),
    ("--learning-rate", "-1e-4"),
    ("--learning-rate", "nan"),
    ("--gamma", "1.5"),
    ("--gae-lambda", "-0.1"),
    ("--clip-range", "0"),
    ("--ent-coef", "-0.01"),
    ("--target-kl", "-1"),
    ("--critic-warmup", "-1"),
    ("--log-std-init", "inf"),
    ("--hidden", "128,0"),
    ("--hidden", "abc"),
    ("--hidden", "0"),
    ("--hidden", "-5"),
    ("--hidden", "1000000000"),  # more memory than any machine: refused before torch runs
    ("--activation", "sigmoid"),
    ("--action-mode", "bogus"),
    ("--scenario", "nowhere"),
    ("--n-uavs", "0"),
    ("--n-uavs", "99"),
    ("--n-obstacles", "-2"),
    ("--k-uavs", "0"),
    ("--episode-duration", "-5"),
    ("--residual-scale", "0"),
    ("--seed", "-1"),
    ("--seed", "99999999"),
    ("--eval-episodes", "-1"),
    ("--torch-threads", "0"),
    ("--device", "gpu"),
    ("--device", "cuda:x"),
    ("--device", "cpu:0"),
    ("--device", "cuda:"),
    ("--config", "nokey"),
    ("--config", "dt=-1"),
]

RECIPES = {
    "ppo_shared": lambda argv: ppo_shared.parse_args(argv),
    "ppo_residual_apf": lambda argv: ppo_shared.parse_args(argv, RESIDUAL_DEFAULTS),
    "mappo": lambda argv: mappo.parse_args(argv),
}


def _refused(parse, argv, capsys, flag):
    with pytest.raises(SystemExit) as info:
        parse(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("\n"), err  # one line
    assert f"argument {flag}" in err, err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize("recipe", sorted(RECIPES))
@pytest.mark.parametrize(("flag", "value"), BAD)
def test_each_recipe_refuses_each_bad_value_in_one_line(recipe, flag, value, capsys, tmp_path):
    _refused(RECIPES[recipe], [flag, value, "--out-dir", str(tmp_path)], capsys, flag)


@pytest.mark.parametrize("recipe", sorted(RECIPES))
def test_an_out_dir_that_is_a_file_is_refused(recipe, capsys, tmp_path):
    (tmp_path / "f").write_text("x")
    _refused(RECIPES[recipe], ["--out-dir", str(tmp_path / "f")], capsys, "--out-dir")


@pytest.mark.parametrize(("flag", "value"), [("--value-loss-scale", "-1"),
                                             ("--grad-norm-clip", "nan"),
                                             ("--batch-size", "3000"),
                                             ("--device", "cuda")])  # fmt: skip
def test_mappo_refuses_its_own_bad_values(flag, value, capsys, tmp_path):
    _refused(mappo.parse_args, [flag, value, "--out-dir", str(tmp_path)], capsys, flag)


def test_good_values_are_accepted(tmp_path):
    argv = ["--checkpoint-every", "5", "--gamma", "1", "--ent-coef", "0",
            "--out-dir", str(tmp_path), "--config", "reward.collision=2"]  # fmt: skip
    args = ppo_shared.parse_args(argv)
    assert (args.checkpoint_every, args.gamma, args.ent_coef) == (5, 1.0, 0.0)
    assert ppo_shared.parse_args([]) == ppo_shared.Args()  # the defaults pass their own checks
    assert mappo.parse_args([]) == mappo.Args()
    assert ppo_shared.parse_args([], RESIDUAL_DEFAULTS) == RESIDUAL_DEFAULTS


@pytest.mark.parametrize("value", ["gpu", "cuda:x", "cpu:0", "cuda:", "CUDA"])
def test_a_device_that_is_no_torch_device_name_is_refused_by_its_type(value, capsys, tmp_path):
    # Refused as a name, before torch is asked (which would see a GPU on a GPU machine).
    err = _refused(ppo_shared.parse_args, ["--out-dir", str(tmp_path), "--device", value],
                   capsys, "--device")  # fmt: skip
    assert f"must be cpu, cuda or cuda:N, got {value!r}" in err


def test_a_device_torch_cannot_see_is_refused_in_one_line(monkeypatch, capsys, tmp_path):
    torch = pytest.importorskip("torch")
    argv = ["--out-dir", str(tmp_path), "--device"]
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    err = _refused(ppo_shared.parse_args, [*argv, "cuda"], capsys, "--device")
    assert "cuda: torch" in err and "sees no CUDA device" in err
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    err = _refused(ppo_shared.parse_args, [*argv, "cuda:2"], capsys, "--device")
    assert "cuda:2: torch sees 2 CUDA device(s) here (cuda:0 to cuda:1)" in err
    assert ppo_shared.parse_args([*argv, "cuda:1"]).device == "cuda:1"
    assert ppo_shared.parse_args([*argv, "cuda"], RESIDUAL_DEFAULTS).device == "cuda"
    assert ppo_shared.parse_args(argv[:2]).device == "cpu"  # the default asks nothing of torch


@pytest.mark.parametrize(
    "command",
    [
        [sys.executable, "-m", "uasep_env.training", "ppo_shared"],
        [sys.executable, str(ROOT / "train" / "ppo_shared.py")],
        [sys.executable, str(ROOT / "train" / "mappo.py")],
    ],
)
def test_checkpoint_every_minus_five_is_refused_before_the_run_starts(command, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [*command, "--checkpoint-every", "-5", "--out-dir", str(out)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        timeout=HANG_GUARD_S,
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "argument --checkpoint-every: must be an integer >= 1, got '-5'" in proc.stderr
    assert not out.exists()  # nothing written


DRIVERS = {
    "seeds": (["--recipe", "shared", "--out-dir", "x"], [
        ("--seeds", "0"), ("--parallel", "-1"), ("--select-episodes", "0"),
        ("--episodes", "x"), ("--scaling-episodes", "-1"), ("--workers", "0"),
    ]),
    "reproduce": (["report.json", "--out-dir", "x"], [("--seed", "-1"), ("--workers", "0")]),
}  # fmt: skip


@pytest.mark.parametrize(
    ("driver", "flag", "value"),
    [(d, f, v) for d, (_, bad) in DRIVERS.items() for f, v in bad],
)
def test_the_drivers_refuse_bad_values_in_one_line(driver, flag, value, capsys):
    import importlib

    module = importlib.import_module(driver)
    base, _ = DRIVERS[driver]
    _refused(lambda argv: module.build_parser().parse_args(argv), [*base, flag, value], capsys,
             flag)  # fmt: skip


def test_recipe_help_lists_every_flag_with_its_default(capsys):
    from uasep_env.training.cli import main

    assert main(["mappo", "--help"]) == 0
    text = capsys.readouterr().out
    for name in mappo.Args.__dataclass_fields__:
        assert "--" + name.replace("_", "-") in text
    assert text.count("(default:") >= len(mappo.Args.__dataclass_fields__)
    assert main(["nope"]) == 2
    assert "unknown recipe 'nope'" in capsys.readouterr().err


def test_a_missing_resume_folder_is_one_line_before_anything_runs(tmp_path, capsys):
    from uasep_env.training.cli import main

    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    argv = ["ppo_shared", "--resume", str(tmp_path / "nope"), "--out-dir", str(tmp_path / "r")]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "no such checkpoint folder" in err
    assert not (tmp_path / "r").exists()


def test_a_recipe_without_torch_is_one_line_naming_the_extra(monkeypatch, tmp_path, capsys):
    from uasep_env.training.cli import main

    monkeypatch.setitem(sys.modules, "torch", None)  # import torch -> ModuleNotFoundError
    assert main(["ppo_shared", "--out-dir", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs torch" in err and "uasep-env[train]" in err
    assert not (tmp_path / "run").exists()


def test_report_help_lists_every_flag_with_its_default(capsys):
    from uasep_env.reporting.scaling import build_parser, cli

    parser = build_parser("uasep-report")
    text = parser.format_help()
    for action in parser._actions:
        if action.option_strings and action.dest != "help":
            assert action.option_strings[0] in text
    assert text.count("(default:") == len(parser._actions) - 1  # all but --help
    with pytest.raises(SystemExit) as info:
        cli(["--episodes", "-3"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "argument --episodes" in err


def test_a_recipe_may_extend_args_with_fields_of_its_own(capsys):
    from dataclasses import dataclass

    from uasep_env.training.args import Args, parse_args

    @dataclass
    class Mine(Args):
        cost_limit: float = 0.1
        lagrange_steps: int = 3
        dual: bool = True

    args = parse_args(["--cost-limit", "0.5", "--no-dual"], Mine())
    assert (args.cost_limit, args.lagrange_steps, args.dual) == (0.5, 3, False)
    _refused(lambda argv: parse_args(argv, Mine()), ["--cost-limit", "nan"], capsys,
             "--cost-limit")  # fmt: skip


@pytest.mark.parametrize("recipe", sorted(RECIPES))
@pytest.mark.parametrize("width", ["1000000000", "100000,100000", "0", "-5"])
def test_a_hidden_width_that_cannot_train_is_one_line_naming_it(recipe, width, capsys):
    err = _refused(RECIPES[recipe], ["--hidden", width], capsys, "--hidden")
    assert repr(width) in err, err


def test_the_hidden_width_limit_follows_the_memory_available(monkeypatch, capsys):
    from uasep_env.runtime import capacity

    assert ppo_shared.parse_args(["--hidden", "4096,4096"]).hidden == "4096,4096"
    monkeypatch.setattr(capacity, "available_memory", lambda: 10**8)
    err = _refused(ppo_shared.parse_args, ["--hidden", "4096,4096"], capsys, "--hidden")
    assert "100 MB available" in err, err
    assert ppo_shared.parse_args(["--hidden", "64,64"]).hidden == "64,64"


@pytest.mark.parametrize("recipe", sorted(RECIPES))
@pytest.mark.parametrize(
    "variable, value", [("UASEP_THREADS", "0"), ("UASEP_THREADS", "x"), ("UASEP_WORKERS", "-2")]
)
def test_a_bad_thread_variable_is_one_line_naming_it(recipe, variable, value, monkeypatch, capsys):
    monkeypatch.setenv(variable, value)
    with pytest.raises(SystemExit) as info:
        RECIPES[recipe]([])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{variable}={value!r}" in err, err


@pytest.mark.parametrize(
    "variable, value", [("UASEP_THREADS", "0"), ("UASEP_WORKERS", "0"), ("UASEP_THREADS", "-1")]
)
def test_uasep_eval_refuses_a_bad_thread_variable_in_one_line_status_2(variable, value):
    """A subprocess: the variables are read once per process (as the kernels read them)."""
    code = "from uasep_env.evaluation import main; raise SystemExit(main(['--episodes', '1']))"
    env = {**os.environ, variable: value, "PYTHONPATH": str(ROOT)}
    res = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True,
        timeout=HANG_GUARD_S,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1, res.stderr
    assert f"uasep-eval: error: {variable}={value!r}" in res.stderr, res.stderr


#: What reStructuredText or the issue tracker leave in a text for people: roles, literals,
#: strong emphasis, issue numbers.
MARKUP = re.compile(r":[a-z]+:`|``|\*\*|\bissue \d+", re.IGNORECASE)


@pytest.mark.parametrize("recipe", list(COMMANDS))
def test_recipe_help_is_plain_text_of_its_own(recipe, capsys):
    """``uasep-train RECIPE --help``: no markup, no issue numbers, its own description."""
    from uasep_env.training.args import plain_text
    from uasep_env.training.cli import main

    assert main([recipe, "--help"]) == 0
    text = capsys.readouterr().out
    assert not MARKUP.findall(text), MARKUP.findall(text)
    description = text.split("\n\n")[1]  # after the usage
    first = importlib.import_module(COMMANDS[recipe][0]).__doc__.splitlines()[0]
    assert " ".join(description.split()).startswith(plain_text(first))
    # The short trial run is named, and the rounding of the step budget said.
    assert f"\n  uasep-train {recipe} --total-timesteps 20000" in text
    assert f"\n    uasep-train {recipe}" in text  # the examples keep their lines
    assert "rounded up to whole rollouts" in " ".join(text.split())


def test_eval_and_report_help_are_plain_text():
    from uasep_env.evaluation.cli import build_parser as eval_parser
    from uasep_env.reporting.scaling import build_parser as report_parser

    for parser in (eval_parser(), report_parser("uasep-report")):
        text = parser.format_help()
        assert not MARKUP.findall(text), MARKUP.findall(text)


def test_plain_text_renders_the_markup_as_sphinx_shows_it():
    from uasep_env.training.args import plain_text

    doc = (
        "by :class:`~a.b.Callback` (:mod:`uasep_env.costs`; :func:`title <a.f>`), "
        "``--x 1``, a **cost\ncritic**; an example::\n\n    code"
    )
    assert plain_text(doc) == (
        "by Callback (uasep_env.costs; title), --x 1, a cost\ncritic; an example:\n\n    code"
    )


def test_the_step_budget_is_rounded_up_to_whole_rollouts_and_said_once():
    from uasep_env.training.args import Args, budget_notice, rounded_budget

    args = Args(total_timesteps=150_000)  # 32 environments x 3 UAVs x 256 steps: 24,576
    assert rounded_budget(args, 3) == 172_032
    assert budget_notice(args, 3) == (
        "--total-timesteps 150000 rounded up to 172032: whole rollouts of 24576 agent-steps "
        "(--n-envs 32 x 3 UAVs x --n-steps 256)"
    )
    assert budget_notice(Args(total_timesteps=7 * 24_576), 3) is None  # nothing to say
    # A resumed run counts its rollouts from its checkpoint's agent-steps.
    assert rounded_budget(args, 3, start=150) == 150 + 7 * 24_576
    assert budget_notice(args, 3, start=200_000) is None  # past the budget: nothing to train
