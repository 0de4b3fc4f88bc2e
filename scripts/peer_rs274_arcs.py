#!/usr/bin/python3
"""Reference data for `tests/peer_rs274_arcs.rs`: the arcs LinuxCNC's G-code interpreter makes of a program.

LinuxCNC's RS274/NGC interpreter (the library behind `rs274`, Debian package linuxcnc-uspace) emits one
ARC_FEED canonical command per G2/G3 block: end point, centre, rotation (sign: + counter-clockwise,
- clockwise; magnitude: 1 + the number of extra full turns, i.e. P) and the end of the helical axis. The
`rs274` program prints these with 4 decimals in the program's units; LinuxCNC's Python binding of the same
interpreter (`gcode.parse`, used by its AXIS preview) hands them over as doubles, in inches. This script
takes the doubles, tracks every motion's end point so each arc also gets its start, and checks that every
record rounds to what `rs274 -g` prints (so the two front ends agree and the units are understood).

Output CSV (inches, as the interpreter gives them): line, rotation, x0, y0, z0 (start), x1, y1, z1 (end),
cx, cy (centre). The header names the program's MD5 and the LinuxCNC version.

Run with the system Python, which has LinuxCNC's `gcode` module (Debian 12, linuxcnc-uspace
2.9.0~pre1+git20230208.f1270d6ed7-1+deb12u2, Python 3.11.2):

    apt-get install -y linuxcnc-uspace
    /usr/bin/python3 scripts/peer_rs274_arcs.py /usr/share/linuxcnc/ncfiles/arcspiral.ngc \\
        tests/data/peers/rs274/arcspiral_arcs.csv
    /usr/bin/python3 scripts/peer_rs274_arcs.py tests/data/peers/rs274/arcs_mixed.ngc \\
        tests/data/peers/rs274/arcs_mixed_arcs.csv
"""
import hashlib
import os
import re
import subprocess
import sys
import tempfile

import gcode  # LinuxCNC's interpreter, /usr/lib/python3/dist-packages/gcode.*.so

EMPTY_TOOL = (-1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0)


class Canon:
    """The callbacks the interpreter makes; motions are recorded, everything else ignored."""

    def __init__(self, parameter_file):
        self.parameter_file = parameter_file
        self.line = 0
        self.pos = (0.0, 0.0, 0.0)
        self.arcs = []

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *args: None

    def get_external_angular_units(self):
        return 1.0

    def get_external_length_units(self):
        return 1.0

    def get_axis_mask(self):
        return 7  # X Y Z

    def get_block_delete(self):
        return False

    def get_tool(self, idx):
        return EMPTY_TOOL

    def next_line(self, state):
        self.line = state.sequence_number

    def straight_traverse(self, x, y, z, *rest):
        self.pos = (x, y, z)

    def straight_feed(self, x, y, z, *rest):
        self.pos = (x, y, z)

    def arc_feed(self, x1, y1, cx, cy, rot, z1, *rest):
        self.arcs.append((self.line, rot) + self.pos + (x1, y1, z1, cx, cy))
        self.pos = (x1, y1, z1)


def rs274_records(path):
    """(rotation, x1, y1, cx, cy, z1, units) of each ARC_FEED that `rs274 -g` prints."""
    out = subprocess.run(["rs274", "-g", path], capture_output=True, text=True, check=True).stdout
    units, recs = None, []
    for line in out.splitlines():
        m = re.search(r"USE_LENGTH_UNITS\(CANON_UNITS_(\w+)\)", line)
        if m:
            units = m.group(1)
        m = re.search(r"ARC_FEED\(([^)]*)\)", line)
        if m:
            v = [float(t) for t in m.group(1).split(",")]
            recs.append((v[4], v[0], v[1], v[2], v[3], v[5], units))
    return recs


def linuxcnc_version():
    try:
        return subprocess.run(
            ["dpkg-query", "-W", "-f=${Version}", "linuxcnc-uspace"], capture_output=True, text=True
        ).stdout.strip()
    except OSError:
        return "unknown"


def main():
    src, dst = sys.argv[1], sys.argv[2]
    with tempfile.TemporaryDirectory() as tmp:
        canon = Canon(os.path.join(tmp, "rs274.var"))
        result, _ = gcode.parse(src, canon, ["G20", "G90"], "")
    if result > gcode.MIN_ERROR:
        sys.exit(f"{src}: the interpreter stopped with error {result}")
    theirs = rs274_records(src)
    assert len(theirs) == len(canon.arcs), f"rs274 printed {len(theirs)} arcs, the binding gave {len(canon.arcs)}"
    for a, (rot, x1, y1, cx, cy, z1, units) in zip(canon.arcs, theirs):
        f = 25.4 if units == "MM" else 1.0
        assert a[1] == rot, (a, rot)
        for ours, printed in [(a[5], x1), (a[6], y1), (a[8], cx), (a[9], cy), (a[7], z1)]:
            assert abs(ours * f - printed) <= 0.5e-4 + 1e-9, (a, ours * f, printed)
    with open(src, "rb") as fh:
        md5 = hashlib.md5(fh.read()).hexdigest()
    with open(dst, "w") as out:
        out.write(f"# {len(canon.arcs)} ARC_FEED records of {os.path.basename(src)} (md5 {md5}), inches,\n")
        out.write(f"# LinuxCNC {linuxcnc_version()} rs274ngc interpreter via its Python binding gcode.parse;\n")
        out.write("# each rounds to `rs274 -g`'s printed record. Written by scripts/peer_rs274_arcs.py.\n")
        out.write("line,rotation,x0,y0,z0,x1,y1,z1,cx,cy\n")
        for a in canon.arcs:
            out.write(",".join([str(a[0]), str(a[1])] + [repr(float(v)) for v in a[2:]]) + "\n")
    print(f"{dst}: {len(canon.arcs)} arcs from {src} (md5 {md5})")


if __name__ == "__main__":
    main()
