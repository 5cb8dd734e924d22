// The records every renderer's uniform holds (included before slicing.wgsl and biri.wgsl):
// the camera, and for the grid models the grid and the sun and sky.

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
