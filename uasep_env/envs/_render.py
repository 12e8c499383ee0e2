"""Rendering shared by the single-world views (matplotlib is imported on first render)."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

__all__ = ["RenderMixin"]


class RenderMixin:
    """``render()`` / ``close()`` for views with ``config``, ``render_mode`` and ``core``."""

    config: Any
    render_mode: str | None
    core: Any
    _renderer: Any = None

    def render(self) -> np.ndarray | None:
        """Render environment 0 with matplotlib: an RGB array or a window."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None
        if self._renderer is None:
            from uasep_env.rendering import Renderer

            self._renderer = Renderer(self.config, mode=self.render_mode)
        return self._renderer.render(self.core.world, env=0)

    def close(self) -> None:
        """Close the renderer, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
