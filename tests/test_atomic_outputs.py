"""Outputs are all-or-nothing, never destroy inputs, and bad arguments get one clear line."""

import errno
import json
import os
import shutil
from pathlib import Path

import pytest
from conftest import fill_disk

from uasep_env.evaluation import main
from uasep_env.evaluation.overrides import parse_config_overrides
from uasep_env.runtime.atomic import atomic_output, atomic_symlink, atomic_write

CHECKPOINTS = Path(__file__).resolve().parents[1] / "baselines" / "checkpoints"


@pytest.fixture
def full_disk(monkeypatch):
    fill_disk(monkeypatch, room=100)


def _leftovers(folder):
    return sorted(p.name for p in Path(folder).iterdir() if p.name.startswith("."))


def test_a_full_disk_leaves_the_old_file_and_says_so_in_one_line(tmp_path, full_disk):
    target = tmp_path / "out.json"
    target.write_text('{"old": true}')
    with pytest.raises(OSError, match=r"cannot write .*out.json: No space left on device; the "
                       "previous file, if any, is unchanged") as info:  # fmt: skip
        atomic_write(target, "x" * 1000)
    assert info.value.errno == errno.ENOSPC and "\n" not in str(info.value)
    assert target.read_text() == '{"old": true}'
    assert _leftovers(tmp_path) == []


def test_atomic_output_keeps_the_old_file_on_any_error(tmp_path):
    target = tmp_path / "a.csv"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_output(target, "w") as fh:
        fh.write("half")
        raise RuntimeError("killed mid-way")
    assert target.read_text() == "old" and _leftovers(tmp_path) == []
    with atomic_output(target, "w") as fh:
        fh.write("new")
    assert target.read_text() == "new"


def test_symlink_swap_never_leaves_no_link(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    link = tmp_path / "latest"
    atomic_symlink("a", link)
    atomic_symlink("b", link)
    assert os.readlink(link) == "b" and _leftovers(tmp_path) == []


def test_eval_on_a_full_disk_keeps_the_old_json_and_csv(tmp_path, capsys, full_disk):
    out_json, out_csv = tmp_path / "r.json", tmp_path / "r.csv"
    out_json.write_text('{"valid": 1}')
    out_csv.write_text("a,b\n")
    code = main(["--episodes", "1", "--json", str(out_json), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "No space left on device" in err
    assert json.loads(out_json.read_text()) == {"valid": 1}
    code = main(["--episodes", "1", "--csv", str(out_csv), "--quiet"])
    assert code == 1 and out_csv.read_text() == "a,b\n"
    assert _leftovers(tmp_path) == []


def test_outputs_cannot_overwrite_the_policy_or_each_other(tmp_path, capsys):
    victim = tmp_path / "victim.zip"
    shutil.copy(CHECKPOINTS / "ppo_shared.zip", victim)
    before = victim.read_bytes()
    for flag in ("--json", "--csv"):
        code = main(["--policy", str(victim), flag, str(victim), "--quiet"])
        assert code == 2 and "is the policy being evaluated" in capsys.readouterr().err
    assert victim.read_bytes() == before
    same = tmp_path / "out"
    code = main(["--json", str(same), "--csv", str(tmp_path / "." / "out"), "--quiet"])
    assert code == 2 and "--json and --csv: both write" in capsys.readouterr().err
    assert not same.exists()


def test_a_policy_path_with_a_comma_is_one_path(tmp_path, capsys):
    odd = tmp_path / "a,b.zip"
    shutil.copy(CHECKPOINTS / "ppo_shared.zip", odd)
    out = tmp_path / "r.json"
    code = main(["--policy", str(odd), "--scenario", "random", "--json", str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert list(json.loads(out.read_text())["results"]) == ["a,b"]
    # Plain comma lists still split.
    code = main(["--policy", "apf,zero", "--json", str(out), "--quiet"])
    assert code == 0 and list(json.loads(out.read_text())["results"]) == ["apf", "zero"]


def test_deep_and_long_config_values_get_short_clear_errors(capsys):
    with pytest.raises(ValueError, match="nests 100000 levels, limit 8"):
        parse_config_overrides(["noise=" + "[" * 100_000 + "]" * 100_000])
    code = main(["--config", "noise=" + "[" * 100_000 + "]" * 100_000, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and "RecursionError" not in err
    assert len(err) < 600 and err.count("\n") == 1
    code = main(["--config", "scenario=" + "x" * 100_000, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err) < 600 and "chars)" in err
