#!/usr/bin/env python3
"""What a Henyey–Greenstein lobe loses: the example scenes glory.toml and rainbow.toml against
their HG twins, the lobe an engine (Unreal, Unity HDRP, Godot) would use in place of the
particles' phase function.

For each scene: bake it with `--quality draft`, fit the best dual HG w·HG(g1) + (1 − w)·HG(g2)
to the bake's single-scattering row Ams_1 with `photometeor export --format hg` (green channel),
and write the twin: the same TOML with the particle [[field]] replaced by a `kind = "hg"` field
of the same name holding that lobe, the particles' green σ_ext as `extinction_m2` and their
green albedo. The scenes are spectral (31 wavelengths) and the twin has one lobe for all of them,
as an engine has. Then each scene, and the glory scene seen with a 100° field of view (its
fogbow; docs/coupled/examples.py's FOGBOW_FOV), is rendered four ways: the particles and the
twin, each with `--model coupled --cpu` and the path-traced truth (`--model truth --cpu`,
--noise 0.03, at most `--spp` and `--max-seconds` per frame; truths cached under $HG_WORK by
their command). Measured:
- `photometeor compare-render` of coupled-HG against truth-Mie (what an engine's lobe loses,
  with our model's own error in it), coupled-Mie against truth-Mie (our model's own error),
  truth-HG against truth-Mie (the lobe alone), coupled-HG against truth-HG (our model on the
  lobe);
- each frame's ring contrast: the glory's first ring and the fogbow as examples.py measures
  them (its `contrast`, `lower_rings` and docs/renders/pair.py's `rings`), and the rainbow's
  primary bow: 1° rings about the antisolar point (below the image centre in rainbow.toml) over
  the sector within RAINBOW_SECTOR of the bow's top, the brightest within RAINBOW_BRIGHT over
  the darkest within RAINBOW_DARK outside it (Alexander's dark band). A peak on its window's
  edge is flagged: the profile's slope there, not a ring or a bow.
Writes docs/hg/compare.json, compare.md (from the json), per case a strip
<case>-strip.png (truth-Mie | coupled-Mie | coupled-HG | truth-HG at truth-Mie's automatic
exposure) and compare-render's error map of coupled-HG against truth-Mie, <case>-error.png, and
per scene the fit's plot, <scene>-lobes.png.

Run from the repository root after `cargo build --release`, with the test venv's Python
(numpy, OpenEXR, Pillow):
    .venv/bin/python docs/hg/compare.py [--max-seconds 150]
    .venv/bin/python docs/hg/compare.py --markdown-only  # compare.md from compare.json
"""
import argparse, hashlib, json, os, re, subprocess, sys, time, tomllib

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "docs", "renders"))
sys.path.insert(0, os.path.join(ROOT, "docs", "coupled"))
from examples import FOGBOW_FOV, FOGBOW_SIZE, contrast, file_stem, lower_rings  # noqa: E402

BIN = os.environ.get("PHOTOMETEOR", os.path.join(ROOT, "target", "release", "photometeor"))
WORK = os.environ.get("HG_WORK", "/tmp/photometeor-hg")
# Scene and image size, as docs/coupled/examples.py renders them.
SCENES = [("glory", 256, 256), ("rainbow", 160, 120)]
# The four frames of a case, in the strip's order: (particles or lobe, model).
FRAMES = [("mie", "truth"), ("mie", "coupled"), ("hg", "coupled"), ("hg", "truth")]
# What is compared with what: (test frame, reference frame).
COMPARISONS = [(("hg", "coupled"), ("mie", "truth")), (("mie", "coupled"), ("mie", "truth")),
               (("hg", "truth"), ("mie", "truth")), (("hg", "coupled"), ("hg", "truth"))]
# The rainbow's primary bow, in degrees from the antisolar point: the brightest 1° ring within
# RAINBOW_BRIGHT over the darkest within RAINBOW_DARK, Alexander's dark band outside the bow up
# to the secondary. Chosen from the truth-Mie and coupled-Mie profiles (compare.json's rings):
# the bow peaks in the ring 41–42°, falls by half into the next, and the band's floor lies at
# 49–50°, the secondary rising from 51°. The rings count only the pixels within RAINBOW_SECTOR
# degrees (position angle about the antisolar point) of the bow's top, where the rays cross the
# middle of the rain shaft: full rings also cross the shaft's sides and the horizon, which put
# a bump at 44–46° into every frame's profile, the lobe's too.
RAINBOW_BRIGHT, RAINBOW_DARK = (38.0, 43.0), (43.0, 50.0)
RAINBOW_SECTOR, RAINBOW_STEP, RAINBOW_TOP = 25.0, 1.0, 70.0


def label(frame):
    variant, model = frame
    return f"{model}-{'Mie' if variant == 'mie' else 'HG'}"


def run(args):
    r = subprocess.run([BIN] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"photometeor {' '.join(args)}: exit {r.returncode}\n{r.stderr}")
    return r


def hg_field(name, dual, sigma_ext, albedo):
    """The [[field]] table of the twin: the dual-HG fit (a single lobe where the fit's weight is
    1) with the particles' σ_ext and albedo."""
    lines = ["[[field]]",
             "# The best dual Henyey–Greenstein fit to the draft bake's Ams_1 (G) of the particles",
             "# it replaces (photometeor export --format hg), with their G σ_ext and albedo.",
             f'name = "{name}"', 'kind = "hg"', f"g = {dual['g1']!r}"]
    if 0.0 < dual["w"] < 1.0:
        lines += [f"g2 = {dual['g2']!r}", f"weight = {dual['w']!r}"]
    lines += [f"extinction_m2 = {sigma_ext!r}", f"albedo = {min(albedo, 1.0)!r}"]
    return "\n".join(lines) + "\n"


def replace_field(text, name, table):
    """`text` with the whole [[field]] table named `name` (from its header to the next table's
    header or the end) replaced by `table`; exits if there is not exactly one."""
    parts = re.split(r"(?m)^(?=\[)", text)
    hits = [i for i, p in enumerate(parts)
            if p.startswith("[[field]]") and re.search(rf'(?m)^name\s*=\s*"{name}"', p)]
    if len(hits) != 1:
        sys.exit(f"expected one [[field]] named {name!r}, found {len(hits)}")
    parts[hits[0]] = table + "\n"
    return "".join(parts)


def antisolar_rings(rgb, scene_text, sector=RAINBOW_SECTOR, step=RAINBOW_STEP, top=RAINBOW_TOP):
    """Mean luminance in rings of `step` degrees about the antisolar point (wherever it lies in
    the image), over the pixels within `sector` degrees of position angle of the rings' top (the
    direction towards the zenith), relative to their mean, and the rings' centres; rings with
    no pixel are left out. The camera as runtime/render/src/camera.rs builds it (vertical fov,
    square pixels), the sun's direction from its elevation and azimuth (from +z towards +x)."""
    import numpy as np
    from pair import LUMA
    s = tomllib.loads(scene_text)
    cam, sun = s["camera"], s["sun"]
    pos, at = np.array(cam["position_m"], float), np.array(cam["look_at_m"], float)
    forward = (at - pos) / np.linalg.norm(at - pos)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    h, w = rgb.shape[:2]
    t = np.tan(np.radians(cam["fov_deg"] / 2))
    i, j = np.meshgrid(np.arange(w), np.arange(h))
    sx = (2 * (i + 0.5) / w - 1) * t * w / h
    sy = (1 - 2 * (j + 0.5) / h) * t
    ray = forward + sx[..., None] * right + sy[..., None] * up
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    e, a = np.radians(sun["elevation_deg"]), np.radians(sun["azimuth_deg"])
    antisolar = -np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])
    angle = np.degrees(np.arccos(np.clip(ray @ antisolar, -1, 1)))
    # Position angle about the antisolar point, 0 towards the zenith.
    top_dir = np.array([0.0, 1.0, 0.0]) - antisolar[1] * antisolar
    top_dir /= np.linalg.norm(top_dir)
    side = np.cross(antisolar, top_dir)
    position = np.degrees(np.arctan2(ray @ side, ray @ top_dir))
    lum = rgb @ LUMA
    ring = np.where(np.abs(position) <= sector, np.floor(angle / step).astype(int), -1)
    theta, value = [], []
    for k in range(int(round(top / step))):
        inside = ring == k
        if inside.any():
            theta.append((k + 0.5) * step)
            value.append(lum[inside].mean())
    value = np.array(value)
    return np.array(theta), value / value.mean()


def at_edge(theta, angle, window):
    """Whether `angle` is the first or last ring centre within `window`."""
    inside = [t for t in theta if window[0] <= t <= window[1]]
    return angle in (min(inside), max(inside))


def save_strip(frames, out):
    """Writes the frames side by side, 4 white pixels apart, as sRGB PNG at the first frame's
    automatic exposure (docs/renders/pair.py's rule); returns the exposure."""
    import numpy as np
    from PIL import Image
    from pair import LUMA, srgb
    lum = frames[0] @ LUMA
    exposure = 1.5 / np.sort(lum.ravel())[int((lum.size - 1) * 0.97)]
    h, w = frames[0].shape[:2]
    gap = np.full((h, 4, 3), np.nan)
    row = np.concatenate(sum([[f, gap] for f in frames], [])[:-1], axis=1)
    img = srgb(1.0 - np.exp(-exposure * np.maximum(np.nan_to_num(row), 0.0)))
    img[np.isnan(row)] = 1.0
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(out, optimize=True)
    return float(exposure)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--max-seconds", type=float, default=150.0,
                   help="each truth's cap on wall time (with --noise 0.03 and --spp)")
    p.add_argument("--spp", type=int, default=65536, help="each truth's cap on samples per pixel")
    p.add_argument("--markdown-only", action="store_true",
                   help="rewrite compare.md from compare.json, rendering nothing")
    a = p.parse_args()
    if a.markdown_only:
        write_markdown(json.load(open(os.path.join(HERE, "compare.json"))))
        return
    from pair import read_exr, rings
    started = time.time()
    stamp = lambda: f"[{time.time() - started:5.0f} s]"
    os.makedirs(WORK, exist_ok=True)
    report = {"quality": "draft", "max_seconds": a.max_seconds, "spp": a.spp,
              "noise": 0.03, "lobes": {}, "cases": {}}
    cases = []
    for name, w, h in SCENES:
        scene = os.path.join(ROOT, "data", "scenes", f"{name}.toml")
        text = open(scene).read()
        bake, export = f"{WORK}/{name}-bake", f"{WORK}/{name}-hg-export"
        print(f"{stamp()} {name}: bake --quality draft, export --format hg", flush=True)
        run(["bake", scene, "--out", bake, "--quality", "draft", "--quiet"])
        run(["export", bake, "--format", "hg", "--out", export])
        fields = json.load(open(f"{export}/export.json"))["fields"]
        if len(fields) != 1:
            sys.exit(f"{name}: expected one field in {export}/export.json, found {list(fields)}")
        (field, f), = fields.items()
        dual = f["orders"]["1"]["channels"]["G"]["dual_hg"]
        sigma_ext, albedo = f["sigma_ext_m2"][1], f["albedo"][1]
        report["lobes"][name] = {
            "field": field, "kind": f["kind"], "sigma_ext_m2_G": sigma_ext, "albedo_G": albedo,
            "g_G": f["orders"]["1"]["channels"]["G"]["g"], "dual_hg_G": dual,
            "dual_hg_R": f["orders"]["1"]["channels"]["R"]["dual_hg"],
            "dual_hg_B": f["orders"]["1"]["channels"]["B"]["dual_hg"]}
        # The plot in 64 colours: a tenth of the bytes, the same lines.
        from PIL import Image
        Image.open(f"{export}/{field}.lobes.png").convert("RGB").quantize(64).save(
            os.path.join(HERE, f"{name}-lobes.png"), optimize=True)
        twin = replace_field(text, field, hg_field(field, dual, sigma_ext, albedo))
        twin = re.sub(r'(?m)^name = "([^"]*)"', r'name = "\1_hg"', twin, count=1)
        print(f"  {field} ({f['kind']}): dual HG g1 {dual['g1']:.4f}, g2 {dual['g2']:.4f}, "
              f"w {dual['w']:.4f}; σ_ext {sigma_ext:.4g} m², albedo {albedo:.6f}", flush=True)
        variants = {"mie": (text, bake), "hg": (twin, f"{WORK}/{name}-hg-bake")}
        cases.append((name, name, w, h, variants))
        if name == "glory":
            fog = {v: (t.replace("fov_deg = 36", f"fov_deg = {FOGBOW_FOV:g}"), d)
                   for v, (t, d) in variants.items()}
            cases.append(("glory (fogbow)", name, FOGBOW_SIZE, FOGBOW_SIZE, fog))
    for case, scene_name, w, h, variants in cases:
        file = file_stem(case)
        size = ["--width", str(w), "--height", str(h), "--quality", "draft"]
        row = {"scene": scene_name, "size": [w, h], "truths": {}, "coupled_seconds": {},
               "errors": {}}
        exr = {}
        for variant, model in FRAMES:
            text, tables = variants[variant]
            path = f"{WORK}/{file}-{variant}.toml"
            open(path, "w").write(text)
            where = ["--tables", tables]
            if model == "truth":
                args = ["render", path, "--model", "truth", *size, "--cpu", "--spp", str(a.spp),
                        "--noise", "0.03", "--set", f"max_seconds={a.max_seconds:g}"]
                key = hashlib.sha256((text + " ".join(args[2:])).encode()).hexdigest()[:16]
                out = f"{WORK}/{file}-{variant}-truth-{key}.exr"
                if not os.path.exists(out):
                    print(f"{stamp()} {case}: truth-{variant} (at most {a.max_seconds:g} s)",
                          flush=True)
                    t0 = time.time()
                    r = run(args + where + ["--out", out + ".part.exr"])
                    os.rename(out + ".part.exr", out)
                    open(out + ".txt", "w").write(
                        f"{r.stderr.strip().splitlines()[-1]} [{time.time() - t0:.0f} s]")
                row["truths"][label((variant, model))] = open(out + ".txt").read()
                print(f"{stamp()} {case}: {label((variant, model))}: "
                      f"{row['truths'][label((variant, model))]}", flush=True)
            else:
                out = f"{WORK}/{file}-{variant}-coupled.exr"
                t0 = time.time()
                run(["render", path, "--model", "coupled", *size, "--cpu", *where, "--out", out])
                row["coupled_seconds"][label((variant, model))] = round(time.time() - t0, 1)
                print(f"{stamp()} {case}: {label((variant, model))} "
                      f"[{time.time() - t0:.1f} s]", flush=True)
            exr[(variant, model)] = out
        for test, ref in COMPARISONS:
            key = f"{label(test)} vs {label(ref)}"
            map_args = []
            if (test, ref) == COMPARISONS[0]:
                map_args = ["--map", os.path.join(HERE, f"{file}-error.png")]
            e = json.loads(run(["compare-render", exr[ref], exr[test], "--json",
                                *map_args]).stdout)
            row["errors"][key] = e
            print(f"  {key:28s} bias {e['bias']:+7.1%} median {e['median_rel_error']:6.1%} "
                  f"p95 {e['p95_rel_error']:6.1%} (reference noise {e['truth_noise']:.1%})",
                  flush=True)
        frames = {f: read_exr(exr[f]) for f in FRAMES}
        row["exposure"] = save_strip([frames[f] for f in FRAMES],
                                     os.path.join(HERE, f"{file}-strip.png"))
        rings_row = {}
        for f in FRAMES:
            if case == "glory (fogbow)":
                theta, value = lower_rings(frames[f], FOGBOW_FOV)
                dark, bright = (28.0, 36.0), (36.0, 44.0)
            elif case == "glory":
                theta, value = rings(frames[f], 36.0)
                dark, bright = (0.5, 1.0), (1.0, 2.0)  # examples.py's `contrast` defaults
            else:
                theta, value = antisolar_rings(frames[f], variants[f[0]][0])
                dark, bright = RAINBOW_DARK, RAINBOW_BRIGHT
            lo, hi, c = contrast(theta, value, dark=dark, bright=bright)
            edge = at_edge(list(theta), hi, bright)
            rings_row[label(f)] = {"minimum_deg": lo, "peak_deg": hi, "contrast": c,
                                   "peak_at_window_edge": edge,
                                   "profile": [round(float(v), 4) for v in value]}
            print(f"  rings {label(f):12s}: darkest {lo:.3f}°, brightest {hi:.3f}°, "
                  f"contrast {c:+.1%}{' (peak at the window edge)' if edge else ''}", flush=True)
        rings_row["angle_deg"] = [round(float(t), 3) for t in theta]
        row["rings"] = rings_row
        report["cases"][case] = row
    report["wall_s"] = round(time.time() - started)
    json.dump(report, open(os.path.join(HERE, "compare.json"), "w"), indent=1)
    write_markdown(report)
    print(f"{stamp()} wrote docs/hg/compare.json, compare.md and the PNGs", flush=True)


def pct(x, sign=False):
    return f"{x:+.1%}".replace("%", " %") if sign else f"{x:.1%}".replace("%", " %")


RING_NOTES = {
    "glory": "the glory's first ring: 0.25° rings about the antisolar point (the image centre) "
             "over the mean of 10–12°; the brightest within 1–2° over the darkest within 0.5–1°",
    "glory (fogbow)": "the fogbow: 1° rings about the antisolar point over the lower half of "
                      "the image; the brightest within 36–44° over the darkest within 28–36°",
    "rainbow": "the primary bow: 1° rings about the antisolar point (below the image centre, "
               f"under the horizon) within {RAINBOW_SECTOR:g}° of position angle of the bow's "
               f"top; the brightest within {RAINBOW_BRIGHT[0]:g}–{RAINBOW_BRIGHT[1]:g}° over "
               f"the darkest within {RAINBOW_DARK[0]:g}–{RAINBOW_DARK[1]:g}° (Alexander's dark "
               "band)",
}


def write_markdown(report):
    """compare.md from the report that compare.json holds."""
    frames = [label(f) for f in FRAMES]
    # Each truth's own wall time, the "[… s]" its cached summary line ends with.
    truth_seconds = sum(float(re.search(r"\[(\d+) s\]$", line).group(1))
                        for row in report["cases"].values() for line in row["truths"].values())
    md = [
        "# What a Henyey–Greenstein lobe loses",
        "",
        "Engines (Unreal, Unity HDRP, Godot) give a cloud or rain one or two Henyey–Greenstein "
        "lobes instead of its phase function. Here the example scenes "
        "[glory.toml](../../data/scenes/glory.toml) and "
        "[rainbow.toml](../../data/scenes/rainbow.toml) are rendered as written, with "
        f"`{report['quality']}` tables and small images, and as their HG twins: the same scene "
        "with the particle field replaced by a `kind = \"hg\"` field of the same name "
        "([physics.md §8.1](../physics.md#81-given-phase-functions-kind--hg-kind--tabulated)) "
        "holding the best dual lobe w·HG(g1) + (1 − w)·HG(g2) that "
        "`photometeor export --format hg` fits to the bake's single-scattering row Ams_1 in "
        "the green channel, with the particles' green σ_ext and albedo. Both scenes are "
        "spectral (31 wavelengths); the twin has one lobe for all of them, as an engine has, "
        "so it also loses the colour of the bows and rings. The glory scene is also seen with "
        "a 100° field of view, for its fogbow.",
        "",
        "Each case is rendered four ways: truth-Mie and truth-HG, the path-traced truth "
        f"(`--model truth --cpu --noise {report['noise']}`, at most {report['spp']} samples per "
        f"pixel and `max_seconds = {report['max_seconds']:g}`), and coupled-Mie and coupled-HG "
        "(`--model coupled --cpu`). Generated by [compare.py](compare.py) "
        "(figures: [compare.json](compare.json)) on 2 cores: the truths took "
        f"{truth_seconds / 60:.0f} min, the rest of its last run (bakes and exports cached, "
        f"the coupled frames, the comparisons) {report['wall_s'] / 60:.1f} min.",
        "",
        "## The lobes",
        "",
        "The fits (green channel, Ams_1); *moved*: the share of the scattered light the lobe "
        "puts in a wrong θ bin; *rms*: its relative rms error over θ ≥ 1°; *kept*: the lobe's "
        "value at each feature's peak over the table's. Each scene's plot: the table's Ams_1 "
        "against the lobe at the table's own g, the best HG and the best dual HG.",
        "",
        "| scene | field | g1 | g2 | w | σ_ext (m²) | albedo | moved | rms | kept | plot |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scene, lobe in report["lobes"].items():
        d = lobe["dual_hg_G"]
        kept = ", ".join(f"{k} {pct(v['kept'])}" for k, v in d["features"].items())
        md.append(f"| {scene} | {lobe['field']} ({lobe['kind']}) | {d['g1']:.4f} | "
                  f"{d['g2']:.4f} | {d['w']:.4f} | {lobe['sigma_ext_m2_G']:.4g} | "
                  f"{lobe['albedo_G']:.6f} | {pct(d['moved'])} | "
                  f"{pct(d['rms_relative_from_1deg'])} | {kept} | "
                  f"[{scene}-lobes.png]({scene}-lobes.png) |")
    keys = list(next(iter(report["cases"].values()))["errors"])
    md += ["", "## Errors", "",
           "`photometeor compare-render` over the volume's pixels (bias / median / p95 of the "
           "relative error; differences within 3σ of the reference's noise count as 0). "
           "coupled-HG vs truth-Mie is what an engine's lobe loses, with our model's own error "
           "in it; coupled-Mie vs truth-Mie is that own error; truth-HG vs truth-Mie is the "
           "lobe's alone.", "",
           "| case | size | " + " | ".join(keys) + " |", "|---|---|" + "---|" * len(keys)]
    for case, row in report["cases"].items():
        cells = [f"{pct(e['bias'], True)} / {pct(e['median_rel_error'])} / "
                 f"{pct(e['p95_rel_error'])}" for e in row["errors"].values()]
        md.append(f"| {case} | {row['size'][0]}×{row['size'][1]} | " + " | ".join(cells) + " |")
    md += ["", "The truths' noise (median relative standard error, green, volume pixels) and "
           "how each stopped:", "", "| case | frame | truth |", "|---|---|---|"]
    for case, row in report["cases"].items():
        for frame, line in row["truths"].items():
            md.append(f"| {case} | {frame} | {line} |")
    md += ["", "## Ring contrasts", "",
           "The brightest ring within one window over the darkest within another, minus 1, "
           "per frame, as [docs/coupled/examples.py](../coupled/examples.py) measures the "
           "glory and the fogbow (the rings' profiles: compare.json). A peak on the edge of "
           "its window (marked *edge*) is the profile's slope there, not a ring or a bow: the "
           "lobe has none, and the figure is what the view's brightness does across the "
           "windows. A truth's contrast also carries its noise: the largest of several noisy "
           "rings over the smallest of others is positive on a flat profile.", "",
           "| case | what | " + " | ".join(frames) + " |", "|---|---|" + "---|" * len(frames)]
    for case, row in report["cases"].items():
        cells = [f"{pct(row['rings'][f]['contrast'], True)} "
                 f"({row['rings'][f]['minimum_deg']:g}° / {row['rings'][f]['peak_deg']:g}°"
                 f"{', edge' if row['rings'][f]['peak_at_window_edge'] else ''})"
                 for f in frames]
        md.append(f"| {case} | {RING_NOTES[case]} | " + " | ".join(cells) + " |")
    md += ["", "Each cell: the contrast (darkest ring's angle / brightest ring's angle).", "",
           "## Pictures", ""]
    for case, row in report["cases"].items():
        file = file_stem(case)
        md += [f"### {case}", "",
               f"![{case}: " + " | ".join(frames) + f"]({file}-strip.png)", "",
               f"*{case}, {row['size'][0]}×{row['size'][1]}: " + " | ".join(frames)
               + ", at truth-Mie's automatic exposure. " + {
                   "glory": "The twin has no glory: the bright spot and its coloured rings "
                            "about the antisolar point (the image centre) are gone, and the "
                            "deck, lit from behind the camera, is darker.",
                   "glory (fogbow)": "The twin has neither the fogbow (the pale arc about "
                                     "39° from the antisolar point, the image centre) nor "
                                     "the glory (the small bright spot).",
                   "rainbow": "The twin has no bow: neither the primary with its colours, nor "
                              "the secondary, nor Alexander's dark band between them.",
               }[case] + "*", "",
               f"![{case}: coupled-HG against truth-Mie]({file}-error.png)", "",
               f"*{case}: coupled-HG against truth-Mie, compare-render's map: red too bright, "
               "blue too dark, full colour at ±50 %, grey within 3σ of the truth's noise.*", ""]
    open(os.path.join(HERE, "compare.md"), "w").write("\n".join(md))


if __name__ == "__main__":
    main()
