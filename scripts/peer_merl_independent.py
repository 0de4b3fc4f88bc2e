#!/usr/bin/env python3
"""An independently written MERL `.binary` file for `tests/merl_independent.rs`.

Written from the published layout of the MERL BRDF database (Matusik, Pfister, Brand & McMillan 2003, the
sample reader `BRDFRead.cpp` distributed with the database), not from brdfmill's reader or writer:

* header: three little-endian int32, the table's dimensions 90 (theta_h), 90 (theta_d), 180 (phi_d);
* then 3 x 90*90*180 little-endian float64: all red values, then all green, then all blue; within a channel
  the index is  phi_d_index + 180 * theta_d_index + 180 * 90 * theta_h_index;
* the stored numbers are the BRDF divided by the channel scale 1/1500 (red), 1.15/1500 (green),
  1.66/1500 (blue): a reader multiplies by the scale;
* theta_h_index = floor(90 * sqrt(theta_h / (pi/2)))  (the non-linear theta_h axis),
  theta_d_index = floor(90 * theta_d / (pi/2)),
  phi_d_index   = floor(180 * phi_d / pi), phi_d in [0, pi) (phi_d + pi is folded by reciprocity),
  each clamped to the table.

Each bin holds the closed form below evaluated at the bin's centre in index space (theta_h at
((i + 1/2) / 90)^2 * pi/2, theta_d at (j + 1/2) / 90 * pi/2, phi_d at (k + 1/2) / 180 * pi). Each channel
depends on one coordinate only, so the 35 MB table is a few long runs and deflates to 164 kB:

    red(theta_h)   = 0.05 + 0.8 cos(theta_h)^4
    green(theta_d) = 0.3 + 0.2 cos(theta_d)
    blue(phi_d)    = 0.4 + 0.15 cos(2 phi_d) + 0.05 sin(2 phi_d)

(blue is not symmetric about phi_d = pi/2, so a reader that mirrors phi_d instead of folding it by pi is
seen.) The test evaluates the same closed forms in Rust.

Written with Python 3.11.7 and NumPy 2.4.6 (only the standard library's zipfile besides NumPy):

    python3 -m venv /work/venv && /work/venv/bin/pip install numpy==2.4.6
    /work/venv/bin/python scripts/peer_merl_independent.py tests/data/peers/merl/independent.binary.zip
"""
import sys
import zipfile
from pathlib import Path

import numpy as np

NH, ND, NP = 90, 90, 180
SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)


def red(theta_h):
    return 0.05 + 0.8 * np.cos(theta_h) ** 4


def green(theta_d):
    return 0.3 + 0.2 * np.cos(theta_d)


def blue(phi_d):
    return 0.4 + 0.15 * np.cos(2 * phi_d) + 0.05 * np.sin(2 * phi_d)


def table():
    th = ((np.arange(NH) + 0.5) / NH) ** 2 * (np.pi / 2)
    td = (np.arange(ND) + 0.5) / ND * (np.pi / 2)
    pd = (np.arange(NP) + 0.5) / NP * np.pi
    # shape (theta_h, theta_d, phi_d), C order: phi_d fastest, theta_h slowest, as the index above
    ones = np.ones((NH, ND, NP))
    r = red(th)[:, None, None] * ones
    g = green(td)[None, :, None] * ones
    b = blue(pd)[None, None, :] * ones
    return [c / s for c, s in zip((r, g, b), SCALE)]


def main():
    out = Path(sys.argv[1])
    out.parent.mkdir(parents=True, exist_ok=True)
    header = np.array([NH, ND, NP], dtype="<i4").tobytes()
    body = b"".join(np.ascontiguousarray(c, dtype="<f8").tobytes() for c in table())
    assert len(body) == 3 * NH * ND * NP * 8
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        info = zipfile.ZipInfo("independent.binary", date_time=(2024, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        z.writestr(info, header + body, compresslevel=9)
    print(f"{out}: {out.stat().st_size} bytes (MERL table {len(header) + len(body)} bytes)")


if __name__ == "__main__":
    main()
