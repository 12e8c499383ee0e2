"""What a pip user gets (issue 23): dependency floors, installs without the optional extras,
the shipped policies as package data, the sdist and the package metadata.

The wheel and sdist themselves are built and installed in a clean venv by ``make
test-package`` (CI); the declared floors are installed and tested by ``make test-floors``.
"""

from __future__ import annotations

import os
import re
import runpy
import subprocess
import sys

import numpy as np
import pytest
from conftest import HANG_GUARD_S, ROOT, run_python

import uasep_env
from uasep_env.config import make_config
from uasep_env.policies import check_policy_name, load_policy, make_policy, shipped_policies

tomllib = pytest.importorskip("tomllib", reason="Python >= 3.11")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
CHECKPOINTS = ROOT / "baselines" / "checkpoints"


# ------------------------------------------------------------------ item 1: true floors
def test_observations_build_without_reshape_copy_keyword(monkeypatch):
    """numpy < 2.1 has no ``reshape(..., copy=)``: the numpy path must not need it."""
    from uasep_env import _numba
    from uasep_env.envs.core import EnvCore

    original = np.reshape

    def old_reshape(a, *args, **kwargs):
        if "copy" in kwargs:
            raise TypeError("reshape() got an unexpected keyword argument 'copy'")
        return original(a, *args, **kwargs)

    monkeypatch.setitem(_numba._state, "numba", None)  # the numpy reference, as without numba
    core = EnvCore({"n_uavs": 4, "n_obstacles": 2, "scenario": "random"}, n_envs=3)
    reference = core.reset(seed=5).copy()
    monkeypatch.setattr(np, "reshape", old_reshape)
    np.testing.assert_array_equal(core.reset(seed=5), reference)  # the same numbers


def _floor_pins() -> dict[str, str]:
    lines = (ROOT / ".ci" / "floors.txt").read_text().splitlines()
    pins = [line.split("==") for line in lines if line.strip() and not line.startswith("#")]
    return {name.strip().lower(): version.strip() for name, version in pins}


def test_floors_job_installs_exactly_the_declared_floors():
    declared = {}
    for req in PYPROJECT["project"]["dependencies"]:
        m = re.fullmatch(r"([A-Za-z0-9_.-]+)>=([0-9.]+)", req)
        assert m, f"core dependency {req!r} must be a plain '>=' floor (tested by the job)"
        declared[m[1].lower()] = m[2]
    pins = _floor_pins()
    assert set(pins) == set(declared)
    for name, floor in declared.items():
        assert pins[name].split(".")[: len(floor.split("."))] == floor.split("."), name
    assert "numba" not in pins


def test_gymnasium_floor_has_autoreset_mode():
    """make_vec needs gymnasium.vector.AutoresetMode, new in 1.1: the floor says so."""
    assert "gymnasium>=1.1" in PYPROJECT["project"]["dependencies"]


# --------------------------------------------------- item 2: no matplotlib (core install)
_NO_MATPLOTLIB = "import sys; sys.modules['matplotlib'] = None  # as if not installed\n"


def test_check_env_and_render_without_matplotlib():
    out = run_python(
        _NO_MATPLOTLIB
        + """
import gymnasium, uasep_env
from gymnasium.utils.env_checker import check_env
from uasep_env.registration import ENV_IDS
for env_id in ENV_IDS:
    env = gymnasium.make(env_id, episode_duration=4.0)
    assert env.metadata["render_modes"] == [], env.metadata
    check_env(env.unwrapped)
    env.close()
# Asking for rendering is one clear error, at once, naming the extra.
try:
    gymnasium.make("uasep/PaperEncounter-v3", render_mode="rgb_array")
except ModuleNotFoundError as err:
    print("ERR", err)
try:
    gymnasium.make_vec("uasep/PaperEncounter-v3", 2, vectorization_mode="vector_entry_point",
                       render_mode="rgb_array")
except ModuleNotFoundError as err:
    print("VEC", err)
try:
    uasep_env.parallel_env(render_mode="human")
except ModuleNotFoundError as err:
    print("PAR", err)
from uasep_env.envs.gym_env import FormationEnv
env = FormationEnv()  # render() without a render_mode: Gymnasium's warning, None
env.reset(seed=0)
assert env.render() is None
""",
        timeout=HANG_GUARD_S,
    )
    assert out.returncode == 0, out.stderr
    for tag in ("ERR", "VEC", "PAR"):
        line = next(x for x in out.stdout.splitlines() if x.startswith(tag))
        assert "render()" in line and "uasep-env[viz]" in line, line


def test_eval_plot_without_matplotlib_fails_before_evaluating(tmp_path):
    out = run_python(
        _NO_MATPLOTLIB
        + f"""
from uasep_env.evaluation import main
raise SystemExit(main(["--policy", "apf", "--plot", {str(tmp_path / "figs")!r},
                       "--json", {str(tmp_path / "out.json")!r}]))
"""
    )
    assert out.returncode == 2
    assert "--plot" in out.stderr and "uasep-env[viz]" in out.stderr
    assert not (tmp_path / "out.json").exists()  # nothing ran


def test_render_modes_declared_with_matplotlib():
    pytest.importorskip("matplotlib")
    from uasep_env.envs.gym_env import FormationEnv

    assert FormationEnv.metadata["render_modes"] == ["human", "rgb_array"]


# ------------------------------------------------ item 3: shipped policies, by name
def test_shipped_policies_resolve_by_name():
    names = shipped_policies()
    assert {"ppo_shared", "ppo_residual_apf"} <= set(names)
    for name, path in names.items():
        assert path.read_bytes() == (CHECKPOINTS / f"{name}.zip").read_bytes()
        assert check_policy_name(name) == name
    shared = load_policy("ppo_shared")
    assert shared.name == "ppo_shared"
    cfg = make_config(scenario="paper")
    residual = make_policy("ppo_residual_apf", cfg)
    assert residual.name == "ppo_residual_apf" and residual.mode == "residual_apf"
    with pytest.raises(ValueError, match="ppo_shared"):  # the message lists them
        check_policy_name("ppo_sharde")
    with pytest.raises(FileNotFoundError, match="no shipped policy"):
        load_policy("ppo_sharde")


def test_uasep_eval_runs_a_shipped_policy_by_name(tmp_path):
    from uasep_env.evaluation import main

    out = tmp_path / "r.json"
    args = ["--policy", "ppo_residual_apf", "--config", "episode_duration=4", "--json", str(out)]
    assert main([*args, "--quiet"]) == 0
    assert '"ppo_residual_apf"' in out.read_text()


def _needs_build_tools(*dists: str) -> None:
    """Skip unless the packaging tools are installed (the floors venv has none of them)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        if int(version("setuptools").split(".")[0]) < 77:  # license = "MIT" (PEP 639)
            pytest.skip("needs setuptools >= 77")
        for dist in dists:
            version(dist)
    except PackageNotFoundError as err:
        pytest.skip(f"needs {err}")


def _setup_py() -> dict:
    return runpy.run_path(str(ROOT / "setup.py"), run_name="setup_py_under_test")


def test_build_copies_the_repo_checkpoints_into_the_package(tmp_path):
    """The wheel's package data is the repo's baselines/checkpoints/*.zip, byte for byte."""
    _needs_build_tools()
    build = subprocess.run(
        [sys.executable, "setup.py", "-q", "build_py", "--build-lib", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert build.returncode == 0, build.stderr
    shipped = sorted((tmp_path / "uasep_env" / "checkpoints").glob("*.zip"))
    source = sorted(CHECKPOINTS.glob("*.zip"))
    assert [p.name for p in shipped] == [p.name for p in source] and source
    for a, b in zip(shipped, source, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert (tmp_path / "uasep_env" / "data" / "ellipse_table.npz").is_file()
    assert (tmp_path / "uasep_env" / "data" / "prediction_calibration.json").is_file()


# --------------------------------------------------------- item 5: package metadata
def test_metadata_license_version_build_requires():
    project = PYPROJECT["project"]
    assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    assert "uasep-env developers" in (ROOT / "LICENSE").read_text()
    requires = PYPROJECT["build-system"]["requires"]
    assert not any(r.startswith("wheel") for r in requires)
    assert "version" in project["dynamic"]
    released = re.findall(r"^## (\d+\.\d+\.\d+)", (ROOT / "CHANGELOG.md").read_text(), re.M)
    assert uasep_env.__version__ == released[0] == "0.4.0"


def test_readme_for_the_package_index_has_absolute_links():
    absolute_links = _setup_py()["absolute_links"]
    page = absolute_links((ROOT / "README.md").read_text())
    targets = re.findall(r"\]\(([^)\s]+)\)", page)
    assert targets
    relative = [t for t in targets if not t.startswith(("https://", "#"))]
    assert relative == []
    assert "../" not in "".join(targets)
    assert absolute_links("![f](docs/frame.png) [x](uasep_env/sim/world.py) [s](#speed)") == (
        "![f](https://raw.githubusercontent.com/uasep/uasep-env/main/docs/frame.png) "
        "[x](https://github.com/uasep/uasep-env/blob/main/uasep_env/sim/world.py) [s](#speed)"
    )


def test_the_package_index_page_opens_with_pip_not_make():
    # The README keeps its clone set-up block on top; the index's page (the wheel's long
    # description) drops it and opens with installing the package.
    page = _setup_py()["index_readme"]((ROOT / "README.md").read_text())
    first_block = page[page.index("```") :].split("\n```\n", 1)[0]
    assert first_block.startswith("```bash\npip install") and "make " not in first_block
    assert page.index("pip install") < page.index("Commands marked *(repository)*")
    assert PYPROJECT["project"]["description"].split()[0] != "make"
    with pytest.raises(ValueError, match="make eval"):
        _setup_py()["index_readme"]("# t\n\ntext\n")


def test_readme_links_stay_inside_the_repository():
    readme = (ROOT / "README.md").read_text()
    for target in re.findall(r"\]\(([^)\s#]+)[^)]*\)", readme):
        if target.startswith(("http://", "https://", "mailto:")):
            continue
        path = (ROOT / target).resolve()
        assert path.is_relative_to(ROOT), target
        assert path.exists(), target
    assert (ROOT / "docs" / "paper_errata.md").is_file()


# ---------------------------------------------------------------- item 4: the sdist
def test_sdist_carries_what_the_tests_need(tmp_path):
    _needs_build_tools("build")
    out = subprocess.run(
        [sys.executable, "-m", "build", "--sdist", "--no-isolation", "--outdir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    (sdist,) = tmp_path.glob("*.tar.gz")
    import tarfile

    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    for needed in (
        "LICENSE",
        "setup.py",
        "tests/conftest.py",
        "baselines/checkpoints/ppo_shared.zip",
        "baselines/checkpoints/ppo_residual_apf.zip",
        "baselines/results/summary.md",
        "tools/sync_readme.py",
        "train/README.md",
        "docs/paper_errata.md",
    ):
        assert needed in names, needed
    assert not any("__pycache__" in n for n in names)  # (make test-package checks the wheel)


# ------------------------------------------------------------ the console commands
@pytest.mark.parametrize("name", sorted(PYPROJECT["project"]["scripts"]))
def test_every_console_command_imports_and_prints_its_help(name):
    module, _, func = PYPROJECT["project"]["scripts"][name].partition(":")
    code = (
        f"import sys; from {module} import {func} as entry; sys.argv = [{name!r}, '--help']; "
        "sys.exit(entry())"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "UASEP_NUMBA": "0"}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=HANG_GUARD_S
    )
    assert done.returncode == 0, f"{name} --help: exit {done.returncode}\n{done.stderr[-2000:]}"
    assert "usage" in done.stdout.lower(), done.stdout[:500]
