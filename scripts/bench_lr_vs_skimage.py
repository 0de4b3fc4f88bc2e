#!/usr/bin/env python3
"""Lucy–Richardson: brdfmill against scikit-image's `richardson_lucy`, same grid, kernel and iteration count,
measured in one run on this machine. (The results are compared, cell by cell, in
`tests/peer_skimage_lr.rs` from data that `scripts/peer_skimage_lr.py` writes.)

    python3 -m venv .venv && .venv/bin/pip install scikit-image numpy
    .venv/bin/python scripts/bench_lr_vs_skimage.py
"""
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import skimage
from skimage.restoration import richardson_lucy

ROOT = Path(__file__).resolve().parent.parent
RUNS = 10

with tempfile.TemporaryDirectory() as tmp:
    out = subprocess.run(
        ["cargo", "run", "--quiet", "--release", "--example", "bench_lucy_richardson", "--", str(RUNS), tmp],
        cwd=ROOT, check=True, capture_output=True, text=True,
    ).stdout
    print(out.strip())
    ours_ms = float(re.search(r"median ([0-9.]+) ms/run", out).group(1))
    observed = np.load(Path(tmp) / "observed.npy")
    kernel = np.load(Path(tmp) / "kernel.npy")

kernel = kernel / kernel.sum()
times = []
for _ in range(RUNS):
    t = time.perf_counter()
    richardson_lucy(observed, kernel, num_iter=100, clip=False)
    times.append(time.perf_counter() - t)
sk_ms = sorted(times)[len(times) // 2] * 1e3
print(f"scikit-image {skimage.__version__} richardson_lucy, same arrays, 100 iterations: median {sk_ms:.1f} ms/run")
print(f"ratio (scikit-image / brdfmill): {sk_ms / ours_ms:.2f}x")
sys.exit(0)
