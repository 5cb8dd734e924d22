// The grid gathers' shared steps (`max` and `coupled`), after slicing.wgsl and compose.wgsl;
// their params give the march's step (march_step) and the sun (sky.sun), and each binds its
// per-voxel `LightVoxel` records as `lighting`.

// The per-voxel lighting at p, trilinear (voxel centres, clamped to the edge voxels, as
// DensityGrid::taps): `all` over the eight voxels around p, `solved` over those in the
// diffusion solve only (the gather's `in_solve`), renormalized over them; zero outside the box
// or where no such voxel contributes. Each gather binds its `LightVoxel` records as `lighting`
// and gives their `weighted_add`, `divided` and `in_solve`.
struct Lit {
    all: LightVoxel,
    solved: LightVoxel,
}

fn lighting_at(p: vec3<f32>) -> Lit {
    var out = Lit(LightVoxel(), LightVoxel());
    if (!inside_box(p)) {
        return out;
    }
    let tap = taps(p);
    var total = 0.0;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        let d = vec3<u32>(corner & 1u, (corner >> 1u) & 1u, (corner >> 2u) & 1u);
        let w3 = select(1.0 - tap.t, tap.t, d == vec3<u32>(1u));
        let w = w3.x * w3.y * w3.z;
        if (w == 0.0) {
            continue;
        }
        let at = tap.lo + d * tap.s;
        let v = lighting[at.x + rp.grid.dims.x * (at.y + rp.grid.dims.y * at.z)];
        out.all = weighted_add(out.all, w, v);
        if (in_solve(v)) {
            total = total + w;
            out.solved = weighted_add(out.solved, w, v);
        }
    }
    if (total > 0.0) {
        out.solved = divided(out.solved, total);
    } else {
        out.solved = LightVoxel();
    }
    return out;
}

fn scattering_of(rho: vec4<f32>) -> vec3<f32> {
    var s = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid.fields; i = i + 1u) {
        s = s + rho[i] * ams_field_info[i].yzw;
    }
    return s;
}

// The fraction of sunlight the volume leaves at a point below the grid (compose.wgsl's ground
// and air): the lighting's shadow map, which the CPU marched (render::lattice::ShadowMap; max
// through β_ext, coupled through its δ-scaled extinction).
fn sun_left(p: vec3<f32>) -> vec3<f32> {
    return shadow_map_at(p);
}
