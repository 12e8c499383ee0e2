"""Whether this installation can draw: matplotlib is the optional ``viz`` extra.

The core install (``pip install uasep-env``) has no matplotlib. The environments then declare
no render modes (so ``gymnasium.utils.env_checker.check_env`` does not try them), and asking
for rendering (an env built with a ``render_mode``, a figure) raises one clear error naming
the extra, at once, instead of a bare ``ModuleNotFoundError`` from deep inside the drawing
code or Gymnasium's checker's complaint about an undeclared mode.
"""

from __future__ import annotations

import importlib.util

__all__ = [
    "VIZ_HINT",
    "available_render_modes",
    "checked_render_mode",
    "matplotlib_available",
    "require_matplotlib",
]

#: What to install for rendering and figures.
VIZ_HINT = "pip install 'uasep-env[viz]' (or pip install matplotlib)"


def matplotlib_available() -> bool:
    """Whether matplotlib can be imported (found without importing it)."""
    try:
        return importlib.util.find_spec("matplotlib") is not None
    except (ImportError, ValueError):  # a broken or half-removed installation
        return False


def available_render_modes(modes: tuple[str, ...]) -> list[str]:
    """``modes`` when matplotlib is installed, else none (for an env's ``metadata``)."""
    return list(modes) if matplotlib_available() else []


def require_matplotlib(purpose: str) -> None:
    """Raise a clear ``ModuleNotFoundError`` if matplotlib is missing.

    Args:
        purpose: What needs it, for the message (e.g. ``"render()"``).

    Raises:
        ModuleNotFoundError: Naming ``purpose`` and the ``viz`` extra.
    """
    if not matplotlib_available():
        raise ModuleNotFoundError(
            f"{purpose} needs matplotlib, which is not installed: {VIZ_HINT}", name="matplotlib"
        )


def checked_render_mode(mode: str | None) -> str | None:
    """An env's ``render_mode``, once it is known that it can be drawn.

    Raises:
        ModuleNotFoundError: A render mode without matplotlib (naming the ``viz`` extra).
    """
    if mode is not None:
        require_matplotlib(f"render_mode={mode!r} (render())")
    return mode
