"""Helpers the docs and bench scripts share: the repository root, the soft-ball fixture as a
scene, and JSON made free of machine paths. A script imports it with

    sys.path.insert(0, os.path.join(ROOT, "scripts")); import repo
"""
import json
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def soft_ball(head, field, density, azimuth, size, tail=""):
    """The soft-ball fixture (data/scenes/fixtures/soft_ball.toml) after `head` (the [scene] and
    [[field]] tables), with its field, density, sun azimuth and image size set and `tail` (more
    [render.<model>] tables) after it; its grid file named by absolute path."""
    fixtures = os.path.join(ROOT, "data", "scenes", "fixtures")
    values = {"field": f'"{field}"', "number_density_per_m3": density, "azimuth_deg": azimuth,
              "width": size, "height": size,
              "file": json.dumps(os.path.join(fixtures, "soft_ball_48.f32"))}
    lines = []
    for line in open(os.path.join(fixtures, "soft_ball.toml")).read().splitlines():
        key = line.split("=")[0].strip()
        lines.append(f"{key} = {values[key]}" if key in values and "=" in line else line)
    return head + "\n".join(lines) + "\n" + tail


def portable(value, root, work):
    """`value` with paths inside the repository `root` made relative to it and the work
    directory `work` written as $WORK, so the committed JSON names no machine's paths."""
    if isinstance(value, dict):
        return {k: portable(v, root, work) for k, v in value.items()}
    if isinstance(value, list):
        return [portable(v, root, work) for v in value]
    if isinstance(value, str):
        return value.replace(root.rstrip("/") + "/", "").replace(work, "$WORK")
    return value
