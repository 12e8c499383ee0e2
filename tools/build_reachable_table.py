"""Rebuild the shape table of the enclosing ellipse (``uasep_env/data/ellipse_table.npz``).

Usage: ``python tools/build_reachable_table.py [--out PATH]`` (about a minute per set).

The table holds the minimum-area enclosing ellipse's centre ``c`` and longitudinal semi-axis
``B`` as fractions of the set's extent along the heading (``c`` from the back end), and its
lateral semi-axis ``A`` as a fraction of the set's half-width, for the swept (``s``) and the
terminal (``t``) set, on the grid the shipped table uses (read from it): ``u`` (``al``) and
``log10`` radius (``lr``); see :mod:`uasep_env.reachable.fit`. It only steers the fit
towards the minimum area: whatever it holds, the fitted ellipse passes the enclosure
certificate. A rebuild with the defaults matches the shipped table to 1.5e-7.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import numpy as np

from uasep_env.reachable.optimal import optimal_shape
from uasep_env.reachable.sets import FloatArray, _h_unit
from uasep_env.reachable.shape_table import _load_table
from uasep_env.runtime.atomic import atomic_write

TABLE = Path(__file__).resolve().parents[1] / "uasep_env" / "data" / "ellipse_table.npz"


def build_table(swept: bool, u: FloatArray, logr: FloatArray, **kwargs: int) -> FloatArray:
    """Shape table ``(len(u), len(logr), 3)``: (c, B) over the y-extent, A over max |x|."""
    al, lr = np.meshgrid(np.asarray(u) ** 2, logr, indexing="ij")
    rad = 10.0**lr
    phi = np.where(al >= 1.0, 0.0, rad * np.cos(0.5 * np.pi * al))
    eps = 0.5 * rad * np.sin(0.5 * np.pi * al)
    kappa = eps / (1.0 + eps)
    c, lat, lon = optimal_shape(phi, kappa, swept, **kwargs)
    h0 = kappa + (1.0 - kappa) * _h_unit(np.zeros_like(phi), phi, swept)
    hpi = kappa + (1.0 - kappa) * _h_unit(np.full_like(phi, np.pi), phi, swept)
    hx = kappa + (1.0 - kappa) * _h_unit(np.full_like(phi, 0.5 * np.pi), phi, swept)
    ext = h0 + hpi
    return np.stack([(c + hpi) / ext, lon / ext, lat / np.maximum(hx, 1e-300)], axis=-1)


def main() -> None:
    """Compute both tables on the shipped grid and write them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=TABLE)
    args = parser.parse_args()
    u, logr, _ = _load_table()
    tables = {key: build_table(swept, u, logr) for key, swept in (("s", True), ("t", False))}
    buf = io.BytesIO()
    np.savez(buf, al=u, lr=logr, **tables)
    atomic_write(args.out, buf.getvalue())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
