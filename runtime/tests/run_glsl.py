#!/usr/bin/env python3
"""Run the checked-in GLSL 450 sampling functions in OpenGL and compare with our CPU sampler.

Usage: python3 runtime/tests/run_glsl.py GLSL_FILE INPUT_DIR

INPUT_DIR holds, as .npy, what runtime::gpu::GpuTables uploads and what the CPU reference
(runtime::sample) gives, written by runtime/tests/shaders.rs:
  texture.npy (layers, n_stride, K, 4), forward_fraction.npy (layers * n_stride, 4),
  field_info.npy (layers, 4), params.npy (angle_count, n_stride, field_count, inv_step_rad),
  model_texture.npy (layers, J_P + J_B, K, 4), model_depths.npy (M,),
  queries.npy (Q, 8) = (field, a, b, kind, c, d, e, f), expected.npy (Q, 4) = the kernel's results (kind 0:
  Ams R, G, B, F_n G; 1: M R, G, B, 0; 2: C R, G, B, 0), denominator.npy (Q, 3) = what each
  channel's difference is divided by, tolerance.npy (Q,) = the largest ratio allowed.
The shader is compiled by the OpenGL driver (Mesa's llvmpipe through EGL, headless, via the
`moderngl` package), the eight bindings set as its header states (layout(binding = 0..7)), the
kernel `evaluate_queries` dispatched, and the results read back. Prints "OK worst ..." and exits
0 when every query is within its tolerance (and F_n within 1e-6), else prints the worst and
exits 1; exits 2 when moderngl or an OpenGL 4.5 context is missing.
"""

import os
import struct
import sys

try:
    import moderngl
    import numpy as np
except ImportError as e:  # pragma: no cover
    print(f"missing Python package ({e}); `python3 -m pip install moderngl numpy`", file=sys.stderr)
    sys.exit(2)


KINDS = ("Ams_n", "Poisson M", "Biri C")


def main(glsl_file, inputs):
    load = lambda name: np.load(os.path.join(inputs, name + ".npy"))
    texture, ff, info, params = load("texture"), load("forward_fraction"), load("field_info"), load("params")
    model_texture, model_depths = load("model_texture"), load("model_depths")
    queries, expected = load("queries"), load("expected")
    denominator, tolerance = load("denominator"), load("tolerance")
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=450)
    except Exception as e:  # pragma: no cover
        print(f"no OpenGL 4.5 context ({e}); Debian: libegl1 libgl1-mesa-dri", file=sys.stderr)
        sys.exit(2)
    source = open(glsl_file, encoding="utf-8").read()
    program = ctx.compute_shader(source)
    layers, n_stride, k_len, _ = texture.shape
    tex = ctx.texture_array((k_len, n_stride, layers), 4, texture.astype("f4").tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.use(location=0)
    layers, rows, _, _ = model_texture.shape
    model = ctx.texture_array((k_len, rows, layers), 4, model_texture.astype("f4").tobytes(), dtype="f4")
    model.filter = (moderngl.NEAREST, moderngl.NEAREST)
    model.use(location=4)
    results = ctx.buffer(reserve=queries.shape[0] * 16)
    storage = {
        1: ctx.buffer(ff.astype("f4").tobytes()),
        2: ctx.buffer(info.astype("f4").tobytes()),
        5: ctx.buffer(model_depths.astype("f4").tobytes()),
        6: ctx.buffer(queries.astype("f4").tobytes()),
        7: results,
    }
    for binding, b in storage.items():
        b.bind_to_storage_buffer(binding)
    uniform = ctx.buffer(struct.pack("<4I4f", int(params[0]), int(params[1]), int(params[2]), 0, float(params[3]), 0, 0, 0))
    uniform.bind_to_uniform_block(3)
    program.run(group_x=(queries.shape[0] + 63) // 64)
    ctx.finish()
    got = np.frombuffer(results.read(), dtype="f4").reshape(-1, 4).astype(np.float64)
    ratio = np.abs(got[:, :3] - expected[:, :3]) / denominator / tolerance[:, None]
    kinds = queries[:, 3].astype(int)
    ams = kinds == 0
    ff_err = float(np.abs(got[ams, 3] - expected[ams, 3]).max())
    renderer = ctx.info["GL_RENDERER"]
    ok = ff_err < 1e-6
    for kind, name in enumerate(KINDS):
        rows_of_kind = np.flatnonzero(kinds == kind)
        if rows_of_kind.size == 0:
            continue
        r = ratio[rows_of_kind]
        i = int(rows_of_kind[np.unravel_index(r.argmax(), r.shape)[0]])
        worst = float(r.max() * tolerance[i])
        ok = ok and r.max() <= 1.0
        print(f"{name}: worst {worst:.2e} (tolerance {tolerance[i]:.0e}; query {i} {queries[i].tolist()}: "
              f"GLSL {got[i].tolist()} vs CPU {expected[i].tolist()})")
    print(f"{'OK' if ok else 'FAILED'}: F_n {ff_err:.1e}; {queries.shape[0]} queries on {renderer}")
    return 0 if ok else 1


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1], sys.argv[2]))
