#!/usr/bin/env python3
"""The fast models against the path-traced truth on the example scenes of data/scenes/
(cumulus_dawn, glory, rainbow, halo), each scene as it is written (its sky, its ground, its
grid) but with `draft` tables and a small image: riley, max and coupled (CPU references)
against `--model truth`, compared by `photometeor compare-render` over the volume's pixels.
For the glory, also the ring contrast: the mean luminance in rings of 0.25° about the
antisolar point (the image centre), the first bright ring over the minimum before it; and the
fogbow's, from the same scene seen with a 100° field of view ("glory (fogbow)"): rings of 1°
over the lower half of the image (whose rays all meet the deck), the fogbow (~39° from the
antisolar point for these droplets) over the dark band inside it.

Each truth is rendered once (--noise 0.03, at most `--spp` (65536) and `max_seconds` per scene)
and cached under $EXAMPLES_WORK by its command, so re-running after a model change renders
only the models. Writes docs/coupled/examples.json, examples.md and an error map per scene
for coupled (examples-<scene>-coupled.png: red too bright, blue too dark, full at ±50 %, grey
within 3σ of the truth's noise).

Run from the repository root after `cargo build --release`, with the test venv's Python
(numpy, OpenEXR):
    .venv/bin/python docs/coupled/examples.py [--max-seconds 300]
    .venv/bin/python docs/coupled/examples.py --only glory --models coupled  # printed only
    .venv/bin/python docs/coupled/examples.py --markdown-only  # examples.md from examples.json
"""
import argparse, hashlib, json, os, subprocess, sys, time


HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "docs", "renders"))

BIN = os.environ.get("PHOTOMETEOR", os.path.join(ROOT, "target", "release", "photometeor"))
WORK = os.environ.get("EXAMPLES_WORK", "/tmp/photometeor-examples")
# Scene, image size (the glory larger, for its rings: 0.14° a pixel), and whether to measure it
# also without the sky (no skylight and no air: the volume's own error, apart from the sky
# model's, which is single scattering in the fast models and full in the truth).
SCENES = [("cumulus_dawn", 160, 120, False), ("glory", 256, 256, True),
          ("rainbow", 160, 120, True), ("halo", 160, 120, False)]
MODELS = ["riley", "max", "coupled"]
# The fogbow's view: the glory scene with this field of view (degrees), this image size.
FOGBOW_FOV, FOGBOW_SIZE = 100.0, 192


def file_stem(name):
    """A case's name as it appears in file names: "glory (sky off)" → "glory-sky-off"."""
    return name.replace(" (sky off)", "-sky-off").replace(" (fogbow)", "-fogbow")


def cases():
    """The cases: (name, scene file, width, height), the variants' scene files written under
    WORK."""
    os.makedirs(WORK, exist_ok=True)
    out = []
    for name, w, h, sky_off in SCENES:
        scene = os.path.join(ROOT, "data", "scenes", f"{name}.toml")
        out.append((name, scene, w, h))
        if sky_off:
            # The same scene with `[sky] enabled = false` (these scenes have no [sky] table).
            path = os.path.join(WORK, f"{name}.toml")
            open(path, "w").write(open(scene).read() + "\n[sky]\nenabled = false\n")
            out.append((f"{name} (sky off)", path, w, h))
        if name == "glory":
            path = os.path.join(WORK, "glory-fogbow.toml")
            text = open(scene).read().replace("fov_deg = 36", f"fov_deg = {FOGBOW_FOV:g}")
            open(path, "w").write(text)
            out.append(("glory (fogbow)", path, FOGBOW_SIZE, FOGBOW_SIZE))
    return out


def run(args):
    r = subprocess.run([BIN] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(args)}: {r.stderr}")
    return r


def contrast(theta, value, dark=(0.5, 1.0), bright=(1.0, 2.0)):
    """The glory's first ring for r_eff ≈ 10 µm: the darkest ring within `dark` degrees and the
    brightest within `bright` after it: (minimum's angle, peak's angle, peak / minimum − 1).
    (Fixed windows: a truth's 2–3 % noise makes the first local extremum a noise wiggle.)"""
    lo = [i for i, t in enumerate(theta) if dark[0] <= t <= dark[1]]
    hi = [i for i, t in enumerate(theta) if bright[0] <= t <= bright[1]]
    i = min(lo, key=lambda k: value[k])
    j = max(hi, key=lambda k: value[k])
    return float(theta[i]), float(theta[j]), float(value[j] / value[i] - 1.0)


def lower_rings(rgb, fov_deg, step=1.0, top=50.0):
    """Mean luminance in rings of `step` degrees about the image centre over the pixels below
    it (in the glory scene, the rays that meet the deck at every angle up to `top`), relative to
    their mean, and the rings' centres; `fov_deg` the vertical field of view."""
    from pair import rings  # numpy and OpenEXR: needed to measure, not to write examples.md
    theta, value = rings(rgb, fov_deg, step, top, lower=True)
    return theta, value / value.mean()


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--max-seconds", type=float, default=300.0)
    p.add_argument("--spp", type=int, default=65536,
                   help="the truths' cap on samples per pixel (with --noise 0.03 and max_seconds)")
    p.add_argument("--only", help="comma-separated cases (e.g. 'glory,glory (sky off)'): "
                   "printed, not written")
    p.add_argument("--models", default=",".join(MODELS), help="the models to render")
    p.add_argument("--markdown-only", action="store_true",
                   help="rewrite examples.md from examples.json, rendering nothing")
    a = p.parse_args()
    if a.markdown_only:
        write_markdown(json.load(open(os.path.join(HERE, "examples.json"))))
        return
    from pair import read_exr, rings
    only = a.only.split(",") if a.only else None
    models = a.models.split(",")
    report = {"quality": "draft", "scenes": {}}
    for name, scene, w, h in cases():
        if only and name not in only:
            continue
        file = file_stem(name)
        size = ["--width", str(w), "--height", str(h), "--quality", "draft"]
        args = ["render", scene, "--model", "truth", *size, "--cpu", "--spp", str(a.spp),
                "--noise", "0.03", "--set", f"max_seconds={a.max_seconds}"]
        key = hashlib.sha256((open(scene).read() + " ".join(args[2:])).encode()).hexdigest()[:16]
        truth = f"{WORK}/{file}-truth-{key}.exr"
        if not os.path.exists(truth):
            t0 = time.time()
            r = run(args + ["--out", truth + ".part.exr"])
            os.rename(truth + ".part.exr", truth)
            open(truth + ".txt", "w").write(
                f"{r.stderr.strip().splitlines()[-1]} [{time.time() - t0:.0f} s]")
        row = {"size": [w, h], "truth": open(truth + ".txt").read(), "models": {}}
        print(f"{name}: truth {row['truth']}", flush=True)
        frames = {"truth": read_exr(truth)}
        for model in models:
            out = f"{WORK}/{file}-{model}.exr"
            t0 = time.time()
            r = run(["render", scene, "--model", model, *size, "--cpu", "--out", out])
            seconds = time.time() - t0
            map_args = []
            if model == "coupled" and not only:
                map_args = ["--map", os.path.join(HERE, f"examples-{file}-coupled.png")]
            e = json.loads(run(["compare-render", truth, out, "--json", *map_args]).stdout)
            e["seconds"] = round(seconds, 1)
            e["summary"] = r.stderr.strip().splitlines()[-1]
            row["models"][model] = e
            frames[model] = read_exr(out)
            print(f"  {model:8s} bias {e['bias']:+7.1%} median {e['median_rel_error']:6.1%} "
                  f"p95 {e['p95_rel_error']:6.1%} (truth noise {e['truth_noise']:.1%}) "
                  f"[{seconds:.1f} s]", flush=True)
        if name == "glory (fogbow)":
            row["rings"] = {}
            for label, rgb in frames.items():
                theta, value = lower_rings(rgb, FOGBOW_FOV)
                # The dark band inside the fogbow and the bow (coupled's profile: 33° and 39°).
                lo, hi, c = contrast(theta, value, dark=(28.0, 36.0), bright=(36.0, 44.0))
                row["rings"][label] = {"minimum_deg": lo, "peak_deg": hi, "contrast": c,
                                       "profile": [round(v, 4) for v in value]}
                print(f"  fogbow {label:8s}: minimum {lo:.1f}°, bow {hi:.1f}°, "
                      f"contrast {c:+.1%}", flush=True)
            row["rings"]["angle_deg"] = [round(t, 3) for t in theta]
        elif name.startswith("glory"):
            fov = 36.0
            row["rings"] = {}
            for label, rgb in frames.items():
                theta, value = rings(rgb, fov)
                lo, hi, c = contrast(theta, value)
                row["rings"][label] = {"minimum_deg": lo, "peak_deg": hi, "contrast": c,
                                       "profile": [round(v, 4) for v in value]}
                print(f"  rings {label:8s}: minimum {lo:.3f}°, bright ring {hi:.3f}°, "
                      f"contrast {c:+.1%}", flush=True)
            row["rings"]["angle_deg"] = [round(t, 3) for t in theta]
        report["scenes"][name] = row
    if only or models != MODELS:
        return
    json.dump(report, open(os.path.join(HERE, "examples.json"), "w"), indent=1)
    write_markdown(report)


def write_markdown(report):
    """examples.md from the report that examples.json holds."""
    md = ["| scene | size | truth | " + " | ".join(
        f"{m}: bias / median / p95" for m in MODELS) + " | coupled error map |",
          "|" + "---|" * (4 + len(MODELS))]
    for name, row in report["scenes"].items():
        cells = [f"{row['models'][m]['bias']:+.1%} / {row['models'][m]['median_rel_error']:.1%}"
                 f" / {row['models'][m]['p95_rel_error']:.1%}" for m in MODELS]
        noise = row["models"]["coupled"]["truth_noise"]
        md.append(f"| {name} | {row['size'][0]}×{row['size'][1]} | noise {noise:.1%} | "
                  + " | ".join(cells)
                  + f" | ![](examples-{file_stem(name)}-coupled.png) |")
    for glory in [n for n in report["scenes"] if n.startswith("glory")]:
        md += ["", f"Glory rings ({glory}: 0.25° rings about the antisolar point, over 10–12°; "
               "the darkest within 0.5–1°, the brightest within 1–2°):" if glory != "glory (fogbow)"
               else "The fogbow (glory.toml with a 100° view: 1° rings about the antisolar point "
               "over the lower half of the image; the darkest within 28–36°, the brightest "
               "within 36–44°):", "",
               "| frame | darkest ring | brightest ring | contrast |", "|---|---|---|---|"]
        for label, r in report["scenes"][glory]["rings"].items():
            if label != "angle_deg":
                md.append(f"| {label} | {r['minimum_deg']:.3f}° | {r['peak_deg']:.3f}° | "
                          f"{r['contrast']:+.1%} |")
    open(os.path.join(HERE, "examples.md"), "w").write(
        "\n".join(md).replace("%", " %") + "\n")


if __name__ == "__main__":
    main()
