"""What every env view shares: its world, and rendering it (matplotlib imported on first render)."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium.error import ClosedEnvironmentError

from uasep_env.viz.requirements import require_matplotlib

__all__ = ["ViewMixin"]


class ViewMixin:
    """``world``, ``render()`` and ``close()`` for views with ``render_mode`` and ``core``."""

    render_mode: str | None
    core: Any
    _renderer: Any = None
    _closed: bool = False

    @property
    def world(self) -> Any:
        """The underlying batched :class:`~uasep_env.sim.world.World` (``core.world``)."""
        return self.core.world

    def render(self) -> np.ndarray | None:
        """Render environment 0 with matplotlib: an RGB array or a window.

        Raises:
            ModuleNotFoundError: Without matplotlib, naming the ``viz`` extra.
        """
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None
        if self._renderer is None:
            require_matplotlib(f"render() (render_mode={self.render_mode!r})")
            from uasep_env.viz.frames import Renderer

            self._renderer = Renderer(mode=self.render_mode)
        return self._renderer.render(self.core.world, env=0)

    def close_renderer(self) -> None:
        """Close the renderer, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def close(self) -> None:
        """Close the renderer, if any; later ``reset``/``step`` calls raise (Gymnasium's rule).

        Closing twice is harmless.
        """
        self.close_renderer()
        self._closed = True

    def check_open(self, method: str) -> None:
        """Raise ``ClosedEnvironmentError`` if :meth:`close` was called.

        Raises:
            gymnasium.error.ClosedEnvironmentError: The environment is closed.
        """
        if self._closed or getattr(self, "closed", False):  # the vector API's own flag
            raise ClosedEnvironmentError(
                f"{type(self).__name__}.{method}() called after close(); create a new environment"
            )
