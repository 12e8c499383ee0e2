"""Reachable sets of non-cooperative obstacles and the ellipses/ellipsoids that enclose them.

Paper section 3.1 (eqs. 8-18) with the errata of ``notes.md`` ("Obstacle reachable set").
Units: metres, seconds, radians, m/s throughout. The derivation (the sets S1..S5, the
support functions, the enclosure certificate, the distance solver) is in
``docs/reachable_sets.md``.

* :mod:`~uasep_env.reachable.sets` -- the 2D sets: front curve, support functions, boundaries;
* :mod:`~uasep_env.reachable.fit` -- the heading-aligned ellipse (certified to enclose, or the
  paper's eq. 17) and the ellipsoid (eq. 18, corrected), steered by a shipped shape table;
* :mod:`~uasep_env.reachable.optimal` -- the reference minimum-area ellipse the table holds
  (``tools/build_reachable_table.py`` rebuilds the table);
* :mod:`~uasep_env.reachable.distance` -- signed point-to-ellipsoid distances, nearest points
  and normals (compiled with numba when available).
* :mod:`~uasep_env.reachable.calibrated` -- ``prediction.fit="calibrated"``: regions of the
  same form sized by split conformal prediction per aircraft class, read from a shipped table
  (``tools/build_prediction_calibration.py`` rebuilds it).

Frames for ellipsoids: world NED (x north, y east, z down); heading ``psi`` from north towards
east; the body frame has axis 0 along the heading, axis 1 to the right (``psi + pi/2``) and
axis 2 down. ``semi_axes[..., :]`` is ordered (longitudinal, lateral, vertical).
"""

from __future__ import annotations

from uasep_env.reachable.distance import (
    contains,
    distance_to_ellipsoid,
    nearest_point_on_ellipsoid,
    pairwise_distances,
    region_distances,
)
from uasep_env.reachable.fit import ellipse, ellipsoid
from uasep_env.reachable.sets import boundary, front_curve, support

__all__ = [
    "boundary",
    "contains",
    "distance_to_ellipsoid",
    "ellipse",
    "ellipsoid",
    "front_curve",
    "nearest_point_on_ellipsoid",
    "pairwise_distances",
    "region_distances",
    "support",
]
