"""Read a folder written by `mpmlab run --vtk DIR` with readers that share
no code with the writer, and print what it holds, one fact a line, for
tests/frontend/vtk.rs to compare with the engine's state.

The points (.vtu) are read with meshio; the collections (.pvd), the
boundaries (.vtp) and the grid (.vtr), which meshio does not read, with
Python's XML parser and a base64 decoder of VTK's inline binary arrays
(written here from the VTK file format specification). Floats are printed
with repr, which round-trips exactly.

Output lines:
  pvd KIND STEP TIMESTEP        every entry of KIND.pvd, in order
  points STEP N                 every points file: number of points
  array STEP NAME v1 v2 ...     every point array of every step, flattened
  lines KIND STEP L P           every .vtp file: polylines and points
  line KIND STEP I CELLDATA x1 y1 x2 y2 ...   every polyline (CELLDATA:
                                name=value,... of its cell data)
  grid STEP NX NY ACTIVE x0 y0 h   every .vtr file
  nonfinite COUNT               non-finite values over every array read
Exit status 3 when meshio (or numpy) is missing.
"""

import base64
import math
import os
import struct
import sys
import xml.etree.ElementTree as ET

try:
    import meshio
    import numpy as np
except ImportError as e:
    print(f"missing python module: {e.name} (python3 -m pip install meshio)", file=sys.stderr)
    sys.exit(3)

NONFINITE = 0
TYPES = {"Float64": "d", "Float32": "f", "Int32": "i", "Int64": "q", "UInt8": "B", "UInt32": "I", "UInt64": "Q"}


def fmt(v):
    global NONFINITE
    if isinstance(v, float) and not math.isfinite(v):
        NONFINITE += 1
    return repr(float(v)) if isinstance(v, float) else str(int(v))


def decode(array, root):
    """The values of a DataArray with format="binary" (inline base64: a
    header with the byte count, then the data) or format="ascii"."""
    kind = TYPES[array.get("type")]
    text = (array.text or "").strip()
    if array.get("format") == "ascii":
        return [float(t) if kind in "fd" else int(t) for t in text.split()]
    assert array.get("format") == "binary", array.attrib
    order = "<" if root.get("byte_order", "LittleEndian") == "LittleEndian" else ">"
    header = "Q" if root.get("header_type", "UInt32") == "UInt64" else "I"
    raw = base64.b64decode(text)
    hsize = struct.calcsize(header)
    (nbytes,) = struct.unpack(order + header, raw[:hsize])
    data = raw[hsize : hsize + nbytes]
    assert len(data) == nbytes, (len(data), nbytes)
    count = nbytes // struct.calcsize(kind)
    return list(struct.unpack(order + kind * count, data))


def collection(folder, kind):
    """(step, timestep, path) of every entry of KIND.pvd."""
    path = os.path.join(folder, kind + ".pvd")
    if not os.path.exists(path):
        return []
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection", root.attrib
    out = []
    for ds in root.find("Collection").findall("DataSet"):
        rel = ds.get("file")
        step = int(os.path.splitext(os.path.basename(rel))[0])
        full = os.path.join(folder, rel)
        assert os.path.exists(full), full
        out.append((step, float(ds.get("timestep")), full))
        print("pvd", kind, step, repr(float(ds.get("timestep"))))
    return out


def read_points(step, path):
    m = meshio.read(path)
    print("points", step, len(m.points))
    print("array", step, "x", " ".join(fmt(float(v)) for v in m.points[:, 0]))
    print("array", step, "y", " ".join(fmt(float(v)) for v in m.points[:, 1]))
    print("array", step, "z", " ".join(fmt(float(v)) for v in m.points[:, 2]))
    for name, values in m.point_data.items():
        flat = np.asarray(values).reshape(-1)
        conv = float if flat.dtype.kind == "f" else int
        print("array", step, name, " ".join(fmt(conv(v)) for v in flat))


def read_lines(kind, step, path):
    root = ET.parse(path).getroot()
    assert root.get("type") == "PolyData", root.attrib
    piece = root.find("PolyData").find("Piece")
    xyz = decode(piece.find("Points").find("DataArray"), root)
    for v in xyz:
        fmt(v)
    lines = piece.find("Lines")
    arrays = {a.get("Name"): decode(a, root) for a in lines.findall("DataArray")} if lines is not None else {}
    conn, offsets = arrays.get("connectivity", []), arrays.get("offsets", [])
    cell = piece.find("CellData")
    cell_data = {a.get("Name"): decode(a, root) for a in cell.findall("DataArray")} if cell is not None else {}
    n_points = int(piece.get("NumberOfPoints"))
    assert len(xyz) == 3 * n_points
    print("lines", kind, step, len(offsets), n_points)
    start = 0
    for i, end in enumerate(offsets):
        ids = conn[start:end]
        start = end
        data = ",".join(f"{k}={fmt(v[i])}" for k, v in sorted(cell_data.items())) or "-"
        coords = " ".join(f"{fmt(xyz[3 * p])} {fmt(xyz[3 * p + 1])}" for p in ids)
        print("line", kind, step, i, data, coords)


def read_grid(step, path):
    root = ET.parse(path).getroot()
    assert root.get("type") == "RectilinearGrid", root.attrib
    piece = root.find("RectilinearGrid").find("Piece")
    x0, x1, y0, y1, _, _ = (int(v) for v in piece.get("Extent").split())
    coords = [decode(a, root) for a in piece.find("Coordinates").findall("DataArray")]
    x, y = coords[0], coords[1]
    nx, ny = x1 - x0, y1 - y0
    assert len(x) == nx + 1 and len(y) == ny + 1
    active = decode(piece.find("CellData").find("DataArray"), root)
    assert len(active) == nx * ny
    print("grid", step, nx, ny, sum(active), fmt(x[0]), fmt(y[0]), fmt(x[1] - x[0]))


def main(folder):
    for step, _, path in collection(folder, "points"):
        read_points(step, path)
    for step, _, path in collection(folder, "grid"):
        read_grid(step, path)
    for kind in ("boundaries", "ibm"):
        for step, _, path in collection(folder, kind):
            read_lines(kind, step, path)
    print("nonfinite", NONFINITE)


if __name__ == "__main__":
    main(sys.argv[1])
