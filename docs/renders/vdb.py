"""The README's OpenVDB cloud (data/scenes/vdb_cloud.toml, its grid written by the OpenVDB
library: data/scenes/vdb/make_cloud.py): the path-traced truth and coupled side by side at
the truth's automatic exposure (as `render --png` picks it), coupled and riley measured against
the truth with `photometeor compare-render`. Writes `vdb_cloud-pair.png` and `vdb_cloud.json`.

The truth is the long part (4096 spp at 240 × 168: about 11 minutes on 2 CPU cores): give it
as an EXR already rendered at the scene's size (`--truth`), or it is rendered here.

    python3 docs/renders/vdb.py [--bin target/release/photometeor] [--truth T.exr] [--spp 4096]
"""
import argparse
import json
import tempfile
import time
from pathlib import Path

from pair import against_truth, read_exr, render, save_pair

HERE = Path(__file__).resolve().parent
SCENE = HERE.parents[1] / "data/scenes/vdb_cloud.toml"


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", default=str(HERE.parents[1] / "target/release/photometeor"))
    p.add_argument("--truth", help="a truth EXR of the scene at its own size")
    p.add_argument("--spp", type=int, default=4096)
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="vdb-"))
    truth_exr = a.truth or str(tmp / "truth.exr")
    report = {"scene": str(SCENE.relative_to(HERE.parents[1])), "models": {}}
    if not a.truth:
        started = time.time()
        render([a.bin, "render", str(SCENE), "--model", "truth", "--cpu", "--set",
                f"spp={a.spp}", "--out", truth_exr], truth_exr)
        report["truth_wall_s"] = time.time() - started
    report["truth_spp"] = a.spp
    frames = {}
    for model in ["coupled", "riley"]:
        frames[model], report["models"][model] = against_truth(
            a.bin, SCENE, model, ["--cpu"], truth_exr, str(tmp / f"{model}.exr"))
    report["exposure"] = save_pair(read_exr(truth_exr), frames["coupled"],
                                   HERE / "vdb_cloud-pair.png")
    (HERE / "vdb_cloud.json").write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
