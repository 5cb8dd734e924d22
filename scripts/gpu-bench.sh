#!/usr/bin/env bash
# Every render model's frame time on this machine's GPU adapter, in one step, as JSON.
#
#   scripts/gpu-bench.sh [OUT]      # OUT: a directory (default: $OUT if set, else bench/gpu)
#   QUICK=1 scripts/gpu-bench.sh    # small sizes: checks the script on a software adapter
#   BIN=target/release/photometeor scripts/gpu-bench.sh   # no build: a binary built elsewhere
#
# A binary built elsewhere links libfontconfig, libfreetype, libpng16, libexpat, libbrotli and
# libz (plotters' text): on a bare machine without them, copy those of the build machine beside
# it (`ldd BIN`) and set LD_LIBRARY_PATH, as the lent H200 runs of bench/gpu/ did.
#
# Builds the release binary, bakes each scene's tables (draft preset: frame time does not depend
# on it), then runs `photometeor bench render` per scene with the models that scene takes,
# interleaved in one run so their ratios are fair: riley, miyazaki, max and coupled on the clouds
# (image sizes, slice counts and grid resolutions varied one at a time), miyazaki on the shafts,
# biri on the lamp beams, and the path-traced truth (GPU and CPU; paths/s) on the dense cumulus.
# Writes OUT/<scene>.json, OUT/machine.txt (adapter, CPU, date) and prints a summary. On an H200
# machine of 16 threads the parts of this run were timed on 2026-12-04 (docs/log.md, "the render
# models on a real GPU"): max's and coupled's lighting (CPU) were most of it, about 5 minutes in all; on 2
# cores with lavapipe use QUICK=1 (347 s on 2026-12-05, the JSON as on a GPU). Since 2026-12-05 coupled's transport sweeps, skylight
# sweeps and diffusion solves run on the GPU (`per_sun = "auto"` on a real adapter); its JSON's
# passes say how long.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-${OUT:-bench/gpu}}
mkdir -p "$OUT"
start=$(date +%s)
# Mesa's Vulkan driver prints an error line per process where XDG_RUNTIME_DIR is unset.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    XDG_RUNTIME_DIR=$(mktemp -d)
    export XDG_RUNTIME_DIR
    trap 'rm -rf "$XDG_RUNTIME_DIR"' EXIT
fi

# BIN=path uses a binary built elsewhere (a GPU machine without a Rust toolchain).
if [ -z "${BIN:-}" ]; then
    cargo build --release --quiet
    BIN=target/release/photometeor
fi

if [ "${QUICK:-0}" = 1 ]; then
    SIZE=64 SIZES=32,64 SLICES=32,64 GRIDS=32,64 REPEAT=1 SPP=4 HD=96x54 RELIGHT_SIZE=16
else
    SIZE=512 SIZES=256,512,1024 SLICES=64,128,256,512 GRIDS=64,128 REPEAT=2 SPP=16 HD=1920x1080
    RELIGHT_SIZE=64
fi

{
    echo "date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
    echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//') ($(nproc) threads)"
    command -v nvidia-smi > /dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
    echo "quick: ${QUICK:-0}"
} > "$OUT/machine.txt"

# bench SCENE MODELS [extra options…]: one interleaved run, JSON to OUT/<name>.json.
bench() {
    local scene=$1 models=$2 name
    shift 2
    name=$(basename "$scene" .toml)
    echo "== $name: $models" >&2
    "$BIN" bench render "$scene" --model "$models" --size "$SIZE" --repeat "$REPEAT" --json "$@" \
        > "$OUT/$name${TAG:+-$TAG}.json"
}

bench data/scenes/dense_cumulus.toml riley,miyazaki --sizes "$SIZES" --slice-counts "$SLICES" \
    --grids "$GRIDS"
# max's and coupled's lighting (CPU, seconds per sun) does not depend on the slice count: timed
# apart, once per setting, so that it does not take most of the run (measured on an H200
# machine: 16 s and 8 s per frame at grid 128, which over every slice count and two repeats
# took 430 s of dense_cumulus alone).
# coupled with `diffuse = "diffusion"` over the sizes and grids (the figures of the first runs);
# its default, the discrete-ordinates transport, costs minutes per sun on 2 cores at grid 128
# (docs/models/coupled.md), so it is timed once per grid at the base size.
DIFFUSION='diffuse="diffusion"'
REPEAT=1 TAG=lighting bench data/scenes/dense_cumulus.toml max,coupled --sizes "$SIZES" \
    --grids "$GRIDS" --set "$DIFFUSION"
# With --camera-moves: coupled's frames that reuse the lighting (the viewer's camera move,
# the lighting's buffers kept on the GPU), `camera_move_s` in the JSON.
REPEAT=1 TAG=transport bench data/scenes/dense_cumulus.toml riley,coupled --grids "$GRIDS" \
    --camera-moves
# The camera move at 1920 × 1080 (a game's frame) beside riley's frame of the same size.
REPEAT=1 TAG=1080p bench data/scenes/dense_cumulus.toml riley,coupled --sizes "$HD" \
    --camera-moves
# coupled's relight in steps after sun moves of 1°, 5° and 30°, cold and warm, at each preset
# but reference (each step's time; the per-sun passes where `auto` puts them, on a real GPU the
# GPU; the gathers that measure each step on the CPU, at a small size), in calls of the 2 ms a
# game gives its clouds: the JSON's longest_transport_call_s is the target's figure.
for preset in realtime balanced; do
    echo "== dense_cumulus: relight in steps, $preset" >&2
    "$BIN" bench relight data/scenes/dense_cumulus.toml --size "$RELIGHT_SIZE" \
        --moves 1,5,30 --gpu --set "preset=$preset" --step-budget-ms 2 --json \
        > "$OUT/dense_cumulus-relight-$preset.json"
done
# The same with coupled's per-sun passes on this machine's CPU, for the ratio.
REPEAT=1 TAG=transport-cpu bench data/scenes/dense_cumulus.toml riley,coupled --grids "$GRIDS" \
    --set 'per_sun="cpu"'
bench data/scenes/cumulus_dawn.toml riley,miyazaki,max,coupled --set "$DIFFUSION"
REPEAT=1 bench data/scenes/rainbow.toml riley,miyazaki,max,coupled --sizes "$SIZES" \
    --set "$DIFFUSION"
bench data/scenes/shafts.toml miyazaki --sizes "$SIZES"
bench data/scenes/beams.toml biri --sizes "$SIZES"
# The truth's paths/s on the GPU beside the CPU truth's on this machine's cores (--cpu); on a
# software adapter both are the CPU truth (render::truth::gpu docs).
"$BIN" bench render data/scenes/dense_cumulus.toml --model truth --size "$SIZE" --spp "$SPP" \
    --repeat 1 --cpu --json > "$OUT/dense_cumulus-truth.json"

echo "gpu-bench: $(($(date +%s) - start)) s; JSON in $OUT" >&2
cat "$OUT/machine.txt" >&2
