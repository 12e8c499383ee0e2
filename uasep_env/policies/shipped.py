"""The policies that ship with the package, by name (``"ppo_shared"``, ``"ppo_residual_apf"``).

Their source is the repository's ``baselines/checkpoints/*.zip`` (where training writes
them). A wheel carries them as package data, ``uasep_env/checkpoints/*.zip``, copied from
there when the wheel is built (``setup.py``); a source checkout or an editable install reads
them from ``baselines/checkpoints/`` directly. Either way there is one copy in the repository.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["shipped_policies", "shipped_policy_path"]

_PACKAGE = Path(__file__).resolve().parents[1]  # .../uasep_env
#: Where the shipped checkpoints are looked for: the installed package's data, then the
#: repository's folder (a source checkout).
SEARCH_PATH = (_PACKAGE / "checkpoints", _PACKAGE.parent / "baselines" / "checkpoints")


def _folder() -> Path | None:
    for folder in SEARCH_PATH:
        if any(folder.glob("*.zip")):
            return folder
    return None


def shipped_policies() -> dict[str, Path]:
    """``name -> checkpoint path`` of every shipped policy (empty if none is found)."""
    folder = _folder()
    return {} if folder is None else {p.stem: p for p in sorted(folder.glob("*.zip"))}


def shipped_policy_path(name: str) -> Path | None:
    """The checkpoint of the shipped policy called ``name``, or None if there is none."""
    if not isinstance(name, str) or not name or "/" in name or "\\" in name:
        return None
    return shipped_policies().get(name)
