"""The optional extras: ``[all]`` holds every one that can share an environment."""

from __future__ import annotations

import re

import pytest
from conftest import ROOT

tomllib = pytest.importorskip("tomllib", reason="Python >= 3.11")

PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
#: Extras [all] leaves out, and why: BenchMARL 1.5.2 requires TorchRL < 0.12, clients >= 0.14.1.
NOT_IN_ALL = {"benchmarl"}


def self_extras(requirements: list[str]) -> set[str]:
    """The extras of ``uasep-env[...]`` requirements (the package naming its own extras)."""
    found: set[str] = set()
    for req in requirements:
        m = re.fullmatch(r"uasep-env\[([^\]]*)\]", req.strip())
        if m:
            found |= {e.strip() for e in m[1].split(",")}
    return found


def test_the_all_extra_is_every_extra_but_benchmarl():
    extras = PROJECT["optional-dependencies"]
    in_all = self_extras(extras["all"])
    assert in_all == set(extras) - NOT_IN_ALL - {"all"}, (
        f"[all] lacks {set(extras) - NOT_IN_ALL - {'all'} - in_all}, "
        f"or names {in_all - set(extras) | in_all & NOT_IN_ALL} it should not"
    )
    # [all] names only the package's own extras: one list of pins per dependency.
    assert all(self_extras([r]) for r in extras["all"])


def test_benchmarl_and_clients_cannot_share_an_environment():
    # Why benchmarl stays out of [all]: their TorchRL ranges do not meet.
    extras = PROJECT["optional-dependencies"]
    assert "benchmarl==1.5.2" in extras["benchmarl"]
    assert any(r.startswith("torchrl>=0.14") for r in extras["clients"])
