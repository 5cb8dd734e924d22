#!/usr/bin/python3
"""Writes cloud.vdb, the example OpenVDB cloud of data/scenes/vdb_cloud.toml, with the OpenVDB
library itself (Debian's python3-openvdb, which scripts/test installs):

    /usr/bin/python3 data/scenes/vdb/make_cloud.py

A small cumulus made as an artist's tool would make one: a union of spheres (a flat base, a
heaped top) roughened by a seeded fractal value noise, 25 m voxels, y up. One `density` grid of
values in [0, 1] (multiplied by the scene's number_density_per_m3), stored as half floats
with the library's default codec (blosc); voxels of density 0 are left inactive, so the tree
is sparse. Index (0, 0, 0) is the middle of the cloud's base.
"""

import os

import numpy as np
import pyopenvdb as vdb

VOXEL_M = 25.0
NX, NY, NZ = 128, 88, 128  # 3.2 × 2.2 × 3.2 km
rng = np.random.default_rng(61)


def smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def value_noise(cells, shape):
    """A random lattice of `cells` cells per axis, interpolated (smoothly) onto `shape`."""
    lattice = rng.random((cells + 1,) * 3)
    weights = []
    for n in shape:
        u = np.linspace(0.0, cells, n, endpoint=False) + 0.5 * cells / n
        i = np.minimum(u.astype(int), cells - 1)
        f = smoothstep(0.0, 1.0, u - i)
        w = np.zeros((n, cells + 1))
        w[np.arange(n), i] = 1.0 - f
        w[np.arange(n), i + 1] = f
        weights.append(w)
    return np.einsum("ia,jb,kc,abc->ijk", *weights, lattice, optimize=True)


def fbm(shape):
    """Five octaves of value noise, 0…1."""
    total, norm = np.zeros(shape), 0.0
    for octave, cells in enumerate([4, 8, 16, 32, 64]):
        amp = 0.7**octave
        total += amp * value_noise(cells, shape)
        norm += amp
    return total / norm


# Voxel centres in metres, x and z about the middle, y from the base.
x = (np.arange(NX) - NX / 2 + 0.5) * VOXEL_M
y = (np.arange(NY) + 0.5) * VOXEL_M
z = (np.arange(NZ) - NZ / 2 + 0.5) * VOXEL_M
X, Y, Z = np.meshgrid(x, y, z, indexing="ij")

# Spheres heaped round a central tower: (centre x, centre y, centre z, radius), metres.
spheres = [(0, 700, 0, 750), (-600, 450, 200, 520), (550, 430, -250, 560), (150, 1150, 100, 520),
           (-350, 950, -300, 450), (400, 850, 400, 480), (-150, 1500, -50, 380),
           (800, 300, 350, 380), (-850, 280, -250, 360), (100, 350, -700, 420),
           (-200, 380, 750, 400)]
inside = np.full(X.shape, -np.inf)
for cx, cy, cz, r in spheres:
    d = np.sqrt((X - cx) ** 2 + (Y - cy) ** 2 + (Z - cz) ** 2)
    inside = np.maximum(inside, 1.0 - d / r)
shaped = inside + 0.7 * (fbm(X.shape) - 0.5)
density = smoothstep(0.0, 0.08, shaped) * smoothstep(0.0, 60.0, Y)
density = np.where(density < 1e-3, 0.0, density).astype(np.float32)

grid = vdb.FloatGrid(0.0)
grid.name = "density"
grid.copyFromArray(density, ijk=(-NX // 2, 0, -NZ // 2), tolerance=0.0)
grid.transform = vdb.createLinearTransform(voxelSize=VOXEL_M)
grid.saveFloatAsHalf = True
out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "cloud.vdb")
vdb.write(out, grids=[grid])
print(f"{out}: {grid.activeVoxelCount()} active voxels of {density.size}, "
      f"{os.path.getsize(out) / 2**20:.2f} MiB")
