"""The enclosure certificate of the heading-aligned ellipse, and the least axes that pass it.

An ellipse ``(c, A, B)`` encloses the reachable set plus its radius when its support exceeds
the set's at a set of nodes on ``[0, pi]`` by margins that bound what happens between them
(derived in ``docs/reachable_sets.md``). :mod:`uasep_env.reachable.fit` fits its axes with
:func:`_axes_for` and checks them with :func:`_certified`; the compiled ``fit_ellipse``
(:mod:`uasep_env._kernels.ellipse_fit`) does the same row by row.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from uasep_env.reachable.sets import FloatArray, _h_unit_of


class _Nodes:
    """Certificate nodes on ``[0, pi]`` with their trigonometry and the set's support there.

    ``cos``/``sin``: the nodes' cosines and sines (numpy's, as the fit's kernel gets them);
    ``factors``: :func:`_unit_factors` of ``phi``.
    """

    def __init__(
        self,
        th: FloatArray,
        vt: FloatArray,
        phi: FloatArray,
        r: FloatArray,
        swept: bool,
        cos: FloatArray,
        sin: FloatArray,
        factors: tuple[FloatArray, FloatArray, FloatArray],
    ) -> None:
        self.th = th
        self.cos = cos
        self.c2 = cos**2
        self.s2 = sin**2
        self.d2 = np.diff(th, axis=-1) ** 2 / 8.0
        ip, omc, sc = factors
        unit = _h_unit_of(
            th, sin, cos, phi[..., None], ip[..., None], omc[..., None], sc[..., None], swept
        )
        self.h = r[..., None] + vt[..., None] * unit
        self.cos_in = self.cos[..., 1:-1]
        self.c2_in = self.c2[..., 1:-1]
        self.inv_s2_in = 1.0 / self.s2[..., 1:-1]

    def take(self, idx: NDArray[np.intp]) -> _Nodes:
        """The nodes of the rows ``idx``."""
        sub = object.__new__(_Nodes)
        for name in ("th", "cos", "c2", "s2", "d2", "h", "cos_in", "c2_in", "inv_s2_in"):
            setattr(sub, name, getattr(self, name)[idx])
        return sub


def _margins(
    nd: _Nodes, lat: FloatArray, lon: FloatArray, r: FloatArray, eps_abs: FloatArray
) -> FloatArray:
    """Certificate margins ``max(max rho_E - r, 0) Delta^2 / 8`` at the nodes, ``(..., K)``."""
    a2 = (lat * lat)[..., None]
    b2 = (lon * lon)[..., None]
    den = a2 * nd.s2
    den += b2 * nd.c2
    np.maximum(den, 1e-300, out=den)
    rho = np.sqrt(den)
    rho *= den
    np.divide(a2 * b2, rho, out=rho)  # radius of curvature of the ellipse at the nodes
    m_int = np.maximum(rho[..., 1:], rho[..., :-1])
    m_int -= r[..., None]
    np.maximum(m_int, 0.0, out=m_int)
    m_int *= nd.d2
    out = rho
    out[..., 0] = m_int[..., 0]
    out[..., -1] = m_int[..., -1]
    np.maximum(m_int[..., 1:], m_int[..., :-1], out=out[..., 1:-1])
    out += eps_abs[..., None]
    return out


def _axes_for(
    nd: _Nodes, delta: FloatArray, c: FloatArray, lon: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Least axes ``(A, B >= lon)`` with ``h_E(theta_k) >= h_k + delta_k`` at every node.

    ``B`` only grows (to meet the tip constraints at 0 and pi); ``A`` is the least value with
    ``c cos theta_k + sqrt(A^2 sin^2 + B^2 cos^2) >= h_k + delta_k`` at the inner nodes.
    """
    h = nd.h
    lon = np.maximum(lon, h[..., 0] + delta[..., 0] - c)
    lon = np.maximum(lon, h[..., -1] + delta[..., -1] + c)
    need = c[..., None] * nd.cos_in
    np.subtract(h[..., 1:-1], need, out=need)
    need += delta[..., 1:-1]
    np.maximum(need, 0.0, out=need)
    need *= need
    need -= (lon * lon)[..., None] * nd.c2_in
    need *= nd.inv_s2_in
    return np.sqrt(np.maximum(np.max(need, axis=-1), 0.0)), lon


def _certified(
    nd: _Nodes,
    c: FloatArray,
    lat: FloatArray,
    lon: FloatArray,
    r: FloatArray,
    eps_abs: FloatArray,
) -> NDArray[np.bool_]:
    """Whether ``(c, A, B)`` passes the enclosure certificate (``docs/reachable_sets.md``)."""
    delta = _margins(nd, lat, lon, r, eps_abs)
    he = c[..., None] * nd.cos + np.sqrt(
        (lat * lat)[..., None] * nd.s2 + (lon * lon)[..., None] * nd.c2
    )
    return np.all(he - nd.h >= delta, axis=-1)
