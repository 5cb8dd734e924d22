"""Shared by the image scripts (shafts.py, beams.py, four.py, growing.py) and
docs/coupled/examples.py: run
`photometeor render`, read its EXR, measure a frame against a truth, and write two frames side
by side (or four, 2 × 2) at one exposure (the left one's automatic exposure, as
`photometeor render --png` picks it: the 97th percentile of luminance maps to 1 − e^{−1.5})."""
import json
import subprocess
import sys
import time

import numpy as np
import OpenEXR
from PIL import Image

LUMA = np.array([0.2126, 0.7152, 0.0722])


def render(args, exr):
    """Runs `args` (the binary and its arguments, writing `exr`), prints its last stderr line,
    and returns the frame's linear R, G, B (height × width × 3)."""
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(r.stderr)
    print(r.stderr.strip().splitlines()[-1])
    with OpenEXR.File(exr, separate_channels=True) as f:
        ch = f.channels()
        return np.stack([ch[c].pixels for c in "RGB"], axis=-1).astype(np.float64)


def srgb(v):
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)


def save_pair(left, right, out):
    """Writes left | 4 white pixels | right to `out` as sRGB PNG; negative radiance is black.
    Returns the exposure."""
    lum = left @ LUMA
    exposure = 1.5 / np.sort(lum.ravel())[int((lum.size - 1) * 0.97)]
    w = left.shape[1]
    both = np.concatenate([left, np.zeros((left.shape[0], 4, 3)), right], axis=1)
    img = srgb(1.0 - np.exp(-exposure * np.maximum(both, 0.0)))
    img[:, w:w + 4] = 1.0
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(out, optimize=True)
    return exposure


def rings(rgb, fov_deg, step=0.25, top=12.0, lower=False):
    """Mean luminance in rings of `step` degrees about the image centre (a glory's antisolar
    point), over the mean of the outer 2°, and the rings' centres; `fov_deg` the vertical
    field of view; `lower`: over the pixels below the centre only."""
    h, w = rgb.shape[:2]
    f = (h / 2) / np.tan(np.radians(fov_deg / 2))
    y, x = np.mgrid[0:h, 0:w]
    angle = np.degrees(np.arctan(np.hypot(x + 0.5 - w / 2, y + 0.5 - h / 2) / f))
    edges = np.arange(0.0, top + 1e-9, step)
    lum = rgb @ LUMA
    ring = np.digitize(angle, edges)
    if lower:
        ring = np.where(y + 0.5 > h / 2, ring, 0)
    mean = np.array([lum[ring == i].mean() for i in range(1, len(edges))])
    return edges[:-1] + step / 2, mean / mean[-int(2 / step):].mean()


def read_exr(exr):
    """A frame's linear R, G, B (height × width × 3) from its EXR."""
    with OpenEXR.File(str(exr), separate_channels=True) as f:
        ch = f.channels()
        return np.stack([ch[c].pixels for c in "RGB"], axis=-1).astype(np.float64)


def against_truth(binary, scene, model, size, truth_exr, exr):
    """Renders `scene` with `model` (`size`: extra arguments) into `exr`, measures it against
    `truth_exr` with `compare-render --json`, prints the figures, and returns the frame and
    its report entry ({"error": compare-render's JSON, "wall_s_incl_start": s})."""
    started = time.time()
    frame = render([binary, "render", str(scene), "--model", model, *size, "--out", exr], exr)
    seconds = time.time() - started
    out = subprocess.run([binary, "compare-render", str(truth_exr), exr, "--json"],
                         capture_output=True, text=True, check=True)
    e = json.loads(out.stdout)
    print(f"{model}: bias {e['bias']:+.1%}, median {e['median_rel_error']:.1%}, "
          f"p95 {e['p95_rel_error']:.1%} (truth noise {e['truth_noise']:.1%}), {seconds:.1f} s")
    return frame, {"error": e, "wall_s_incl_start": seconds}


def grid_2x2(rows, exposure_of):
    """Two rows of two frames (each height × width × 3) with 4 white pixels between them, at
    the automatic exposure of frame `exposure_of` (as `render --png` picks it); returns the
    exposure and the sRGB image (0…1)."""
    lum = exposure_of @ LUMA
    exposure = 1.5 / np.sort(lum.ravel())[int((lum.size - 1) * 0.97)]
    h, w = rows[0][0].shape[:2]
    gap = np.zeros((h, 4, 3))
    lines = [np.concatenate([a, gap, b], axis=1) for a, b in rows]
    grid = np.concatenate([lines[0], np.zeros((4, lines[0].shape[1], 3)), lines[1]], axis=0)
    img = srgb(1.0 - np.exp(-exposure * np.maximum(grid, 0.0)))
    img[:, w:w + 4] = 1.0
    img[h:h + 4, :] = 1.0
    return exposure, img
