//! GPU plumbing every model's renderer shares: the bind-group layout and compute pipelines of a
//! shader compiled after the tables' WGSL, buffers made from bytes, the slice uniforms read
//! with a dynamic offset, a frame recorded into one compute pass, timed and read back, and the
//! limits checked before anything is allocated. Device creation is not here
//! ([`runtime::gpu::Gpu`]): a renderer takes the device it is given.

use std::time::Instant;

use wgpu::util::DeviceExt;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuError, GpuTables, WGSL, read_back};

use crate::{
    camera::SUN_DIAMETER_DEG, checks::FrameError, frame::Frame, image::Image, volume::MAX_FIELDS,
};

/// The pieces the slicing renderers' shaders share (grid sampling, camera rays, the sky).
pub const SLICING_WGSL: &str = concat!(
    include_str!("view.wgsl"),
    "\n",
    include_str!("slicing.wgsl")
);

/// The camera every renderer's uniform holds ([`View`]), included in [`SLICING_WGSL`].
pub const VIEW_WGSL: &str = include_str!("view.wgsl");

/// The pixel around a volume's light (the air, the sun disk, the ground), shared by this
/// renderer's composite and `max`'s gather (after [`SLICING_WGSL`]).
pub const COMPOSE_WGSL: &str = include_str!("compose.wgsl");

/// The grid gathers' shared WGSL (`max`, `coupled`): scattering of a mixture, the march to the
/// sun.
pub const MARCH_WGSL: &str = include_str!("march.wgsl");

/// A grid gather's view of `frame`: the camera's axes and the march's step, half the smallest
/// voxel side (m).
pub(crate) struct GatherView {
    /// The camera.
    pub view: View,
    /// The march's step (m).
    pub step: f64,
}

/// Checks that the densities, `lighting_bytes` per voxel of lighting and the image fit
/// `device`'s limits, and returns the gather's view of `frame`.
pub(crate) fn gather_view(
    device: &wgpu::Device,
    frame: &Frame,
    lighting_bytes: u64,
) -> Result<GatherView, RenderError> {
    let grid = &frame.grid;
    let voxels = grid.data.len() as u64;
    check_sizes(
        device,
        &[
            ("density grid bytes", 16 * voxels),
            ("lighting bytes", lighting_bytes * voxels),
            ("image bytes", 16 * (frame.width * frame.height) as u64),
        ],
    )?;
    let axes = frame
        .camera
        .axes()
        .ok_or_else(|| FrameError("camera look_at_m equals position_m".into()))?;
    let size: [f64; 3] =
        std::array::from_fn(|a| (grid.max_m[a] - grid.min_m[a]) / grid.dims[a] as f64);
    Ok(GatherView {
        view: View::of(frame, axes),
        step: 0.5 * size.iter().copied().fold(f64::INFINITY, f64::min),
    })
}

/// A grid gather's whole shader module: the tables', the slicing renderers', [`COMPOSE_WGSL`],
/// [`MARCH_WGSL`], then `gather`.
pub fn gather_source(gather: &str) -> String {
    slicing_source(&format!("{COMPOSE_WGSL}\n{MARCH_WGSL}\n{gather}"))
}

/// Why a GPU render failed.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The frame's parameters are out of range or its fields do not fit the tables.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The device failed, or a buffer exceeds its limits.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Wall times of one GPU frame (s).
#[derive(Debug, Clone, Copy, Default)]
pub struct Timings {
    /// Density grid and buffers created and uploaded.
    pub upload: f64,
    /// Every pass recorded, submitted and waited for: the frame time.
    pub frame: f64,
    /// Image copied back and mapped.
    pub readback: f64,
}

impl Timings {
    /// "upload U ms, frame F ms, readback R ms", for a summary line.
    pub fn describe(&self) -> String {
        format!(
            "upload {:.1} ms, frame {:.1} ms, readback {:.1} ms",
            self.upload * 1e3,
            self.frame * 1e3,
            self.readback * 1e3
        )
    }
}

/// A compute-visible buffer binding of bind group 1.
pub(crate) fn entry(
    binding: u32,
    ty: wgpu::BufferBindingType,
    dynamic: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Three channels and a scalar as one vec4<f32> row.
pub(crate) fn a4(v: [f64; 3], w: f64) -> [f32; 4] {
    [v[0] as f32, v[1] as f32, v[2] as f32, w as f32]
}

/// Three channels as a vec3<f32> uniform field.
pub(crate) fn a3(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

/// A vector as a vec3<f32> uniform field.
pub(crate) fn v3(v: glam::DVec3) -> [f32; 3] {
    a3(v.to_array())
}

/// A vector and a scalar as one vec4<f32> uniform row.
pub(crate) fn v4(v: glam::DVec3, w: f64) -> [f32; 4] {
    [v[0] as f32, v[1] as f32, v[2] as f32, w as f32]
}

/// What the grid models' uniforms hold of the fields and the sky: each field's σ_ext (m²,
/// [`MAX_FIELDS`] rows, zero past the last field), and the sun and the air ([`Sky`]).
pub(crate) struct FieldsAndSky {
    pub sigma_ext: [[f32; 4]; MAX_FIELDS],
    pub sky: Sky,
}

/// [`FieldsAndSky`] of `tables` and `frame`.
pub(crate) fn fields_and_sky(tables: &Tables, frame: &Frame) -> FieldsAndSky {
    FieldsAndSky {
        sigma_ext: std::array::from_fn(|i| {
            tables
                .fields
                .get(i)
                .map_or([0.0; 4], |f| v4(f.sigma_ext_m2.into(), 0.0))
        }),
        sky: Sky::of(frame),
    }
}

runtime::uniform! {
    /// The volumes' grid and the ground below it (`Grid` in `view.wgsl`).
    pub struct Grid as "Grid" {
        /// The box's lower corner (m).
        pub min: [f32; 3],
        /// The ground's albedo (Lambertian; 0: black).
        pub ground_albedo: f32,
        /// The box's upper corner (m).
        pub max: [f32; 3],
        /// Padding.
        pub pad: f32,
        /// Voxels along x, y, z.
        pub dims: [u32; 3],
        /// The field count.
        pub fields: u32,
    }
}

impl Grid {
    /// `frame`'s grid with `fields` fields, and its ground.
    pub(crate) fn of(frame: &Frame, fields: usize) -> Self {
        Self {
            min: v3(frame.grid.min_m),
            ground_albedo: frame.ground_albedo as f32,
            max: v3(frame.grid.max_m),
            pad: 0.0,
            dims: frame.grid.dims.map(|n| n as u32),
            fields: fields as u32,
        }
    }
}

runtime::uniform! {
    /// The sun and the air (`Sky` in `view.wgsl`).
    pub struct Sky as "Sky" {
        /// The air's β at sea level per channel (1/m).
        pub beta: [f32; 3],
        /// γ, its 1/H (1/m).
        pub inv_scale_height: f32,
        /// The unit vector towards the sun.
        pub sun: [f32; 3],
        /// cos of the disk's radius.
        pub cos_disk: f32,
        /// The sun's irradiance per channel.
        pub irradiance: [f32; 3],
        /// The disk's solid angle (sr).
        pub disk_sr: f32,
    }
}

impl Sky {
    /// `frame`'s sun and air.
    pub(crate) fn of(frame: &Frame) -> Self {
        let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
        Self {
            beta: a3(frame.atmosphere.beta_sea_level_per_m),
            inv_scale_height: (1.0 / frame.atmosphere.scale_height_m) as f32,
            sun: v3(frame.sun.direction()),
            cos_disk: cos_disk as f32,
            irradiance: a3(frame.sun.irradiance),
            disk_sr: (std::f64::consts::TAU * (1.0 - cos_disk)) as f32,
        }
    }
}

runtime::uniform! {
    /// A texture on a plane across the sunlight (`TexturePlane` in `view.wgsl`: riley's light
    /// buffer, miyazaki's shadow surface).
    pub struct TexturePlane as "TexturePlane" {
        /// The unit axis u.
        pub u: [f32; 3],
        /// The texture's origin along u (m).
        pub u_origin: f32,
        /// The unit axis w.
        pub w: [f32; 3],
        /// Its origin along w (m).
        pub w_origin: f32,
        /// Texel size along u, w (m).
        pub texel: [f32; 2],
        /// Padding.
        pub pad0: f32,
        /// Padding.
        pub pad1: f32,
    }
}

impl TexturePlane {
    /// The plane of axes `u`, `w`, origins `origin` and texel sizes `texel` (m).
    pub(crate) fn new(
        (u, w): (glam::DVec3, glam::DVec3),
        origin: [f64; 2],
        texel: [f64; 2],
    ) -> Self {
        Self {
            u: v3(u),
            u_origin: origin[0] as f32,
            w: v3(w),
            w_origin: origin[1] as f32,
            texel: texel.map(|t| t as f32),
            pad0: 0.0,
            pad1: 0.0,
        }
    }
}

runtime::uniform! {
    /// The camera of a view (`View` in `slicing.wgsl`; [`crate::camera::Camera`]).
    pub struct View as "View" {
        /// The eye, or an orthographic image's centre (m).
        pub eye: [f32; 3],
        /// tan(fov_y / 2) of a perspective camera.
        pub tan_half_fov: f32,
        /// The unit view direction.
        pub forward: [f32; 3],
        /// The image's width / height.
        pub aspect: f32,
        /// The unit right axis.
        pub right: [f32; 3],
        /// An orthographic image's half height (m); 0 for a perspective camera.
        pub ortho_half_height: f32,
        /// The unit up axis.
        pub up: [f32; 3],
        /// Padding.
        pub pad: f32,
    }
}

impl View {
    /// `frame`'s camera and image with the camera's `axes` (forward, right, up;
    /// [`crate::camera::Camera::axes`]).
    pub(crate) fn of(
        frame: &Frame,
        (forward, right, up): (glam::DVec3, glam::DVec3, glam::DVec3),
    ) -> Self {
        let camera = &frame.camera;
        Self {
            eye: v3(camera.position_m),
            tan_half_fov: camera.tan_half_fov() as f32,
            forward: v3(forward),
            aspect: (frame.width as f64 / frame.height as f64) as f32,
            right: v3(right),
            ortho_half_height: camera
                .ortho_half_height_m((frame.width, frame.height))
                .unwrap_or(0.0) as f32,
            up: v3(up),
            pad: 0.0,
        }
    }
}

runtime::uniform! {
    /// The per-slice uniform of the slicing models (`SliceParams` in `render.wgsl` and
    /// `svs.wgsl`), read at a dynamic offset.
    pub struct SliceParams as "SliceParams" {
        /// The slice's plane value (m).
        pub plane: f32,
        /// Its index in processing order.
        pub index: u32,
        /// Padding.
        pub pad0: u32,
        /// Padding.
        pub pad1: u32,
    }
}

/// A slicing model's whole shader: [`WGSL`], [`SLICING_WGSL`], then the model's own `wgsl`.
pub fn slicing_source(wgsl: &str) -> String {
    format!("{WGSL}\n{SLICING_WGSL}\n{wgsl}")
}

/// Bind group 1's layout and the compute pipelines `names` of a shader `source` (a whole
/// module, [`slicing_source`]; `tables`' layout as bind group 0).
/// Bind group 1 has `bindings` buffers: 0 the params uniform, 5 the slice uniforms (dynamic
/// offset) unless `read_only` names it, those in `read_only` read-only storage (1, the densities, always among them),
/// every other one read-write storage; and, for a shader with [`COMPOSE_WGSL`], the sky-light
/// table at [`SKY_LIGHT_BINDING`] (`compose` true).
pub(crate) fn build(
    gpu: &Gpu,
    tables: &GpuTables,
    label: &str,
    source: String,
    (bindings, compose): (u32, bool),
    read_only: &[u32],
    names: &[&str],
) -> (wgpu::BindGroupLayout, Vec<wgpu::ComputePipeline>) {
    use wgpu::BufferBindingType::{Storage, Uniform};
    let device = &gpu.device;
    let sky = compose.then_some(SKY_LIGHT_BINDING);
    let entries: Vec<wgpu::BindGroupLayoutEntry> = (0..bindings)
        .chain(sky)
        .map(|b| match b {
            0 => entry(0, Uniform, false),
            // The slicing renderers' per-slice uniform, where binding 5 is not a storage one.
            5 if !read_only.contains(&5) => entry(5, Uniform, true),
            b => entry(
                b,
                Storage {
                    read_only: read_only.contains(&b) || Some(b) == sky,
                },
                false,
            ),
        })
        .collect();
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(&format!("{label} layout")),
        entries: &entries,
    });
    let pipelines = compute_pipelines(device, label, source, &[&tables.layout, &layout], names);
    (layout, pipelines)
}

/// The compute pipelines `names` of the WGSL module `source`, over the bind group `layouts`.
pub(crate) fn compute_pipelines(
    device: &wgpu::Device,
    label: &str,
    source: String,
    layouts: &[&wgpu::BindGroupLayout],
    names: &[&str],
) -> Vec<wgpu::ComputePipeline> {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let layouts: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(|&l| Some(l)).collect();
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(&format!("{label} pipeline layout")),
        bind_group_layouts: &layouts,
        immediate_size: 0,
    });
    names
        .iter()
        .map(|name| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            })
        })
        .collect()
}

/// A buffer holding `bytes`.
pub(crate) fn filled(
    device: &wgpu::Device,
    label: &str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytes,
        usage,
    })
}

/// A storage buffer of `size` bytes; `readable` adds COPY_SRC for the readback.
pub(crate) fn storage(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    readable: bool,
) -> wgpu::Buffer {
    let extra = if readable {
        wgpu::BufferUsages::COPY_SRC
    } else {
        wgpu::BufferUsages::empty()
    };
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::STORAGE | extra,
        mapped_at_creation: false,
    })
}

/// The binding of the sky-light table ([`crate::skylight`]) in bind group 1 of the shaders
/// that compose pixels ([`COMPOSE_WGSL`]).
pub(crate) const SKY_LIGHT_BINDING: u32 = 15;

/// The sky-light table of `frame` as a read-only storage buffer, followed by the grid models'
/// `shadow` map's rows (`ShadowMap::gpu_rows`; two header rows of zeros without one:
/// compose.wgsl's `shadow_map_at`).
pub(crate) fn sky_light_buffer(
    device: &wgpu::Device,
    frame: &Frame,
    shadow: Option<Vec<[f32; 4]>>,
) -> wgpu::Buffer {
    let mut rows = crate::skylight::SkyLight::of(frame).gpu_table();
    rows.extend(shadow.unwrap_or_else(|| vec![[0.0; 4]; 2]));
    filled(
        device,
        "photometeor sky light",
        bytemuck::cast_slice(&rows),
        wgpu::BufferUsages::STORAGE,
    )
}

/// Bind group 1: `buffers[i]` at binding i, whole, except the slice uniforms at binding 5 (a
/// uniform buffer there), bound as one 16-byte entry (the dynamic offset picks the slice); `sky` at
/// [`SKY_LIGHT_BINDING`].
pub(crate) fn bind(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    label: &str,
    buffers: &[&wgpu::Buffer],
    sky: Option<&wgpu::Buffer>,
) -> wgpu::BindGroup {
    let sky = sky.map(|b| wgpu::BindGroupEntry {
        binding: SKY_LIGHT_BINDING,
        resource: b.as_entire_binding(),
    });
    let entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .enumerate()
        .map(|(i, buffer)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: if i == 5 && buffer.usage().contains(wgpu::BufferUsages::UNIFORM) {
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer,
                    offset: 0,
                    size: wgpu::BufferSize::new(16),
                })
            } else {
                buffer.as_entire_binding()
            },
        })
        .chain(sky)
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// Refuses buffers larger than the device's storage-binding limit, naming the buffer.
pub(crate) fn check_sizes(
    device: &wgpu::Device,
    sizes: &[(&'static str, u64)],
) -> Result<(), GpuError> {
    let limit = device.limits().max_storage_buffer_binding_size;
    for &(what, bytes) in sizes {
        if bytes > limit {
            return Err(GpuError::Limit {
                what,
                value: bytes,
                limit,
            });
        }
    }
    Ok(())
}

/// The per-slice uniforms (plane value, index) at the device's dynamic-offset stride: the
/// buffer and the stride.
pub(crate) fn slice_uniforms(device: &wgpu::Device, planes: &[f64]) -> (wgpu::Buffer, usize) {
    let stride = device.limits().min_uniform_buffer_offset_alignment.max(16) as usize;
    let mut bytes = vec![0u8; stride * planes.len()];
    for (k, &plane) in planes.iter().enumerate() {
        let entry = SliceParams {
            plane: plane as f32,
            index: k as u32,
            ..Default::default()
        };
        bytes[k * stride..k * stride + 16].copy_from_slice(bytemuck::bytes_of(&entry));
    }
    let buffer = filled(
        device,
        "photometeor slices",
        &bytes,
        wgpu::BufferUsages::UNIFORM,
    );
    (buffer, stride)
}

/// A compute pipeline and the grid (x, y) it runs over, in 8 × 8 workgroups.
pub(crate) struct Dispatch<'a>(pub &'a wgpu::ComputePipeline, pub (usize, usize));

/// The rest of a slicing frame once its buffers are bound: waits for the uploads (timed from
/// `start`); records `clear`, then for each of `slices` slices every pipeline of `per_slice` in
/// order (bind group 1 at the slice's uniform offset, `k · stride`), then `composite`, in one
/// compute pass (each dispatch sees the previous one's writes); submits, waits, and reads the
/// (rgb, T_vol) image of `size` back.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_slices(
    gpu: &Gpu,
    gpu_tables: &GpuTables,
    bind_group: &wgpu::BindGroup,
    start: Instant,
    (slices, stride): (usize, usize),
    (clear, per_slice, composite): (Dispatch, &[Dispatch], Dispatch),
    image: &wgpu::Buffer,
    size: (usize, usize),
) -> Result<(Image, Timings), GpuError> {
    let groups = |(x, y): (usize, usize)| (x.div_ceil(8) as u32, y.div_ceil(8) as u32);
    timed_frame(
        gpu,
        start,
        |pass| {
            pass.set_bind_group(0, &gpu_tables.bind_group, &[]);
            pass.set_bind_group(1, bind_group, &[0]);
            let run = |d: &Dispatch, pass: &mut wgpu::ComputePass| {
                let (x, y) = groups(d.1);
                pass.set_pipeline(d.0);
                pass.dispatch_workgroups(x, y, 1);
            };
            run(&clear, pass);
            for k in 0..slices {
                pass.set_bind_group(1, bind_group, &[(k * stride) as u32]);
                for d in per_slice {
                    run(d, pass);
                }
            }
            run(&composite, pass);
        },
        image,
        size,
    )
}

/// Records `record` into one compute pass labelled `label` and submits it (without waiting).
pub(crate) fn submit_pass(gpu: &Gpu, label: &str, record: impl FnOnce(&mut wgpu::ComputePass)) {
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        record(&mut pass);
    }
    gpu.queue.submit([encoder.finish()]);
}

/// A frame once its buffers are created (timed from `start`): waits for the uploads,
/// records `record` into one compute pass, submits and waits (the frame time), and reads the
/// (rgb, T) image of `size` back. Shared by every GPU model.
pub(crate) fn timed_frame(
    gpu: &Gpu,
    start: Instant,
    record: impl FnOnce(&mut wgpu::ComputePass),
    image: &wgpu::Buffer,
    size: (usize, usize),
) -> Result<(Image, Timings), GpuError> {
    let device = &gpu.device;
    let wait = || {
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))
    };
    gpu.queue.submit([]);
    wait()?;
    let upload = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("photometeor frame"),
    });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("photometeor frame"),
            timestamp_writes: None,
        });
        record(&mut pass);
    }
    gpu.queue.submit([encoder.finish()]);
    wait()?;
    let frame_time = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let (w, h) = size;
    let texels = read_back(gpu, image, 16 * (w * h) as u64)?;
    let out = Image {
        width: w,
        height: h,
        rgb: texels.iter().map(|c| [c[0], c[1], c[2]]).collect(),
        transparency: texels.iter().map(|c| c[3]).collect(),
    };
    Ok((
        out,
        Timings {
            upload,
            frame: frame_time,
            readback: start.elapsed().as_secs_f64(),
        },
    ))
}
