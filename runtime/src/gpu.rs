//! Uploading checked tables to a wgpu device, with the WGSL sampling functions ([`WGSL`]).
//!
//! # Layout (bind group 0, built once, labelled)
//! - binding 0, `ams_table`: `texture_2d_array<f32>`, width K, height N_max (the largest N of
//!   the selected fields), one layer per field in [`Tables::fields`] order; texel (k, r) of
//!   layer i is Ams_{r+1}(θ_k) of field i as RGBA (A = 0). A field with fewer orders repeats
//!   its last row. Format `Rgba32Float`, or `Rgba16Float` when [`TexelFormat::Auto`] finds every
//!   value inside the half-float normal range (6.1·10⁻⁵ … 65504; a forward bin of large drops
//!   at fine Δθ exceeds it). Sampled with `textureLoad` and interpolated in the shader, so it works on every
//!   backend, with or without `FLOAT32_FILTERABLE`.
//! - binding 1, `ams_forward_fraction`: storage `array<vec4<f32>>`, F_n of field i at
//!   index i·N_max + n − 1.
//! - binding 2, `ams_field_info`: storage `array<vec4<f32>>`, (N, σ_sca R, G, B) per field.
//! - binding 3, `ams_params`: uniform (K, N_max, field count, 1/Δθ in 1/rad).
//! - binding 4, `model_table`: `texture_2d_array<f32>`, width K, height J_P + J_B (the largest
//!   over the fields), one layer per field, `Rgba32Float`: rows 0..J_P the Poisson mixtures
//!   M(D_j, θ_k) (`format::poisson`, Max et al. 2004), rows J_P..J_P + J_B Biri et al.'s
//!   kernel primitive C(τ_j, θ_k − 90°) (`format::biri`), RGB (A = 0). 32-bit always: the
//!   primitive's differences are what a renderer uses.
//! - binding 5, `model_depths`: storage `array<f32>`: per field i the header
//!   (J_P, J_B, index of its first Poisson depth, index of its first Biri depth) at 4i..4i + 3,
//!   then the depths; J_P = J_B = 0 for a field whose bake has no such table (a bake from
//!   before the render models).
//!
//! The WGSL functions (`ams`, `forward_fraction`, `ams_mix`, `poisson`, `biri_primitive`)
//! are specified by [`crate::sample`], their CPU reference.

use std::time::Instant;

use thiserror::Error;
use wgpu::util::DeviceExt;

use crate::load::{FieldTable, Tables};

/// The sampling functions; a shader includes this text and binds [`GpuTables::bind_group`] as
/// group 0.
pub const WGSL: &str = include_str!("tables.wgsl");

crate::uniform! {
    /// `ams_params` (binding 3): the table's sizes and 1/Δθ.
    pub struct AmsParams as "AmsParams" {
        /// K, the angles per row.
        pub angle_count: u32,
        /// N_max, the rows per field in `ams_forward_fraction`.
        pub n_stride: u32,
        /// Fields in the table.
        pub field_count: u32,
        /// Padding.
        pub pad0: u32,
        /// 1/Δθ (1/rad).
        pub inv_step_rad: f32,
        /// Padding.
        pub pad1: f32,
        /// Padding.
        pub pad2: f32,
        /// Padding.
        pub pad3: f32,
    }
}

/// Smallest normal and largest finite half-float.
const F16_MIN_NORMAL: f64 = 6.103_515_625e-5;
const F16_MAX: f64 = 65504.0;

/// Why the GPU path cannot run.
#[derive(Debug, Error)]
pub enum GpuError {
    /// No adapter on any enabled backend; wgpu's reason.
    #[error("no GPU adapter found (any backend; set WGPU_BACKEND to choose one): {0}")]
    NoAdapter(String),
    /// The adapter refused a device, or the device failed while waiting; wgpu's reason.
    #[error("the adapter refused a device: {0}")]
    Device(String),
    /// A size exceeds a device limit.
    #[error("{what} = {value} exceeds this device's limit {limit}")]
    Limit {
        /// What was too large.
        what: &'static str,
        /// The amount asked for (a count or bytes).
        value: u64,
        /// The device's limit.
        limit: u64,
    },
    /// Copying, waiting for or mapping the readback buffer failed; wgpu's reason.
    #[error("reading back from the GPU failed: {0}")]
    Readback(String),
}

/// A headless device; a clone shares the device (wgpu's handles are reference-counted).
#[derive(Clone)]
pub struct Gpu {
    /// The adapter the device was requested from.
    pub adapter: wgpu::Adapter,
    /// The device, with the adapter's full limits and no optional features.
    pub device: wgpu::Device,
    /// The device's queue.
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// The first adapter of the primary backends (Vulkan, Metal, DX12), or of those
    /// WGPU_BACKEND names (e.g. `gl`); WGPU_ADAPTER_NAME respected. OpenGL is left out unless
    /// asked for: probing it without a display prints Mesa's "XDG_RUNTIME_DIR is invalid"
    /// on every run, and Vulkan (lavapipe on a machine without a GPU) serves everywhere else.
    pub fn new() -> Result<Self, GpuError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var_os("WGPU_BACKEND").is_none() {
            descriptor.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(descriptor);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("photometeor device"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Self {
            adapter,
            device,
            queue,
        })
    }

    /// "name (backend, device type)".
    pub fn describe(&self) -> String {
        let i = self.adapter.get_info();
        format!("{} ({:?}, {:?})", i.name, i.backend, i.device_type)
    }
}

/// Texel format of the Ams texture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TexelFormat {
    /// Half floats where every value fits, else 32-bit.
    Auto,
    /// Always `Rgba32Float`.
    F32,
}

/// Tables resident on the GPU.
pub struct GpuTables {
    /// The Ams_n texture array (binding 0): K × N_max texels, one layer per field.
    pub texture: wgpu::Texture,
    /// The texture's format, `Rgba16Float` or `Rgba32Float`.
    pub format: wgpu::TextureFormat,
    /// F_n per field (binding 1).
    pub forward_fraction: wgpu::Buffer,
    /// (N, σ_sca R, G, B) per field (binding 2; σ_sca in m²).
    pub field_info: wgpu::Buffer,
    /// (K, N_max, field count, 1/Δθ in 1/rad) uniform (binding 3).
    pub params: wgpu::Buffer,
    /// The Poisson mixtures and Biri kernel primitives (binding 4), `Rgba32Float`.
    pub model_texture: wgpu::Texture,
    /// Their depths, after a header per field (binding 5).
    pub model_depths: wgpu::Buffer,
    /// The layout of bind group 0.
    pub layout: wgpu::BindGroupLayout,
    /// Bind group 0, binding the four resources above.
    pub bind_group: wgpu::BindGroup,
    /// Rows per layer (the largest N).
    pub n_stride: usize,
    /// Wall time of building and uploading, including a wait for the queue (s).
    pub upload_seconds: f64,
}

/// Whether every texel lies in the half-float normal range (or is 0).
pub fn fits_half(tables: &Tables) -> bool {
    tables.fields.iter().all(|f| {
        f.image
            .ams
            .iter()
            .all(|&v| v == 0.0 || (F16_MIN_NORMAL..=F16_MAX).contains(&v.abs()))
    })
}

impl GpuTables {
    /// Uploads every field of `tables`.
    pub fn upload(gpu: &Gpu, tables: &Tables, format: TexelFormat) -> Result<Self, GpuError> {
        let start = Instant::now();
        let device = &gpu.device;
        let n_stride = tables.fields.iter().map(|f| f.n_max()).max().unwrap_or(1);
        check_table_limits(&device.limits(), tables, n_stride)?;
        let half = format == TexelFormat::Auto && fits_half(tables);
        let texture = upload_ams(gpu, tables, n_stride, half);
        let (ff, info) = forward_fraction_and_info(tables, n_stride);
        let storage = |label: &str, data: &[f32]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(data),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let forward_fraction = storage("photometeor F_n", &ff);
        let field_info = storage("photometeor field info", &info);
        let (model_texture, models) = upload_models(gpu, tables)?;
        let model_depths = storage("photometeor model depths", &models.depths);
        let params = params_buffer(device, tables, n_stride);
        let layout = Self::bind_group_layout(device);
        let bind_group = bind_tables(
            device,
            &layout,
            TableResources {
                texture: &texture,
                forward_fraction: &forward_fraction,
                field_info: &field_info,
                params: &params,
                model_texture: &model_texture,
                model_depths: &model_depths,
            },
        );
        gpu.queue.submit([]);
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Self {
            texture,
            format: ams_texel_format(half),
            forward_fraction,
            field_info,
            params,
            model_texture,
            model_depths,
            layout,
            bind_group,
            n_stride,
            upload_seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The layout of bind group 0 (module docs), visible to compute and fragment stages.
    pub fn bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
        let visibility = wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::FRAGMENT;
        let storage = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let texture_array = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2Array,
                multisampled: false,
            },
            count: None,
        };
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("photometeor tables layout"),
            entries: &[
                texture_array(0),
                storage(1),
                storage(2),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                texture_array(4),
                storage(5),
            ],
        })
    }
}

/// Fails when the Ams texture (K × `n_stride` texels, a layer per field) exceeds a device limit.
fn check_table_limits(
    limits: &wgpu::Limits,
    tables: &Tables,
    n_stride: usize,
) -> Result<(), GpuError> {
    let layers = tables.fields.len().max(1);
    for (what, value, limit) in [
        (
            "angle count K",
            tables.angle_count,
            limits.max_texture_dimension_2d,
        ),
        ("orders N", n_stride, limits.max_texture_dimension_2d),
        ("fields", layers, limits.max_texture_array_layers),
    ] {
        if value as u64 > limit as u64 {
            return Err(GpuError::Limit {
                what,
                value: value as u64,
                limit: limit as u64,
            });
        }
    }
    Ok(())
}

/// The Ams texture's format: `Rgba16Float` with `half`, else `Rgba32Float`.
fn ams_texel_format(half: bool) -> wgpu::TextureFormat {
    if half {
        wgpu::TextureFormat::Rgba16Float
    } else {
        wgpu::TextureFormat::Rgba32Float
    }
}

/// The Ams_n texture array (binding 0), filled layer by layer from [`ams_layer_bytes`].
fn upload_ams(gpu: &Gpu, tables: &Tables, n_stride: usize, half: bool) -> wgpu::Texture {
    let k_len = tables.angle_count;
    let layers = tables.fields.len().max(1);
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("photometeor Ams_n table array"),
        size: wgpu::Extent3d {
            width: k_len as u32,
            height: n_stride as u32,
            depth_or_array_layers: layers as u32,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: ams_texel_format(half),
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let texel_bytes = if half { 8 } else { 16 };
    for (i, f) in tables.fields.iter().enumerate() {
        let bytes = ams_layer_bytes(f, k_len, n_stride, half);
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: 0,
                    y: 0,
                    z: i as u32,
                },
                aspect: wgpu::TextureAspect::All,
            },
            &bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some((k_len * texel_bytes) as u32),
                rows_per_image: Some(n_stride as u32),
            },
            wgpu::Extent3d {
                width: k_len as u32,
                height: n_stride as u32,
                depth_or_array_layers: 1,
            },
        );
    }
    texture
}

/// One field's layer of the Ams texture: texel (k, r) = Ams_{r+1}(θ_k) RGB, A = 0, as half or
/// 32-bit floats; rows past the field's N repeat its last row (module docs).
fn ams_layer_bytes(f: &FieldTable, k_len: usize, n_stride: usize, half: bool) -> Vec<u8> {
    let texel_bytes = if half { 8 } else { 16 };
    let mut bytes = Vec::with_capacity(k_len * n_stride * texel_bytes);
    for r in 0..n_stride {
        let row = r.min(f.n_max() - 1);
        for k in 0..k_len {
            let ams = &f.image.ams;
            let texel = [ams[[0, row, k]], ams[[1, row, k]], ams[[2, row, k]], 0.0];
            for v in texel {
                if half {
                    bytes.extend_from_slice(&half::f16::from_f64(v).to_le_bytes());
                } else {
                    bytes.extend_from_slice(&(v as f32).to_le_bytes());
                }
            }
        }
    }
    bytes
}

/// The contents of bindings 1 and 2 (module docs): F_n per field, `n_stride` rows each (a
/// field with fewer orders repeats its last), and (N, σ_sca R, G, B) per field; one row of
/// each for no fields.
fn forward_fraction_and_info(tables: &Tables, n_stride: usize) -> (Vec<f32>, Vec<f32>) {
    let layers = tables.fields.len().max(1);
    let mut ff = Vec::with_capacity(layers * n_stride * 4);
    let mut info = Vec::with_capacity(layers * 4);
    for f in &tables.fields {
        for n in 0..n_stride {
            let r = n.min(f.n_max() - 1);
            for c in 0..3 {
                ff.push(f.image.forward_fraction[[c, r]] as f32);
            }
            ff.push(0.0);
        }
        info.push(f.n_max() as f32);
        info.extend(f.sigma_sca_m2.iter().map(|&s| s as f32));
    }
    if tables.fields.is_empty() {
        ff.extend([0.0f32; 4]);
        info.extend([1.0f32, 0.0, 0.0, 0.0]);
    }
    (ff, info)
}

/// The `ams_params` uniform (binding 3).
fn params_buffer(device: &wgpu::Device, tables: &Tables, n_stride: usize) -> wgpu::Buffer {
    let inv_step = 1.0 / tables.theta_step_deg.to_radians();
    let params = AmsParams {
        angle_count: tables.angle_count as u32,
        n_stride: n_stride as u32,
        field_count: tables.fields.len() as u32,
        inv_step_rad: inv_step as f32,
        ..Default::default()
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("photometeor table params"),
        contents: bytemuck::bytes_of(&params),
        usage: wgpu::BufferUsages::UNIFORM,
    })
}

/// The resources bind group 0 binds, in binding order.
struct TableResources<'a> {
    texture: &'a wgpu::Texture,
    forward_fraction: &'a wgpu::Buffer,
    field_info: &'a wgpu::Buffer,
    params: &'a wgpu::Buffer,
    model_texture: &'a wgpu::Texture,
    model_depths: &'a wgpu::Buffer,
}

/// Bind group 0 (module docs) over `r`, the textures viewed as 2-D arrays.
fn bind_tables(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    r: TableResources,
) -> wgpu::BindGroup {
    let array_view = |texture: &wgpu::Texture, label| {
        texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some(label),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        })
    };
    let view = array_view(r.texture, "photometeor Ams_n table view");
    let model_view = array_view(r.model_texture, "photometeor model table view");
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("photometeor tables"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(&view),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: r.forward_fraction.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: r.field_info.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: r.params.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: wgpu::BindingResource::TextureView(&model_view),
            },
            wgpu::BindGroupEntry {
                binding: 5,
                resource: r.model_depths.as_entire_binding(),
            },
        ],
    })
}

/// The contents of bindings 4 and 5 (module docs), as plain arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelArrays {
    /// Rows per layer, J_P + J_B at most over the fields (at least 1).
    pub rows: usize,
    /// RGBA texels, layer by layer, row by row, K per row (`model_table`).
    pub texels: Vec<f32>,
    /// The headers, then the depths (`model_depths`).
    pub depths: Vec<f32>,
}

/// Lays out the Poisson mixtures and Biri kernel primitives of `tables` for bindings 4 and 5:
/// zeros (and J_P = J_B = 0) where a field has no such table.
pub fn model_arrays(tables: &Tables) -> ModelArrays {
    let k_len = tables.angle_count;
    let counts = |f: &crate::load::FieldTable| {
        (
            f.poisson.as_ref().map_or(0, |p| p.depths.len()),
            f.biri.as_ref().map_or(0, |b| b.depths.len()),
        )
    };
    let rows = tables
        .fields
        .iter()
        .map(|f| counts(f).0 + counts(f).1)
        .max()
        .unwrap_or(0)
        .max(1);
    let layer = 4 * k_len * rows;
    let mut texels = vec![0f32; layer * tables.fields.len().max(1)];
    let mut header = Vec::with_capacity(4 * tables.fields.len());
    let mut depths = Vec::new();
    let first = 4 * tables.fields.len();
    for (i, f) in tables.fields.iter().enumerate() {
        let (j_p, j_b) = counts(f);
        let at_p = first + depths.len();
        header.extend([j_p as f32, j_b as f32, at_p as f32, (at_p + j_p) as f32]);
        let texels = &mut texels[i * layer..(i + 1) * layer];
        let mut put = |row: usize, values: &ndarray::Array3<f64>, j: usize| {
            for k in 0..k_len {
                for c in 0..3 {
                    texels[4 * (row * k_len + k) + c] = values[[c, j, k]] as f32;
                }
            }
        };
        if let Some(p) = &f.poisson {
            depths.extend(p.depths.iter().map(|&d| d as f32));
            for j in 0..j_p {
                put(j, &p.rows, j);
            }
        }
        if let Some(b) = &f.biri {
            depths.extend(b.depths.iter().map(|&d| d as f32));
            for j in 0..j_b {
                put(j_p + j, &b.primitive, j);
            }
        }
    }
    header.extend(depths);
    if header.is_empty() {
        header.extend([0f32; 4]);
    }
    ModelArrays {
        rows,
        texels,
        depths: header,
    }
}

/// The model table texture (binding 4), filled from [`model_arrays`], and the arrays.
fn upload_models(gpu: &Gpu, tables: &Tables) -> Result<(wgpu::Texture, ModelArrays), GpuError> {
    let device = &gpu.device;
    let k_len = tables.angle_count;
    let arrays = model_arrays(tables);
    let rows = arrays.rows;
    let limit = device.limits().max_texture_dimension_2d;
    if rows as u64 > limit as u64 {
        return Err(GpuError::Limit {
            what: "model table rows J_P + J_B",
            value: rows as u64,
            limit: limit as u64,
        });
    }
    let layers = tables.fields.len().max(1);
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("photometeor model table array"),
        size: wgpu::Extent3d {
            width: k_len as u32,
            height: rows as u32,
            depth_or_array_layers: layers as u32,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    gpu.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(&arrays.texels),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some((k_len * 16) as u32),
            rows_per_image: Some(rows as u32),
        },
        wgpu::Extent3d {
            width: k_len as u32,
            height: rows as u32,
            depth_or_array_layers: layers as u32,
        },
    );
    Ok((texture, arrays))
}

/// What one query of [`evaluate`] looks up.
#[derive(Debug, Clone, Copy)]
pub enum Lookup {
    /// `ams(field, n, cos θ)` and `forward_fraction(field, n)`: scattering order n, fractional
    /// (n < 1 samples Ams_1); θ the scattering angle.
    Ams {
        /// The order n.
        n: f32,
        /// cos θ.
        cos_theta: f32,
    },
    /// `poisson(field, D, cos θ)`: Max et al.'s mixture at optical depth D in every channel.
    Poisson {
        /// The segment's optical depth D.
        depth: f32,
        /// cos θ.
        cos_theta: f32,
    },
    /// `biri_primitive(field, τ_h, θ)`: Biri et al.'s kernel primitive.
    BiriPrimitive {
        /// Optical depth τ_h from the light to the ray's foot point.
        tau_h: f32,
        /// The angle at the light from the foot point, radians in [−π/2, π/2].
        theta_rad: f32,
    },
    /// `ams_sweep(field, count, at_first, at_step, at_value, n, cos θ)` and
    /// `forward_fraction_sweep`: a swept field whose `count` members start at layer `field`.
    Sweep {
        /// The number of members.
        count: u32,
        /// at(v_0): ln v_0 for a log sweep, v_0 for a linear one.
        at_first: f32,
        /// at(v_1) − at(v_0).
        at_step: f32,
        /// at(value) of the size looked up.
        at_value: f32,
        /// The order n.
        n: f32,
        /// cos θ.
        cos_theta: f32,
    },
}

/// One query of [`evaluate`].
#[derive(Debug, Clone, Copy)]
pub struct Query {
    /// Index into [`Tables::fields`].
    pub field: u32,
    /// What to look up.
    pub lookup: Lookup,
}

impl Query {
    /// `ams(field, n, cos θ)` and `forward_fraction(field, n)`.
    pub fn ams(field: u32, n: f32, cos_theta: f32) -> Self {
        let lookup = Lookup::Ams { n, cos_theta };
        Self { field, lookup }
    }

    /// `poisson(field, D, cos θ)`, D in every channel.
    pub fn poisson(field: u32, depth: f32, cos_theta: f32) -> Self {
        let lookup = Lookup::Poisson { depth, cos_theta };
        Self { field, lookup }
    }

    /// `biri_primitive(field, τ_h, θ)`, τ_h in every channel, θ in radians.
    pub fn biri_primitive(field: u32, tau_h: f32, theta_rad: f32) -> Self {
        let lookup = Lookup::BiriPrimitive { tau_h, theta_rad };
        Self { field, lookup }
    }

    /// `ams_sweep` at `value` of `sweep`, whose members are the layers from `first` on.
    pub fn ams_sweep(
        first: u32,
        sweep: &format::SweepEntry,
        value: f64,
        n: f32,
        cos_theta: f32,
    ) -> Self {
        let at = |v: f64| sweep.at(v);
        let lookup = Lookup::Sweep {
            count: sweep.values.len() as u32,
            at_first: at(sweep.values[0]) as f32,
            at_step: (at(sweep.values[1]) - at(sweep.values[0])) as f32,
            at_value: at(value) as f32,
            n,
            cos_theta,
        };
        Self {
            field: first,
            lookup,
        }
    }

    /// The kernel's two vec4 (field, a, b, kind), (c, d, e, f) (shaders::QUERY_KERNEL).
    fn words(&self) -> [f32; 8] {
        let field = self.field as f32;
        match self.lookup {
            Lookup::Ams { n, cos_theta } => [field, n, cos_theta, 0.0, 0.0, 0.0, 0.0, 0.0],
            Lookup::Poisson { depth, cos_theta } => {
                [field, depth, cos_theta, 1.0, 0.0, 0.0, 0.0, 0.0]
            }
            Lookup::BiriPrimitive { tau_h, theta_rad } => {
                [field, tau_h, theta_rad, 2.0, 0.0, 0.0, 0.0, 0.0]
            }
            Lookup::Sweep {
                count,
                at_first,
                at_step,
                at_value,
                n,
                cos_theta,
            } => [
                field,
                n,
                cos_theta,
                3.0,
                count as f32,
                at_first,
                at_step,
                at_value,
            ],
        }
    }
}

/// Evaluates each query's lookup in a compute shader and reads the results back: per query
/// [Ams R, G, B, F_n G], [M R, G, B, 0], [C R, G, B, 0] or a sweep's [Ams R, G, B, F_n G]. Used by the tests and
/// `photometeor` checks.
pub fn evaluate(
    gpu: &Gpu,
    tables: &GpuTables,
    queries: &[Query],
) -> Result<Vec<[f32; 4]>, GpuError> {
    let device = &gpu.device;
    // The sampling functions and the reference kernel `evaluate_queries` (shaders.rs).
    let source = crate::shaders::source();
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("photometeor table queries"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let io_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("photometeor query io"),
        entries: &[0u32, 1].map(|binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage {
                    read_only: binding == 0,
                },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }),
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("photometeor query pipeline layout"),
        bind_group_layouts: &[Some(&tables.layout), Some(&io_layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("photometeor query pipeline"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(crate::shaders::ENTRY_POINT),
        compilation_options: Default::default(),
        cache: None,
    });
    let data: Vec<f32> = queries.iter().flat_map(Query::words).collect();
    let query_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("photometeor queries"),
        contents: bytemuck::cast_slice(&data),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (queries.len() * 16) as u64;
    let results = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("photometeor query results"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let io = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("photometeor query io"),
        layout: &io_layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: query_buffer.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: results.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("photometeor queries"),
    });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("photometeor queries"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &tables.bind_group, &[]);
        pass.set_bind_group(1, &io, &[]);
        pass.dispatch_workgroups(queries.len().div_ceil(64) as u32, 1, 1);
    }
    gpu.queue.submit([encoder.finish()]);
    read_back(gpu, &results, size)
}

/// Copies `size` bytes of `source` (a `COPY_SRC` buffer) into a mappable buffer, waits, and
/// returns them as RGBA f32 quadruples.
pub fn read_back(gpu: &Gpu, source: &wgpu::Buffer, size: u64) -> Result<Vec<[f32; 4]>, GpuError> {
    Readback::new(gpu, size).read(gpu, source, 0, size)
}

/// A mappable buffer to read results back through, kept by a caller that reads many times
/// (an iterative solver's sums each iteration) instead of allocating one per read.
pub struct Readback {
    buffer: wgpu::Buffer,
}

impl Readback {
    /// A readback of at most `size` bytes (a multiple of 16).
    pub fn new(gpu: &Gpu, size: u64) -> Self {
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self { buffer }
    }

    /// Copies `size` bytes of `source` (a `COPY_SRC` buffer) from byte `offset` (both
    /// multiples of 16, `size` at most this readback's), waits, and returns them as RGBA f32
    /// quadruples.
    pub fn read(
        &self,
        gpu: &Gpu,
        source: &wgpu::Buffer,
        offset: u64,
        size: u64,
    ) -> Result<Vec<[f32; 4]>, GpuError> {
        let device = &gpu.device;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("photometeor readback"),
        });
        encoder.copy_buffer_to_buffer(source, offset, &self.buffer, 0, size);
        gpu.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        self.buffer
            .map_async(wgpu::MapMode::Read, ..size, move |r| {
                let _ = tx.send(r);
            });
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let rows = {
            let view = self
                .buffer
                .get_mapped_range(..size)
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            let floats: &[f32] = bytemuck::cast_slice(&view);
            floats
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect()
        };
        self.buffer.unmap();
        Ok(rows)
    }
}
