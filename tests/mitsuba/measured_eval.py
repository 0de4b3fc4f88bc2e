"""Evaluate an RGL .bsdf file with Mitsuba 3's `measured` plugin (the peer of tests/rgl_mitsuba.rs).

Usage: measured_eval.py BSDF DIRECTIONS OUT [--light X Y Z] [--albedo X Y Z N]...

DIRECTIONS holds one pair per line, `wi_x,wi_y,wi_z,wo_x,wo_y,wo_z` (unit vectors in the surface's frame,
z the normal). OUT gets one line per pair, `r,g,b`: Mitsuba's `BSDF.eval`, which is f(wi, wo) cos(theta_o).

--light: render an 8 x 8 image of a square of the material seen straight from above by an orthographic
camera, lit by a directional light of unit irradiance from that direction (pointing from the surface to the
light), and append `render,r,g,b`: the image's mean pixel.

--albedo: draw N directions with Mitsuba's own `BSDF.sample` at incident direction (X, Y, Z) on a
stratified grid of sample points, and append `albedo,r,g,b,pdf`: the mean sample weight (the directional
albedo, integral of f cos(theta_o) over the hemisphere, by Mitsuba's importance sampling) and the largest
relative difference between the pdf a sample reports and `BSDF.pdf` of its direction.

Uses the `scalar_rgb` variant (the file is in the RGB form; no LLVM or GPU is needed).
"""

import argparse
import math

import mitsuba as mi

mi.set_variant("scalar_rgb")


def render(bsdf_path, light):
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
            "sensor": {
                "type": "orthographic",
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {
                    "type": "hdrfilm",
                    "width": 8,
                    "height": 8,
                    "pixel_format": "rgb",
                    "rfilter": {"type": "box"},
                },
                "sampler": {"type": "independent", "sample_count": 4},
            },
            "square": {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f().scale([10, 10, 1]),
                "bsdf": {"type": "measured", "filename": bsdf_path},
            },
            "light": {
                "type": "directional",
                "direction": [-light[0], -light[1], -light[2]],
                "irradiance": {"type": "rgb", "value": 1.0},
            },
        }
    )
    image = mi.render(scene)
    h, w, c = image.shape
    flat = list(image.array)
    return [sum(flat[k::c]) / (h * w) for k in range(3)]


def albedo(bsdf, wi, n):
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*wi)
    side = int(math.sqrt(n))
    total = [0.0, 0.0, 0.0]
    worst = 0.0
    for a in range(side):
        for b in range(side):
            s2 = mi.Point2f((a + 0.5) / side, (b + 0.5) / side)
            bs, weight = bsdf.sample(ctx, si, 0.5, s2)
            if bs.pdf > 0 and bs.wo.z > 0:
                for k in range(3):
                    total[k] += weight[k]
                pdf = bsdf.pdf(ctx, si, bs.wo)
                worst = max(worst, abs(pdf - bs.pdf) / bs.pdf)
    return [t / (side * side) for t in total], worst


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bsdf")
    ap.add_argument("directions")
    ap.add_argument("out")
    ap.add_argument("--light", nargs=3, type=float)
    ap.add_argument("--albedo", nargs=4, type=float, action="append", default=[])
    args = ap.parse_args()
    bsdf = mi.load_dict({"type": "measured", "filename": args.bsdf})
    ctx = mi.BSDFContext()
    lines = []
    with open(args.directions) as f:
        for row in f:
            row = row.strip()
            if not row:
                continue
            v = [float(x) for x in row.split(",")]
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(v[0], v[1], v[2])
            value = bsdf.eval(ctx, si, mi.Vector3f(v[3], v[4], v[5]))
            lines.append("%.9g,%.9g,%.9g" % (value[0], value[1], value[2]))
    if args.light:
        lines.append("render,%.9g,%.9g,%.9g" % tuple(render(args.bsdf, args.light)))
    for a in args.albedo:
        mean, worst = albedo(bsdf, a[:3], int(a[3]))
        lines.append("albedo,%.9g,%.9g,%.9g,%.9g" % (mean[0], mean[1], mean[2], worst))
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
