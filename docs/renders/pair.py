"""Shared by the README image scripts (shafts.py, beams.py): run `photometeor render`, read its
EXR, and write two frames side by side at one exposure (the left one's automatic exposure, as
`photometeor render --png` picks it: the 97th percentile of luminance maps to 1 − e^{−1.5})."""
import subprocess, sys

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
