"""The shape table that steers the enclosing ellipse fit towards the minimum area.

:mod:`uasep_env.reachable.fit` starts its search from here; whatever the table holds, the
returned ellipse passes the enclosure certificate (:mod:`uasep_env.reachable.certificate`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uasep_env.reachable.sets import FloatArray


# Shape table (``data/ellipse_table.npz``): the minimum-area enclosing ellipse's centre c and
# longitudinal semi-axis B as fractions of the set's extent along the heading (c from the back
# end), and its lateral semi-axis A as a fraction of the set's half-width, for the swept ("s")
# and the terminal ("t") set, on a grid of u = sqrt((2/pi) atan2(2 r / (v t), phi)) ("al";
# 0: r = 0, 1: phi = 0; 33 nodes) and log10(hypot(phi, 2 r / (v t))) ("lr"; -3..3, 49 nodes).
# Made by ``tools/build_reachable_table.py`` (about a minute). It only steers the fit towards the
# minimum area: whatever it holds, the returned ellipse passes the enclosure certificate.
def _load_table() -> tuple[FloatArray, FloatArray, dict[bool, FloatArray]]:
    """The shipped shape table: ``(u nodes, log10 radius nodes, {swept: (33, 49, 3)})``."""
    path = Path(__file__).parents[1] / "data" / "ellipse_table.npz"
    with np.load(path) as data:
        return (
            np.asarray(data["al"], dtype=np.float64),
            np.asarray(data["lr"], dtype=np.float64),
            {True: np.asarray(data["s"], np.float64), False: np.asarray(data["t"], np.float64)},
        )


_TAB_U, _TAB_LOGR, _TAB = _load_table()


def _corners(tab: FloatArray) -> FloatArray:
    """``(na - 1, nl - 1, 4, 3)``: each cell's four corners, in the order of the interpolation."""
    return np.stack([tab[:-1, :-1], tab[1:, :-1], tab[:-1, 1:], tab[1:, 1:]], axis=2)


# One gather of a cell's four corners instead of four (a partial reset fits a few rows).
_CORNERS = {swept: _corners(tab) for swept, tab in _TAB.items()}


def _interp_table(swept: bool, u: FloatArray, logr: FloatArray) -> FloatArray:
    """Bilinear interpolation of the shape table, ``(..., 3)`` = (c, B, A) fractions."""
    na, nl = _TAB[swept].shape[:2]
    fa = np.clip((u - _TAB_U[0]) / (_TAB_U[1] - _TAB_U[0]), 0.0, na - 1.0)
    fl = np.clip((logr - _TAB_LOGR[0]) / (_TAB_LOGR[1] - _TAB_LOGR[0]), 0.0, nl - 1.0)
    fl = np.where(np.isnan(fl), 0.0, fl)
    i0 = np.minimum(fa.astype(np.intp), na - 2)
    j0 = np.minimum(fl.astype(np.intp), nl - 2)
    ta = (fa - i0)[..., None]
    tl = (fl - j0)[..., None]
    ua, ul = 1 - ta, 1 - tl
    k = _CORNERS[swept][i0, j0]
    return (
        k[..., 0, :] * ua * ul
        + k[..., 1, :] * ta * ul
        + k[..., 2, :] * ua * tl
        + k[..., 3, :] * ta * tl
    )
