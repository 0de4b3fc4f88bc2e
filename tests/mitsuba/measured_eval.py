"""Evaluate an RGL .bsdf file with Mitsuba 3's `measured` plugin (the peer of tests/rgl_mitsuba.rs).

Usage: measured_eval.py BSDF DIRECTIONS OUT [LIGHT_X LIGHT_Y LIGHT_Z]

DIRECTIONS holds one pair per line, `wi_x,wi_y,wi_z,wo_x,wo_y,wo_z` (unit vectors in the surface's frame,
z the normal). OUT gets one line per pair, `r,g,b`: Mitsuba's `BSDF.eval`, which is f(wi, wo) cos(theta_o).
With a light direction (pointing from the surface to the light), it also renders an 8 x 8 image of a square
of the material seen straight from above by an orthographic camera and lit by a directional light of unit
irradiance from that direction, and appends one line `render,r,g,b`: the image's mean pixel. Uses the
`scalar_rgb` variant (the file is in the RGB form; no LLVM or GPU is needed).
"""

import sys

import mitsuba as mi

mi.set_variant("scalar_rgb")


def main():
    bsdf_path, dirs_path, out_path = sys.argv[1:4]
    bsdf = mi.load_dict({"type": "measured", "filename": bsdf_path})
    ctx = mi.BSDFContext()
    lines = []
    with open(dirs_path) as f:
        for row in f:
            row = row.strip()
            if not row:
                continue
            v = [float(x) for x in row.split(",")]
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(v[0], v[1], v[2])
            value = bsdf.eval(ctx, si, mi.Vector3f(v[3], v[4], v[5]))
            lines.append("%.9g,%.9g,%.9g" % (value[0], value[1], value[2]))
    if len(sys.argv) == 7:
        light = [float(x) for x in sys.argv[4:7]]
        scene = mi.load_dict(
            {
                "type": "scene",
                "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
                "sensor": {
                    "type": "orthographic",
                    "to_world": mi.ScalarTransform4f().look_at(
                        origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]
                    ),
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
        mean = [sum(flat[k::c]) / (h * w) for k in range(3)]
        lines.append("render,%.9g,%.9g,%.9g" % tuple(mean))
    with open(out_path, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
