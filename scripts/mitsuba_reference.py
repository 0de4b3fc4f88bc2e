#!/usr/bin/env python3
"""Write reference values of Mitsuba 3's `roughconductor` for brdfmill's cross-check test.

    python3 -m venv .venv && .venv/bin/pip install mitsuba numpy
    .venv/bin/python scripts/mitsuba_reference.py > tests/data/mitsuba/roughconductor.csv

Mitsuba's `eval` returns f·cosθo in float32 (variant scalar_rgb), with wi and wo in the local shading frame.
The directions are drawn from a fixed seed so the file is reproducible; CI does not need Mitsuba, the test
`tests/mitsuba_crosscheck.rs` reads this file.
"""
import math
import random
import sys

import mitsuba as mi

mi.set_variant("scalar_rgb")

CONFIGS = [
    # distribution, alpha_u, alpha_v, eta rgb, k rgb
    ("ggx", 0.2, 0.2, (0.2378, 1.0066, 1.2404), (3.6264, 2.5823, 2.3929)),
    ("ggx", 0.1, 0.3, (1.3456, 0.9652, 0.6172), (7.4746, 6.3995, 5.3031)),
    ("ggx", 0.5, 0.5, (1.35, 1.35, 1.35), (7.47, 7.47, 7.47)),
    ("beckmann", 0.3, 0.3, (0.1556, 0.4241, 1.3831), (3.6024, 2.4721, 1.9155)),
    ("beckmann", 0.15, 0.4, (2.9114, 2.9497, 2.5845), (3.0893, 2.9318, 2.7670)),
]


def direction(theta, phi):
    return (math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta))


def main():
    rng = random.Random(20261122)
    out = sys.stdout
    out.write(f"# Mitsuba {mi.__version__} roughconductor, variant scalar_rgb; value = f*cos(theta_o), float32\n")
    out.write("distribution,alpha_u,alpha_v,eta_r,eta_g,eta_b,k_r,k_g,k_b,wi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g,b\n")
    for dist, au, av, eta, k in CONFIGS:
        bsdf = mi.load_dict({
            "type": "roughconductor",
            "distribution": dist,
            "alpha_u": au,
            "alpha_v": av,
            "eta": {"type": "rgb", "value": list(eta)},
            "k": {"type": "rgb", "value": list(k)},
        })
        ctx = mi.BSDFContext()
        for _ in range(60):
            # near-specular pairs most of the time, so values are not all tiny
            ti = math.acos(rng.uniform(0.05, 1.0))
            pi = rng.uniform(-math.pi, math.pi)
            if rng.random() < 0.7:
                to = min(max(ti + rng.gauss(0.0, 0.25), 0.01), 1.5)
                po = pi + math.pi + rng.gauss(0.0, 0.4)
            else:
                to = math.acos(rng.uniform(0.05, 1.0))
                po = rng.uniform(-math.pi, math.pi)
            wi, wo = direction(ti, pi), direction(to, po)
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wi)
            v = bsdf.eval(ctx, si, mi.Vector3f(*wo))
            vals = [float(v[0]), float(v[1]), float(v[2])]
            # directions are written with the float32 values Mitsuba used
            wi32 = [float(x) for x in mi.Vector3f(*wi)]
            wo32 = [float(x) for x in mi.Vector3f(*wo)]
            row = [dist, au, av, *eta, *k, *wi32, *wo32, *vals]
            out.write(",".join(repr(x) if isinstance(x, float) else str(x) for x in row) + "\n")


if __name__ == "__main__":
    main()
