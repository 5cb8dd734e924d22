#!/usr/bin/python3
"""Writes the OpenVDB files the reader is tested on, with the OpenVDB library itself.

Usage: /usr/bin/python3 write_cases.py OUTDIR

Debian's python3-openvdb (the library's own bindings, 10.0.1) writes each grid with the
library's default codec (blosc, with the active mask); vdb_tool (libopenvdb-tools) rewrites
copies with the zip, active-mask-only and no codec. Beside each file, the library's own
answers in cases.json: the active voxel count, the active voxels' bounding box, the leaf
count, the background, the transform, and the values over the bounding box as the library's
accessor reads them (copyToArray), written as raw little-endian f32, x fastest.

Bad files (a vector grid, a level set, a frustum transform, negative and non-finite
densities, several grids, a box too large to hold dense) are written too; the tests mutate
good files for the rest.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pyopenvdb as vdb

OUT = sys.argv[1]
os.makedirs(OUT, exist_ok=True)
CASES = {}


def blob(shape, center, radii):
    """A smooth blob of densities in [0, 1], zero outside its ellipsoid."""
    idx = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    r2 = sum(((i - c) / r) ** 2 for i, c, r in zip(idx, center, radii))
    return np.clip(1.0 - r2, 0.0, None).astype(np.float32)


def record(name, grid, file=None, half=False, codec="blosc"):
    """Writes `grid` (unless `file` is given) and the library's answers about it."""
    path = file or f"{name}.vdb"
    if file is None:
        vdb.write(os.path.join(OUT, path), grids=[grid])
    (x0, y0, z0), (x1, y1, z1) = grid.evalActiveVoxelBoundingBox()
    dims = (x1 - x0 + 1, y1 - y0 + 1, z1 - z0 + 1)
    values = np.zeros(dims, dtype=np.float32)
    grid.copyToArray(values, ijk=(x0, y0, z0))
    if half:
        values = values.astype(np.float16).astype(np.float32)
    raw = f"{name}.f32"
    values.transpose(2, 1, 0).astype("<f4").tofile(os.path.join(OUT, raw))
    xf = grid.transform
    CASES[name] = {
        "file": path,
        "grid": grid.name,
        "codec": codec,
        "half": half,
        "active_voxels": grid.activeVoxelCount(),
        "index_min": [x0, y0, z0],
        "index_max": [x1, y1, z1],
        "leaves": grid.leafCount(),
        "background": grid.background,
        "voxel_size": list(xf.voxelSize()),
        "origin_m": list(xf.indexToWorld((0, 0, 0))),
        "raw": raw,
    }


def rewrite(name, source, codec, bits=32):
    """A copy of `source` rewritten by vdb_tool with `codec` and `bits`."""
    path = f"{name}.vdb"
    subprocess.run(
        ["vdb_tool", "-read", os.path.join(OUT, source), "-write",
         f"codec={codec}", f"bits={bits}", os.path.join(OUT, path)],
        check=True, capture_output=True)
    return path


# A dense blob placed off the origin, blosc (the library's default).
dense = vdb.FloatGrid()
dense.copyFromArray(blob((24, 16, 20), (12, 8, 10), (10, 6, 8)), ijk=(5, -3, 7), tolerance=0.0)
dense.name = "density"
dense.transform = vdb.createLinearTransform(voxelSize=25.0)
record("dense", dense)
for codec in ["zip", "active", "none"]:
    record(f"dense_{codec}", dense, file=rewrite(f"dense_{codec}", "dense.vdb", codec), codec=codec)

# Saved as halves: by the grid's flag (blosc), and by vdb_tool with zip.
half = dense.deepCopy()
half.saveFloatAsHalf = True
record("half", half, half=True)
record("half_zip", half, file=rewrite("half_zip", "dense.vdb", "zip", bits=16), half=True, codec="zip")

# Sparse: two blobs far apart, a filled block that becomes tiles (a 128³ level-5 tile and
# level-4 tiles), inactive voxels holding values, and a background that is not zero.
sparse = vdb.FloatGrid(0.25)
sparse.name = "density"
a = blob((12, 12, 12), (6, 6, 6), (5, 5, 5)) + 0.5
sparse.copyFromArray(a, ijk=(-100, 10, 40), tolerance=0.0)
sparse.copyFromArray(a, ijk=(150, 60, -20), tolerance=0.0)
sparse.fill((0, 0, 0), (127, 127, 127), 0.75, active=True)
sparse.fill((128, 0, 0), (143, 15, 15), 0.5, active=True)
acc = sparse.getAccessor()
acc.setValueOff((-96, 12, 41), 2.0)
acc.setValueOff((152, 61, -18), 3.0)
sparse.transform = vdb.createLinearTransform(voxelSize=10.0)
record("sparse", sparse)
record("sparse_zip", sparse, file=rewrite("sparse_zip", "sparse.vdb", "zip"), codec="zip")

# Small and sparse, for the fuzz run as much as for itself: level-4 tiles, a blob, an inactive
# voxel holding a value, and a background that is not zero.
tiles = vdb.FloatGrid(0.25)
tiles.name = "density"
tiles.fill((0, 0, 0), (15, 15, 7), 0.5, active=True)
tiles.copyFromArray(blob((12, 12, 12), (6, 6, 6), (5, 5, 5)) + 0.5, ijk=(20, 0, 0), tolerance=0.0)
tiles.getAccessor().setValueOff((22, 1, 1), 2.0)
tiles.transform = vdb.createLinearTransform(voxelSize=10.0)
record("tiles", tiles)
record("tiles_zip", tiles, file=rewrite("tiles_zip", "tiles.vdb", "zip"), codec="zip")

# A scaled and translated transform (a ScaleTranslateMap).
moved = dense.deepCopy()
moved.transform = vdb.createLinearTransform(
    [[10.0, 0, 0, 0], [0, 20.0, 0, 0], [0, 0, 30.0, 0], [100.0, -50.0, 7.0, 1]])
record("transformed", moved)
record("transformed_zip", moved, file=rewrite("transformed_zip", "transformed.vdb", "zip"),
       codec="zip")

# Several grids in one file; the test asks for one that is not there.
other = dense.deepCopy()
other.name = "temperature"
vdb.write(os.path.join(OUT, "two_grids.vdb"), grids=[dense, other])

# Files to refuse.
vec = vdb.Vec3SGrid()
vec.name = "density"
vec.fill((0, 0, 0), (3, 3, 3), (1.0, 0.0, 0.0))
vdb.write(os.path.join(OUT, "vector.vdb"), grids=[vec])
ls = vdb.createLevelSetSphere(radius=5.0)
ls.name = "density"
vdb.write(os.path.join(OUT, "level_set.vdb"), grids=[ls])
fr = dense.deepCopy()
fr.transform = vdb.createFrustumTransform(
    xyzMin=(0, 0, 0), xyzMax=(24, 16, 20), taper=0.5, depth=100.0, voxelSize=1.0)
vdb.write(os.path.join(OUT, "frustum.vdb"), grids=[fr])
neg = dense.deepCopy()
neg.getAccessor().setValueOn((10, 2, 15), -1.0)
vdb.write(os.path.join(OUT, "negative.vdb"), grids=[neg])
nan = dense.deepCopy()
nan.getAccessor().setValueOn((10, 2, 15), float("nan"))
vdb.write(os.path.join(OUT, "nan.vdb"), grids=[nan])
# Two voxels 4000 apart: a tiny file whose dense box (4001³ voxels) no memory holds.
far = vdb.FloatGrid()
far.name = "density"
far.getAccessor().setValueOn((0, 0, 0), 1.0)
far.getAccessor().setValueOn((4000, 4000, 4000), 1.0)
vdb.write(os.path.join(OUT, "far.vdb"), grids=[far])

with open(os.path.join(OUT, "cases.json"), "w") as f:
    json.dump({"library": list(vdb.LIBRARY_VERSION), "cases": CASES}, f, indent=1)
