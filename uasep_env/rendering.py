"""Live frames of a running world: :mod:`uasep_env.viz.frames` under its former name.

Kept so that ``from uasep_env.rendering import Renderer`` keeps working; matplotlib is still
imported only when a renderer draws.
"""

from __future__ import annotations

from uasep_env.viz.frames import RENDER_MODES, Renderer, save_frame
from uasep_env.viz.shapes import ellipsoid_points

__all__ = ["RENDER_MODES", "Renderer", "ellipsoid_points", "save_frame"]
