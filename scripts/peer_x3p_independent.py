#!/usr/bin/env python3
"""X3P files that brdfmill did not write, for `tests/x3p_independent.rs`.

The surface (metres) is z(x, y) = -5e-7 + 2e-6 sin(2 pi 1.5 x / Lx) cos(2 pi y / Ly) + 3e-7 x / Lx on a
40 x 24 grid (x fastest in the file), x_i = i * 1.5 um, y_j = j * 2.5 um, Lx = 60 um, Ly = 60 um. The
points (i, j) = (3, 2), (17, 11), (39, 23) are missing.

Written by x3pio 2.0.0 (an independent reader/writer of ISO 25178-72 on PyPI, MIT), into
`tests/data/peers/x3p/`:
* `x3pio-f64.x3p`: CZ DataType D, Increment 1 (x3pio's default for floating point: it stores metres),
  missing points NaN;
* `x3pio-i32.x3p`: CZ DataType L, the increment x3pio picks to fit int32 (`z_scale="auto"`), missing points
  in a validity file (bindata/valid.bin, ValidPointsLink);

Written by hand below with the standard library only (zipfile, hashlib, xml.etree), from the layout of
ISO 25178-72 / ISO 5436-2 XML (main.xml with Record1-4, bindata/data.bin little-endian x fastest,
md5checksum.hex holding the MD5 of main.xml):
* `hand-i16-offset.x3p`: CZ DataType I (int16), Increment 1e-9, Offset -1e-6: z = Offset + Increment * v;
* `hand-f64-inc1e-6.x3p`: CZ DataType D, heights stored in metres, with CZ Increment 1.0E-6. The schema's
  documentation of Increment (openGPS iso5436_2.xsd) reads "Needed for incremental axis and integer data
  types: Increment is the multiplyer of the integer coordinate ...", and the openGPS reference library adds
  only the offset to a Z value (ISO5436_2Container::ConvertPointToCoord); so for floating-point data the
  increment is not applied, and these heights are the stored metres. (x3pio applies it to every type.)

And `sample-land-x3pio.csv`: the repository's real scan `examples/data/sample-land.x3p` as x3pio reads it
(size, increments, invalid count, and every 97th point's height in metres or nan). x3pio refuses the
file's root element <ISO5436> (the schema's is ISO5436_2), so it reads a copy with only that name changed.

And `brdfmill-f32-x3pio.csv`: `brdfmill-f32.x3p`, which brdfmill's writer made from the surface above (no
missing points, float32 metres, one pitch of 1.5 um on both axes: `tests/x3p_independent.rs` writes it with
BRDFMILL_BLESS=1), as x3pio reads it: every height in metres.

Written with Python 3.11.7, NumPy 2.4.6 and x3pio 2.0.0:

    python3 -m venv /work/venv && /work/venv/bin/pip install numpy==2.4.6 x3pio==2.0.0
    /work/venv/bin/python scripts/peer_x3p_independent.py tests/data/peers/x3p
"""
import hashlib
import io
import sys
import zipfile
from datetime import UTC, datetime
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import x3pio

NX, NY, DX, DY = 40, 24, 1.5e-6, 2.5e-6
MISSING = [(3, 2), (17, 11), (39, 23)]
DATE = datetime(2024, 1, 1, tzinfo=UTC)
ROOT = Path(__file__).resolve().parent.parent


def surface():
    x = np.arange(NX)[None, :] * DX
    y = np.arange(NY)[:, None] * DY
    lx, ly = 60e-6, 60e-6
    z = -5e-7 + 2e-6 * np.sin(2 * np.pi * 1.5 * x / lx) * np.cos(2 * np.pi * y / ly) + 3e-7 * x / lx
    return np.ascontiguousarray(z)  # rows = y, columns = x


def with_missing(z):
    z = z.copy()
    for i, j in MISSING:
        z[j, i] = np.nan
    return z


def write_x3pio(out):
    meta = x3pio.Metadata.for_software("x3pio", x3pio.__version__, date=DATE)
    z = with_missing(surface())
    x3pio.write(out / "x3pio-f64.x3p", z, x_scale=DX, y_scale=DY, metadata=meta)
    x3pio.write(out / "x3pio-i32.x3p", z, x_scale=DX, y_scale=DY, z_type=x3pio.DataType("L"), metadata=meta)
    back = x3pio.read(out / "x3pio-i32.x3p")
    print(f"x3pio-i32.x3p: CZ increment {back.header.z.increment!r}")


def main_xml(z_type, z_increment, z_offset, md5_data):
    ns = "http://www.opengps.eu/2008/ISO5436_2"
    ET.register_namespace("p", ns)
    root = ET.Element(f"{{{ns}}}ISO5436_2")

    def sub(parent, tag, text=None):
        e = ET.SubElement(parent, tag)
        if text is not None:
            e.text = text
        return e

    r1 = sub(root, "Record1")
    sub(r1, "Revision", "ISO5436 - 2000")
    sub(r1, "FeatureType", "SUR")
    axes = sub(r1, "Axes")
    for name, inc in [("CX", DX), ("CY", DY)]:
        a = sub(axes, name)
        sub(a, "AxisType", "I")
        sub(a, "Increment", repr(inc))
        sub(a, "Offset", "0")
    cz = sub(axes, "CZ")
    sub(cz, "AxisType", "A")
    sub(cz, "DataType", z_type)
    sub(cz, "Increment", z_increment)
    sub(cz, "Offset", z_offset)
    r2 = sub(root, "Record2")
    sub(r2, "Date", "2024-01-01T00:00:00+00:00")
    sub(r2, "Creator", "brdfmill scripts/peer_x3p_independent.py")
    ins = sub(r2, "Instrument")
    sub(ins, "Manufacturer", "hand-written")
    sub(ins, "Model", "zipfile+hashlib+xml.etree")
    sub(ins, "Serial", "not available")
    sub(ins, "Version", "1")
    sub(r2, "CalibrationDate", "2024-01-01T00:00:00+00:00")
    ps = sub(r2, "ProbingSystem")
    sub(ps, "Type", "Software")
    sub(ps, "Identification", "analytic surface")
    sub(r2, "Comment", "independent of brdfmill's writer")
    r3 = sub(root, "Record3")
    md = sub(r3, "MatrixDimension")
    sub(md, "SizeX", str(NX))
    sub(md, "SizeY", str(NY))
    sub(md, "SizeZ", "1")
    dl = sub(r3, "DataLink")
    sub(dl, "PointDataLink", "bindata/data.bin")
    sub(dl, "MD5ChecksumPointData", md5_data)
    r4 = sub(root, "Record4")
    sub(r4, "ChecksumFile", "md5checksum.hex")
    buf = io.BytesIO()
    ET.ElementTree(root).write(buf, encoding="UTF-8", xml_declaration=True)
    return buf.getvalue()


def write_hand(path, data_bytes, z_type, z_increment, z_offset):
    md5_data = hashlib.md5(data_bytes).hexdigest()
    xml = main_xml(z_type, z_increment, z_offset, md5_data)
    checksum = f"{hashlib.md5(xml).hexdigest()} *main.xml\n".encode()
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, content in [("main.xml", xml), ("bindata/data.bin", data_bytes), ("md5checksum.hex", checksum)]:
            info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, content)


def write_handmade(out):
    z = surface()
    # int16 with an offset: v = round((z - offset) / increment); |z - offset| < 3.3e-5 m fits int16 at 1 nm
    inc, off = 1e-9, -1e-6
    v = np.rint((z - off) / inc).astype("<i2")
    assert np.abs((z - off) / inc).max() < 32767
    write_hand(out / "hand-i16-offset.x3p", v.tobytes(), "I", "1.0E-9", "-1.0E-6")
    # float64 metres, with an increment that the schema does not apply to floating-point data
    write_hand(out / "hand-f64-inc1e-6.x3p", z.astype("<f8").tobytes(), "D", "1.0E-6", "0")


def patched_sample_land():
    """sample-land.x3p's main.xml has the root element <ISO5436>, which x3pio refuses (the schema's is
    <p:ISO5436_2>); rename it in a copy held in memory and leave everything else, the binary data included,
    as it is (the checksum of main.xml then no longer matches, so x3pio reads it with verify=False)."""
    src = zipfile.ZipFile(ROOT / "examples/data/sample-land.x3p")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename.endswith("main.xml") and not info.filename.startswith("__MACOSX"):
                data = data.replace(b"<ISO5436>", b"<ISO5436_2>", 1).replace(b"</ISO5436>", b"</ISO5436_2>", 1)
            dst.writestr(info, data)
    return io.BytesIO(buf.getvalue())


def write_sample_land(out):
    f = x3pio.read(patched_sample_land(), verify=False)
    layer = f.layers[0]
    z = np.asarray(layer.z)
    ny, nx = z.shape
    flat = z.reshape(-1)
    with open(out / "sample-land-x3pio.csv", "w") as fh:
        fh.write(f"# examples/data/sample-land.x3p (was tests/data/x3p/) as x3pio {x3pio.__version__} reads it (metres); every 97th point\n")
        fh.write(f"# nx={nx} ny={ny} x_increment={f.header.x.increment!r} y_increment={f.header.y.increment!r} "
                 f"z_increment={f.header.z.increment!r} invalid={int(np.isnan(flat).sum())}\n")
        fh.write("index,z_m\n")
        for k in range(0, flat.size, 97):
            fh.write(f"{k},{float(flat[k])!r}\n")
    print(f"sample-land.x3p: {nx} x {ny}, {int(np.isnan(flat).sum())} invalid")


def read_brdfmill(out):
    f = x3pio.read(out / "brdfmill-f32.x3p")
    z = np.asarray(f.layers[0].z)
    ny, nx = z.shape
    flat = z.reshape(-1)
    with open(out / "brdfmill-f32-x3pio.csv", "w") as fh:
        fh.write(f"# brdfmill-f32.x3p (brdfmill's writer) as x3pio {x3pio.__version__} reads it (metres)\n")
        fh.write(f"# nx={nx} ny={ny} x_increment={f.header.x.increment!r} y_increment={f.header.y.increment!r} "
                 f"z_type={f.header.z.data_type!r}\n")
        fh.write("index,z_m\n")
        for k in range(flat.size):
            fh.write(f"{k},{float(flat[k])!r}\n")
    print(f"brdfmill-f32.x3p: {nx} x {ny}")


def main():
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    write_x3pio(out)
    write_handmade(out)
    write_sample_land(out)
    if (out / "brdfmill-f32.x3p").exists():
        read_brdfmill(out)


if __name__ == "__main__":
    main()
