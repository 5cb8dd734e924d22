#!/usr/bin/env bash
# Every example scene (data/scenes/*.toml but the sweep) by every model, on the CPU (--cpu) and
# on the GPU path, at 40 × 30 pixels (the truth at 2 samples, seed 7), with BIN; writes
# OUT/<scene>-<model>-<cpu|gpu>.exr, the command's log beside it, and OUT/summary.txt (rc and
# seconds per render; a model that refuses a scene exits 2 and its refusal is compared).
# Compare two runs with scripts/render-diff.py OUT_A OUT_B: a restructuring that should not
# change the images shows every render bit-identical.
#   usage: scripts/render-diff.sh BIN OUT [TABLES]   (TABLES: a bake cache shared by runs)
set -uo pipefail
bin=$(realpath "$1"); out=$(realpath -m "$2"); tables=$(realpath -m "${3:-$out/tables}")
cd "$(dirname "$0")/.."
mkdir -p "$out"
: > "$out/summary.txt"
for scene in beams cumulus_dawn dense_cumulus glory growing_cumulus halo rainbow shafts; do
    for model in riley miyazaki max coupled biri truth; do
        for place in cpu gpu; do
            args=(--width 40 --height 30 --tables "$tables/$scene" --quiet)
            [ "$place" = cpu ] && args+=(--cpu)
            [ "$model" = truth ] && args+=(--spp 2 --seed 7)
            name="$out/$scene-$model-$place"
            start=$(date +%s.%N)
            "$bin" render "data/scenes/$scene.toml" --model "$model" "${args[@]}" \
                --out "$name.exr" > "$name.log" 2>&1
            rc=$?
            echo "$scene $model $place rc=$rc $(echo "$(date +%s.%N) - $start" | bc)s" \
                | tee -a "$out/summary.txt"
        done
    done
done
