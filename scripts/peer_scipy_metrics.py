#!/usr/bin/env python3
"""Reference data for `tests/peer_scipy_metrics.rs`: the verdict's distances computed by SciPy and NumPy.

Three pairs of 2D grids (float64, C order, rows = q, columns = p, as brdfmill's slope grids), written as
`tests/data/peers/scipy/<case>_{a,b}.npy`, and SciPy's / NumPy's figures for each pair in
`tests/data/peers/scipy/metrics.json`:

* `smooth`: two anisotropic Gaussians of different widths and centres on 48 x 40 cells;
* `sparse`: random non-negative cells of which about 70% are exactly zero in each grid, independently, so
  that each grid has cells where the other has none (the terms Jensen-Shannon must take as 0 log 0);
* `spiky`: a few tall cells on a faint floor of 1e-9 against a broad lobe (a design of flat facets against
  a smooth measured lobe, the case issue 36 describes).

The figures, each from the peer's own routine (brdfmill's grid `a` is the candidate, `b` the reference):

* `js_bits`: `scipy.spatial.distance.jensenshannon(a, b, base=2) ** 2` (SciPy returns the distance, the
  square root of the divergence; it normalises both arrays to unit sum);
* `l1_rel`: `numpy.abs(a - b).sum() / numpy.abs(b).sum()`;
* `corr`: `numpy.corrcoef(a.ravel(), b.ravel())[0, 1]`;
* `var_p`, `var_q`: the variance of the cell centres' p (and q) under the weights `b`:
  `numpy.cov(x, aweights=b, ddof=0)`, the centres `p_i = (i + 1/2) / nx * 2 - 1` (q alike, on [-1, 1]).

Written with Python 3.11.7, NumPy and SciPy as printed into metrics.json:

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy scipy
    /tmp/venv/bin/python scripts/peer_scipy_metrics.py tests/data/peers/scipy
"""
import json
import sys
from pathlib import Path

import numpy as np
import scipy
from scipy.spatial.distance import jensenshannon


def grids(nx, ny):
    p = (np.arange(nx) + 0.5) / nx * 2.0 - 1.0
    q = (np.arange(ny) + 0.5) / ny * 2.0 - 1.0
    return np.meshgrid(p, q)  # P[j, i] = p_i, Q[j, i] = q_j


def cases():
    rng = np.random.default_rng(36)
    P, Q = grids(48, 40)
    a = np.exp(-((P - 0.05) ** 2) / 0.08 - (Q + 0.02) ** 2 / 0.03)
    b = np.exp(-(P**2) / 0.06 - Q**2 / 0.05)
    yield "smooth", a, b
    P, Q = grids(32, 32)
    a = rng.random((32, 32)) * (rng.random((32, 32)) > 0.7)
    b = rng.random((32, 32)) * (rng.random((32, 32)) > 0.7)
    yield "sparse", a, b
    P, Q = grids(40, 40)
    a = np.full((40, 40), 1e-9)
    for _ in range(12):
        a[rng.integers(8, 32), rng.integers(8, 32)] += rng.random() + 0.5
    b = np.exp(-(P**2 + Q**2) / 0.1) + 0.02 / (1.0 + (P**2 + Q**2) / 0.01)
    yield "spiky", a, b


def main(out):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    record = {"numpy": np.__version__, "scipy": scipy.__version__, "cases": {}}
    for name, a, b in cases():
        np.save(out / f"{name}_a.npy", np.ascontiguousarray(a, dtype=np.float64))
        np.save(out / f"{name}_b.npy", np.ascontiguousarray(b, dtype=np.float64))
        P, Q = grids(a.shape[1], a.shape[0])
        record["cases"][name] = {
            "js_bits": float(jensenshannon(a.ravel(), b.ravel(), base=2) ** 2),
            "l1_rel": float(np.abs(a - b).sum() / np.abs(b).sum()),
            "corr": float(np.corrcoef(a.ravel(), b.ravel())[0, 1]),
            "var_p": float(np.cov(P.ravel(), aweights=b.ravel(), ddof=0)),
            "var_q": float(np.cov(Q.ravel(), aweights=b.ravel(), ddof=0)),
        }
    (out / "metrics.json").write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tests/data/peers/scipy")
