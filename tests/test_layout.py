"""The package's folders: moved modules still import by their old paths, with a warning."""

from __future__ import annotations

import importlib
import sys
import warnings

import pytest

from uasep_env._deprecation import MOVED_MODULES


@pytest.mark.parametrize(("old", "new"), sorted(MOVED_MODULES.items()))
def test_a_moved_module_imports_by_its_old_path_with_a_warning(old: str, new: str) -> None:
    module = importlib.import_module(new)
    saved = sys.modules.pop(old, None)
    try:
        with pytest.warns(DeprecationWarning, match=new.replace(".", r"\.")):
            alias = importlib.import_module(old)
        assert alias is module
        # The module keeps its own name and spec: a reload or numba's cache sees the new path.
        assert module.__spec__.name == new
        assert module.__name__ == new
    finally:
        if saved is not None:
            sys.modules[old] = saved


def test_the_old_paths_give_the_same_objects_and_patching_one_patches_both() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import uasep_env.world as old_world
        from uasep_env.rewards import TERMS as old_terms
    from uasep_env.interface.rewards import TERMS
    from uasep_env.sim import world

    assert old_terms is TERMS
    assert old_world is world


def test_no_package_module_is_left_at_an_old_path() -> None:
    import uasep_env

    root = uasep_env.__path__[0]
    import pathlib

    for old in MOVED_MODULES:
        name = old.split(".")[-1]
        assert not (pathlib.Path(root) / f"{name}.py").exists(), old


def test_the_documented_public_imports_work_without_a_warning() -> None:
    code = (
        "import warnings; warnings.simplefilter('error', DeprecationWarning)\n"
        "import uasep_env\n"
        "from uasep_env import World, EnvConfig, make_config, parallel_env, env\n"
        "from uasep_env.policies import APF\n"
        "from uasep_env.metrics import EpisodeRecord\n"
        "from uasep_env.sim.world import World as W\n"
        "assert W is World\n"
    )
    import subprocess

    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
