#!/usr/bin/env python3
"""Reference data for `tests/peer_opencamlib_dropcutter.rs`: OpenCAMLib's ball-nose drop-cutter on a small
triangulated heightfield.

The heightfield (`hf.npy`, 48 rows (y) x 64 columns (x), mm, 20 um pitch, samples at ((i + 1/2) p,
(j + 1/2) p) as brdfmill places them) is a sum of sinusoids with four single raised samples (spikes). OpenCAMLib
reports 1486 vertex, 1719 edge and 267 facet contacts. Each grid cell is split into two
triangles along the diagonal from (i, j) to (i + 1, j + 1); OpenCAMLib's BatchDropCutter drops a
BallCutter of diameter 0.5 mm onto them:

`cl.npy` (3472 x 7, mm) has one row per CL point: x, y, CL (tool-tip) z, then OpenCAMLib's contact point
(CC) x, y, z and its type (0 VERTEX, 1 EDGE, 2 FACET; nothing else occurs for a ball on triangles). The
first 48 x 64 rows are the sample positions, row-major (x fastest); the last 400 are pseudo-random
positions inside the samples' hull, off the grid.

Written with Python 3.11.7, NumPy 2.4.6 and opencamlib 2023.1.11 (ocl.version() printed below):

    python3 -m venv /work/venv && /work/venv/bin/pip install numpy==2.4.6 opencamlib==2023.1.11
    /work/venv/bin/python scripts/peer_opencamlib_dropcutter.py tests/data/peers/opencamlib
"""
import sys
from pathlib import Path

import numpy as np
import opencamlib as ocl

NX, NY, PITCH, DIAMETER = 64, 48, 0.02, 0.5


def heightfield():
    i = np.arange(NX)
    j = np.arange(NY)
    x = (i[None, :] + 0.5) * PITCH
    y = (j[:, None] + 0.5) * PITCH
    lx, ly = NX * PITCH, NY * PITCH
    tau = 2 * np.pi
    z = (
        -0.05
        + 0.030 * np.sin(tau * (3 * x / lx + y / ly))
        + 0.020 * np.cos(tau * (2 * y / ly - x / lx))
        + 0.008 * np.sin(tau * 7 * x / lx) * np.cos(tau * 5 * y / ly)
    )
    for (si, sj, dz) in [(12, 10, 0.04), (40, 30, 0.03), (50, 8, 0.05), (25, 36, 0.02)]:
        z[sj, si] += dz
    return np.ascontiguousarray(z)


def surface(z):
    s = ocl.STLSurf()
    xs = (np.arange(NX) + 0.5) * PITCH
    ys = (np.arange(NY) + 0.5) * PITCH
    for j in range(NY - 1):
        for i in range(NX - 1):
            p00 = ocl.Point(xs[i], ys[j], z[j, i])
            p10 = ocl.Point(xs[i + 1], ys[j], z[j, i + 1])
            p01 = ocl.Point(xs[i], ys[j + 1], z[j + 1, i])
            p11 = ocl.Point(xs[i + 1], ys[j + 1], z[j + 1, i + 1])
            s.addTriangle(ocl.Triangle(p00, p10, p11))
            s.addTriangle(ocl.Triangle(p00, p11, p01))
    return s


def drop(s, pts):
    bdc = ocl.BatchDropCutter()
    bdc.setSTL(s)
    bdc.setCutter(ocl.BallCutter(DIAMETER, 10.0))
    for x, y in pts:
        bdc.appendPoint(ocl.CLPoint(float(x), float(y), -10.0))
    bdc.run()
    out = bdc.getCLPoints()
    assert len(out) == len(pts)
    for p, (x, y) in zip(out, pts):
        assert abs(p.x - x) < 1e-12 and abs(p.y - y) < 1e-12, "OpenCAMLib reordered the points"
    kinds = {"VERTEX": 0.0, "EDGE": 1.0, "FACET": 2.0}
    rows = []
    for p in out:
        cc = p.getCC()
        rows.append([p.x, p.y, p.z, cc.x, cc.y, cc.z, kinds[cc.type.name]])
    return np.array(rows)


def main():
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    z = heightfield()
    s = surface(z)
    grid = [((i + 0.5) * PITCH, (j + 0.5) * PITCH) for j in range(NY) for i in range(NX)]
    rng = np.random.default_rng(20240611)
    lo, hi_x, hi_y = 0.5 * PITCH, (NX - 0.5) * PITCH, (NY - 0.5) * PITCH
    pts = [(float(x), float(y)) for x, y in zip(rng.uniform(lo, hi_x, 400), rng.uniform(lo, hi_y, 400))]
    cl = drop(s, grid + pts)
    assert (cl[:, 2] > -1).all(), "a CL point found no triangle"
    np.save(out / "hf.npy", z)
    np.save(out / "cl.npy", np.ascontiguousarray(cl))
    counts = {k: int((cl[:, 6] == v).sum()) for k, v in [("vertex", 0), ("edge", 1), ("facet", 2)]}
    print(f"OpenCAMLib {ocl.version()}: {NX}x{NY} grid, {2 * (NX - 1) * (NY - 1)} triangles, "
          f"{len(grid)} grid CL points, {len(pts)} off-grid; contacts {counts}")


if __name__ == "__main__":
    main()
