"""Time limits in the tests guard against hangs only, never against a slow (loaded) machine.

A busy 2-core runner ran the suite twenty times slower than an idle one; a limit that a
slow run can cross fails a correct program. Every limit in ``tests/`` is therefore the one
hang guard, :data:`conftest.HANG_GUARD_S`, and hypothesis runs without deadlines.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from conftest import HANG_GUARD_S

TESTS = Path(__file__).resolve().parent
#: Calls whose result is a point in time: ``now() + limit`` is a deadline.
_CLOCKS = {"monotonic", "perf_counter", "time"}


def _is_guard(node: ast.expr) -> bool:
    return isinstance(node, ast.Name) and node.id == "HANG_GUARD_S"


def _limits(tree: ast.AST) -> list[tuple[int, str]]:
    """``(line, what)`` of every time limit in ``tree`` that is not the hang guard."""
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else ""
            name = name or (node.func.id if isinstance(node.func, ast.Name) else "")
            for kw in node.keywords:
                if kw.arg == "timeout" and not (
                    _is_guard(kw.value)
                    or (isinstance(kw.value, ast.Name) and kw.value.id == "timeout")
                ):
                    bad.append((node.lineno, f"{name}(timeout={ast.unparse(kw.value)})"))
                if kw.arg == "deadline" and not (
                    isinstance(kw.value, ast.Constant) and kw.value.value is None
                ):
                    bad.append((node.lineno, f"{name}(deadline={ast.unparse(kw.value)})"))
            if name in {"alarm", "setitimer"} or (
                name == "timeout" and "mark" in ast.unparse(node.func)
            ):
                args = node.args[-1:] if name != "setitimer" else node.args[1:2]
                if not (args and _is_guard(args[0])):
                    bad.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            for clock, limit in ((node.left, node.right), (node.right, node.left)):
                is_now = isinstance(clock, ast.Call) and (
                    isinstance(clock.func, ast.Attribute) and clock.func.attr in _CLOCKS
                )
                if is_now and not _is_guard(limit):
                    bad.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.arguments):  # a default `timeout` parameter
            args = node.posonlyargs + node.args
            defaults = [None] * (len(args) - len(node.defaults)) + list(node.defaults)
            pairs = list(zip(args, defaults, strict=True)) + list(
                zip(node.kwonlyargs, node.kw_defaults, strict=True)
            )
            for arg, default in pairs:
                if arg.arg == "timeout" and default is not None and not _is_guard(default):
                    bad.append((default.lineno, f"def ...({arg.arg}={ast.unparse(default)})"))
    return bad


def test_the_hang_guard_is_generous():
    """Long enough that only a hang crosses it: work that takes minutes idle, loaded."""
    assert HANG_GUARD_S >= 20 * 60


def test_every_time_limit_in_the_tests_is_the_hang_guard():
    found = {}
    for path in sorted(TESTS.rglob("*.py")):
        bad = _limits(ast.parse(path.read_text(), str(path)))
        if bad:
            found[path.relative_to(TESTS).as_posix()] = bad
    assert not found, f"time limits that are not conftest.HANG_GUARD_S: {found}"


@pytest.mark.parametrize(
    "code",
    [
        "subprocess.run(cmd, timeout=120)",
        "pool.apply_async(f).get(timeout=60)",
        "p.wait(timeout=300)",
        "deadline = time.monotonic() + 120",
        "settings(max_examples=5, deadline=500)",
        "signal.alarm(30)",
        "def run(code, timeout=120): pass",
        "@pytest.mark.timeout(60)\ndef test_x(): pass",
    ],
)
def test_the_checker_finds_a_speed_limit(code):
    """The check above is not vacuous: each of these limits is one it reports."""
    assert _limits(ast.parse(code))


def test_the_checker_accepts_the_hang_guard():
    ok = (
        "subprocess.run(cmd, timeout=HANG_GUARD_S)\n"
        "deadline = time.monotonic() + HANG_GUARD_S\n"
        "settings(deadline=None)\n"
        "def run(code, timeout=HANG_GUARD_S):\n    return go(timeout=timeout)\n"
    )
    assert _limits(ast.parse(ok)) == []


def test_hypothesis_has_no_deadline_by_default():
    hypothesis = pytest.importorskip("hypothesis")
    assert hypothesis.settings.default.deadline is None
