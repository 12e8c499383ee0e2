"""A run folder's files are read in one place: the readers of ``training/checkpoint_readers.py``
(re-exported by ``training/rundir.py``) and ``training/curves.py`` (``check_checkpoint``,
``read_state``, ``read_tensors``, ``load_normalization``, ``read_policy``, ``read_progress``).

Hardening the reading of a hostile run folder (symlinks, oversized files) hardens them
only; a recipe that read a checkpoint's or a CSV's file itself would escape it. Also: each
recipe's loop holds a :class:`~uasep_env.training.rundir.RunFolder` (no recipe claims the
folder, rewinds it or publishes by the module functions itself).
"""

import ast
from pathlib import Path

import pytest

TRAINING = Path(__file__).resolve().parents[1] / "uasep_env" / "training"
#: Where a run folder's files may be read.
READERS = {"checkpoint_readers.py", "rundir.py", "curves.py"}
#: Calls that read a file (or load one).
READS = {"loads", "load", "read_text", "read_bytes", "read_checkpoint", "DictReader"}
#: The recipes' loops, each holding one RunFolder.
LOOPS = ["ppo_shared.py", "lean_recipe.py", "mappo.py", "mappo_lagrangian.py"]
#: What only RunFolder calls (the run folder's life, module-level pieces).
LIFE = {"prepare_out_dir", "start_run", "rewind", "plot_curves", "write_validation"}


def _calls(path: Path, bare: bool = False) -> set[str]:
    """The names ``path`` calls; ``bare``: only as functions (``f()``, ``rundir.f()``)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Name):
                names.add(f.id)
            elif isinstance(f, ast.Attribute) and not (
                bare and getattr(f.value, "id", "") != "rundir"
            ):
                names.add(f.attr)
    return names


@pytest.mark.parametrize(
    "path", sorted(p for p in TRAINING.glob("*.py") if p.name not in READERS), ids=str
)
def test_no_training_module_reads_a_run_file_but_the_readers(path):
    assert not _calls(path) & READS, f"{path.name} reads a file itself: {_calls(path) & READS}"


@pytest.mark.parametrize("name", LOOPS)
def test_each_recipe_loop_goes_through_its_run_folder(name):
    calls = _calls(TRAINING / name, bare=True)
    assert not calls & LIFE, f"{name} calls {calls & LIFE} itself, not through RunFolder"
    assert {"start", "attach"} & _calls(TRAINING / name), name
