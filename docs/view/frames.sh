#!/usr/bin/env bash
# Frame times of `photometeor view` per model, measured in the window (under xvfb-run where no
# display runs): each model renders the scene's still view FRAMES times and the screenshot's
# JSON holds each frame's time. The first frame of a model builds its pipelines and, for max
# and coupled, lights the grid for the sun; the frames after it are what a camera move costs
# (max and coupled keep their per-sun lighting while the sun, grid and settings stay: the
# table gives their median). biri draws [[medium]] tables only: it runs on data/scenes/beams.toml.
# Writes docs/view/frames.json and frames.md; the window as it opens (the model --model auto
# chooses) is docs/view/window.png (the picture of docs/viewer.md). Usage, from the repository root:
#   docs/view/frames.sh [SCENE] [WIDTH] [HEIGHT] [FRAMES]
# Builds `photometeor` with the viewer (cargo build --release --features view).
set -euo pipefail
cd "$(dirname "$0")/../.."
scene=${1:-data/scenes/dense_cumulus.toml}
width=${2:-320}
height=${3:-240}
frames=${4:-3}
cargo build --release --features view --quiet
run=()
if [ -z "${DISPLAY:-}" ] && [ -z "${WAYLAND_DISPLAY:-}" ]; then
    run=(xvfb-run -a -s "-screen 0 1600x1000x24")
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for model in riley miyazaki max coupled biri; do
    s=$scene
    [ "$model" = biri ] && s=data/scenes/beams.toml
    "${run[@]}" target/release/photometeor view "$s" --model "$model" --width "$width" \
        --height "$height" --frames "$frames" --screenshot "$out/$model.png" --quiet \
        || echo "{\"model\": \"$model\", \"failed\": true}" > "$out/$model.json"
done
# The picture: the window as it opens on the scene, on the model `--model auto` chooses.
"${run[@]}" target/release/photometeor view "$scene" --width "$width" --height "$height" \
    --screenshot "$out/auto.png" --quiet
cp "$out/auto.png" docs/view/window.png
python3 - "$out" "$scene" "$width" "$height" "$frames" <<'PY'
import json, statistics, sys, pathlib
out, scene, w, h, frames = sys.argv[1:]
rows = [json.loads((pathlib.Path(out) / f"{m}.json").read_text())
        for m in ["riley", "miyazaki", "max", "coupled", "biri"]]
pathlib.Path("docs/view/frames.json").write_text(json.dumps(
    {"scene": scene, "width": int(w), "height": int(h), "frames": int(frames), "models": rows},
    indent=1) + "\n")
lines = [f"`photometeor view {scene}` (biri: data/scenes/beams.toml) at {w}×{h}, {frames} "
         f"frames of the still view per model, the first and the median of the others "
         f"(`docs/view/frames.sh`), adapter: "
         f"{rows[0].get('adapter', '?')}.", "",
         "| model | first frame: sun + view (ms) | next frames: view only, median (ms) | "
         "request to image, mean (ms) | passes of the last frame (ms) |",
         "|---|---|---|---|---|"]
for r in rows:
    if r.get("failed"):
        lines.append(f"| {r['model']} | refused (see its error) | | | |")
        continue
    passes = ", ".join(f"{n} {s * 1e3:.1f}" for n, s in r["passes"])
    t = r["frame_seconds"]
    lines.append(f"| {r['model']} | {t[0] * 1e3:.1f} | {statistics.median(t[1:] or t) * 1e3:.1f} | "
                 f"{r['wall_seconds_mean'] * 1e3:.1f} | {passes} |")
pathlib.Path("docs/view/frames.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
PY
