// The records every renderer's uniform holds (included before slicing.wgsl and biri.wgsl):
// the camera, and for the grid models the grid, the sun and sky, and the plane of a texture
// that looks along the sunlight. Scalars sit in records rather than as fields of a uniform of
// their own: as separate fields, lavapipe ran the truth's paths 5.7× and miyazaki's frame 1.2×
// slower (docs/log.md).

// The camera of a view (render::camera::Camera; mirrored by render::gpu::View).
struct View {
    eye: vec3<f32>,                // the eye, or an orthographic image's centre (m)
    tan_half_fov: f32,             // tan(fov_y / 2) of a perspective camera
    forward: vec3<f32>,            // the unit view direction
    aspect: f32,                   // the image's width / height
    right: vec3<f32>,              // the unit right axis
    ortho_half_height: f32,        // an orthographic image's half height (m); 0: perspective
    up: vec3<f32>,                 // the unit up axis
    pad: f32,
}

// The volumes' grid (render::volume::DensityGrid) and the ground below it (mirrored by
// render::gpu::Grid).
struct Grid {
    min: vec3<f32>,                // the box's lower corner (m)
    ground_albedo: f32,            // the ground's (Lambertian; 0: black)
    max: vec3<f32>,                // its upper corner (m)
    pad: f32,
    dims: vec3<u32>,               // voxels along x, y, z
    fields: u32,                   // the field count
}

// The sun and the air (render::sky::Atmosphere; mirrored by render::gpu::Sky).
struct Sky {
    beta: vec3<f32>,               // the air's β at sea level per channel (1/m)
    inv_scale_height: f32,         // γ, its 1/H (1/m)
    sun: vec3<f32>,                // the unit vector towards the sun
    cos_disk: f32,                 // cos of the disk's radius
    irradiance: vec3<f32>,         // the sun's, per channel
    disk_sr: f32,                  // the disk's solid angle (sr)
}

// A texture on a plane across the sunlight (riley's light buffer, miyazaki's shadow surface;
// mirrored by render::gpu::TexturePlane): texel (i, j) is centred at
// u (u_origin + (i + ½) texel.x) + w (w_origin + (j + ½) texel.y).
struct TexturePlane {
    u: vec3<f32>,                  // the unit axis u
    u_origin: f32,                 // the texture's origin along u (m)
    w: vec3<f32>,                  // the unit axis w
    w_origin: f32,                 // its origin along w (m)
    texel: vec2<f32>,              // texel size along u, w (m)
    pad0: f32,
    pad1: f32,
}
