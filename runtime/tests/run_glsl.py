#!/usr/bin/env python3
"""Run the checked-in GLSL 450 sampling functions in OpenGL and compare with our CPU sampler.

Usage: python3 runtime/tests/run_glsl.py GLSL_FILE INPUT_DIR REL_TOL

INPUT_DIR holds, as .npy, what runtime::gpu::GpuTables uploads and what the CPU reference
(runtime::sample) gives, written by runtime/tests/shaders.rs:
  texture.npy (layers, n_stride, K, 4), forward_fraction.npy (layers * n_stride, 4),
  field_info.npy (layers, 4), params.npy (angle_count, n_stride, field_count, inv_step_rad),
  queries.npy (Q, 4) = (field, n, cos theta, 0), expected.npy (Q, 4) = (Ams R, G, B, F_n G),
  scale.npy (Q,) = the field's largest Ams_1 (the floor of the relative difference).
The shader is compiled by the OpenGL driver (Mesa's llvmpipe through EGL, headless, via the
`moderngl` package), the six bindings set as its header states (layout(binding = 0..5)), the
kernel `evaluate_queries` dispatched, and the results read back. Prints "OK worst ..." and exits
0 when every query is within REL_TOL, else prints the worst and exits 1; exits 2 when moderngl
or an OpenGL 4.5 context is missing.
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


def main(glsl_file, inputs, rel_tol):
    load = lambda name: np.load(os.path.join(inputs, name + ".npy"))
    texture, ff, info, params = load("texture"), load("forward_fraction"), load("field_info"), load("params")
    queries, expected, scale = load("queries"), load("expected"), load("scale")
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
    buffers = [
        ctx.buffer(ff.astype("f4").tobytes()),
        ctx.buffer(info.astype("f4").tobytes()),
        ctx.buffer(struct.pack("<4I4f", int(params[0]), int(params[1]), int(params[2]), 0, float(params[3]), 0, 0, 0)),
        ctx.buffer(queries.astype("f4").tobytes()),
        ctx.buffer(reserve=queries.shape[0] * 16),
    ]
    for binding, b in zip([1, 2], buffers[:2]):
        b.bind_to_storage_buffer(binding)
    buffers[2].bind_to_uniform_block(3)
    buffers[3].bind_to_storage_buffer(4)
    buffers[4].bind_to_storage_buffer(5)
    program.run(group_x=(queries.shape[0] + 63) // 64)
    ctx.finish()
    got = np.frombuffer(buffers[4].read(), dtype="f4").reshape(-1, 4).astype(np.float64)
    rel = np.abs(got[:, :3] - expected[:, :3]) / (np.abs(expected[:, :3]) + 1e-7 * scale[:, None])
    worst = float(rel.max())
    i = int(np.unravel_index(rel.argmax(), rel.shape)[0])
    ff_err = float(np.abs(got[:, 3] - expected[:, 3]).max())
    where = f"query {i} {queries[i].tolist()}: GLSL {got[i].tolist()} vs CPU {expected[i].tolist()}"
    renderer = ctx.info["GL_RENDERER"]
    if worst < rel_tol and ff_err < 1e-6:
        print(f"OK worst {worst:.2e} ({where}); F_n {ff_err:.1e}; {queries.shape[0]} queries on {renderer}")
        return 0
    print(f"worst {worst:.2e} > {rel_tol} or F_n {ff_err:.1e} ({where}) on {renderer}")
    return 1


if __name__ == "__main__":
    if len(sys.argv) != 4:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1], sys.argv[2], float(sys.argv[3])))
