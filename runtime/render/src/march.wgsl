// The grid gathers' shared steps (`max` and `coupled`), after slicing.wgsl and compose.wgsl;
// their params give the march's step in eye.w and the unit vector towards the sun in sun.xyz,
// and each binds its per-voxel rows as `lighting`.

// Row `row` of the per-voxel lighting (`stride` rows a voxel) trilinear at p (voxel centres,
// clamped to the edge voxels, as DensityGrid::taps), over the voxels in the diffusion solve only
// when `masked` (row `mask_row`'s w nonzero; renormalized over them); zero outside the box or
// where no such voxel contributes.
fn lighting_at(p: vec3<f32>, stride: u32, row: u32, mask_row: u32, masked: bool) -> vec4<f32> {
    if (!inside_box(p)) {
        return vec4<f32>(0.0);
    }
    let tap = taps(p);
    var sum = vec4<f32>(0.0);
    var total = 0.0;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        let d = vec3<u32>(corner & 1u, (corner >> 1u) & 1u, (corner >> 2u) & 1u);
        let w3 = select(1.0 - tap.t, tap.t, d == vec3<u32>(1u));
        let w = w3.x * w3.y * w3.z;
        if (w == 0.0) {
            continue;
        }
        let at = tap.lo + d * tap.s;
        let i = at.x + rp.grid_dims.x * (at.y + rp.grid_dims.y * at.z);
        if (masked && lighting[stride * i + mask_row].w == 0.0) {
            continue;
        }
        total = total + w;
        sum = sum + w * lighting[stride * i + row];
    }
    if (masked) {
        return select(vec4<f32>(0.0), sum / total, total > 0.0);
    }
    return sum;
}

fn scattering_of(rho: vec4<f32>) -> vec3<f32> {
    var s = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid_dims.w; i = i + 1u) {
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
