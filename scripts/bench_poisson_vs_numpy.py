#!/usr/bin/env python3
"""Periodic Poisson integration: brdfmill's planned FFT solver against NumPy's FFT Frankot–Chellappa on the
same gradient fields (1024² and 2048²), measured in one run on this machine.

    python3 -m venv .venv && .venv/bin/pip install numpy
    .venv/bin/python scripts/bench_poisson_vs_numpy.py
"""
import re
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RUNS = 5


def frankot_chellappa(gx, gy):
    """z from gradients by the FFT (Frankot & Chellappa 1988): ẑ = -i(ωx Ĝx + ωy Ĝy)/(ωx² + ωy²)."""
    ny, nx = gx.shape
    wx = 2 * np.pi * np.fft.fftfreq(nx)[None, :]
    wy = 2 * np.pi * np.fft.fftfreq(ny)[:, None]
    denom = wx**2 + wy**2
    denom[0, 0] = 1.0
    z = (-1j * wx * np.fft.fft2(gx) - 1j * wy * np.fft.fft2(gy)) / denom
    z[0, 0] = 0.0
    return np.real(np.fft.ifft2(z))


with tempfile.TemporaryDirectory() as tmp:
    out = subprocess.run(
        ["cargo", "run", "--quiet", "--release", "--example", "bench_poisson", "--", str(RUNS), tmp],
        cwd=ROOT, check=True, capture_output=True, text=True,
    ).stdout
    print(out.strip())
    ours = {int(m.group(1)): float(m.group(2)) for m in re.finditer(r"poisson (\d+)x\d+: median ([0-9.]+) ms", out)}
    for n in (1024, 2048):
        gx = np.load(Path(tmp) / f"gx_{n}.npy")
        gy = np.load(Path(tmp) / f"gy_{n}.npy")
        times = []
        for _ in range(RUNS):
            t = time.perf_counter()
            frankot_chellappa(gx, gy)
            times.append(time.perf_counter() - t)
        ms = sorted(times)[len(times) // 2] * 1e3
        print(f"numpy {np.__version__} Frankot-Chellappa {n}x{n}: median {ms:.1f} ms/solve")
        print(f"ratio (numpy / brdfmill) at {n}x{n}: {ms / ours[n]:.2f}x")
