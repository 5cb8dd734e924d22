#!/usr/bin/env python3
"""Writes torus.obj: a torus (R = 0.9 m, r = 0.3 m, 32 × 12 quads) centred at the origin in
the x–z plane, the closed, non-convex occluder of data/scenes/beams.toml."""
import math
import os

R, r, NU, NV = 0.9, 0.3, 32, 12
lines = ["# torus.obj: written by torus.py beside it (R = 0.9 m, r = 0.3 m, 32 × 12 quads)"]
for i in range(NU):
    for j in range(NV):
        u, v = 2 * math.pi * i / NU, 2 * math.pi * j / NV
        x = (R + r * math.cos(v)) * math.cos(u)
        z = (R + r * math.cos(v)) * math.sin(u)
        lines.append(f"v {x:.6f} {r * math.sin(v):.6f} {z:.6f}")
for i in range(NU):
    for j in range(NV):
        a, b = i * NV + j + 1, (i + 1) % NU * NV + j + 1
        c, d = (i + 1) % NU * NV + (j + 1) % NV + 1, i * NV + (j + 1) % NV + 1
        lines.append(f"f {a} {b} {c} {d}")
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "torus.obj"), "w") as f:
    f.write("\n".join(lines) + "\n")
