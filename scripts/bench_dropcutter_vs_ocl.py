#!/usr/bin/env python3
"""Drop-cutter: brdfmill against OpenCAMLib's BatchDropCutter with a BallCutter, on the same 256² heightfield
(10 µm pitch, 1 mm ball) triangulated, measured in one run on this machine; also prints the CL height
differences. (They are checked, with a derived bound, in `tests/peer_opencamlib_dropcutter.rs` from data
that `scripts/peer_opencamlib_dropcutter.py` writes.)

    python3 -m venv .venv && .venv/bin/pip install opencamlib numpy
    .venv/bin/python scripts/bench_dropcutter_vs_ocl.py
"""
import re
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import opencamlib as ocl

ROOT = Path(__file__).resolve().parent.parent

with tempfile.TemporaryDirectory() as tmp:
    out = subprocess.run(
        ["cargo", "run", "--quiet", "--release", "--example", "bench_dropcutter", "--", "1024", tmp],
        cwd=ROOT, check=True, capture_output=True, text=True,
    ).stdout
    print(out.strip())
    ours_s = float(re.search(r"256x256 open edges: ([0-9.]+) s", out).group(1))
    hf = np.load(Path(tmp) / "hf_256.npy")
    cl_ours = np.load(Path(tmp) / "cl_256.npy")

n, pitch, d = hf.shape[0], 0.01, 1.0
xs = (np.arange(n) + 0.5) * pitch
surf = ocl.STLSurf()
for j in range(n - 1):
    for i in range(n - 1):
        p00 = ocl.Point(xs[i], xs[j], hf[j, i])
        p10 = ocl.Point(xs[i + 1], xs[j], hf[j, i + 1])
        p01 = ocl.Point(xs[i], xs[j + 1], hf[j + 1, i])
        p11 = ocl.Point(xs[i + 1], xs[j + 1], hf[j + 1, i + 1])
        surf.addTriangle(ocl.Triangle(p00, p10, p11))
        surf.addTriangle(ocl.Triangle(p00, p11, p01))
t = time.perf_counter()
bdc = ocl.BatchDropCutter()
bdc.setSTL(surf)
bdc.setCutter(ocl.BallCutter(d, 10.0))
for j in range(n):
    for i in range(n):
        bdc.appendPoint(ocl.CLPoint(xs[i], xs[j], -10.0))
bdc.run()
pts = bdc.getCLPoints()
ocl_s = time.perf_counter() - t
cl_ocl = np.array([p.z for p in pts]).reshape(n, n)
print(f"OpenCAMLib {ocl.version()} BatchDropCutter 256x256, BallCutter d=1 mm, {ocl.max_threads()} threads: {ocl_s:.2f} s")
print(f"ratio (OpenCAMLib / brdfmill) at 256x256: {ocl_s / ours_s:.0f}x")
# Interior points (the ball fully over the surface): brdfmill's point-sampled CL is at most the triangulated
# surface's, and below it by no more than the ball's sag between samples plus facet-edge effects.
m = int(np.ceil(0.5 / pitch)) + 1
diff = cl_ocl[m:-m, m:-m] - cl_ours[m:-m, m:-m]
print(f"CL height difference (OpenCAMLib - brdfmill), interior: min {diff.min()*1e3:.4f} µm, max {diff.max()*1e3:.4f} µm")
