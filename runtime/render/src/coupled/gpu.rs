//! The `coupled` model's gather on wgpu (`gather.wgsl`): one compute invocation per pixel
//! marches the ray through the grid as [`super::gather::gather`] does, in f32, reading the
//! per-voxel [`Lighting`] the CPU computed (the beam, the diffusion's I_0 and I_1, the reduced
//! skylight). That lighting depends on the sun, the sky and the cloud, not on the camera: a
//! camera that moves needs only this gather again (`photometeor bench render --model coupled`
//! times both).
//!
//! Bind group 0: the tables ([`GpuTables`]: `ams_mix`). Bind group 1: the params uniform, the
//! densities, the lighting (a [`LightVoxel`] per voxel), the image (rgb, T_vol), the phase functions
//! blurred by the forward peak ([`super::peak`]), the transport's moments (a [`Moments`] per
//! voxel of its grid, the frame's or its blocks').
//!
//! The lighting, the blurred phase functions and the moments are uploaded once per lighting
//! and kept on the GPU while views of it are gathered (the viewer's camera moves): a view then
//! uploads only its parameters, the densities and its image. On dense_cumulus (128 × 70 × 128,
//! the transport on 64 × 35 × 64 blocks) they take 87.5 + 41.6 MiB in f32; before, every view
//! converted and uploaded 420 MiB, the moments interpolated to every voxel of the grid.
//! Between the steps of one relight ([`Lighting::relight`]) only the moments change, and where
//! the transport ran on this device the gather binds its buffer of them in place
//! ([`Lighting::sh_on_gpu`]): a step then uploads nothing of the lighting.

use std::sync::{Arc, Mutex, Weak};
use std::time::Instant;

use rayon::prelude::*;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables};

use super::Settings;
use super::light::{Lighting, check, delta_scaled};
use crate::gpu::{
    FieldsAndSky, GatherView, Grid, RenderError, Sky, Timings, View, a3, bind, build,
    fields_and_sky, filled, gather_source, gather_view, sky_light_buffer, storage, timed_frame, v3,
};
use crate::{frame::Frame, image::Image, volume::MAX_FIELDS};

runtime::uniform! {
    /// `CoupledParams` of `gather.wgsl`.
    pub struct CoupledParams as "CoupledParams" {
        /// The camera.
        pub view: View,
        /// The grid and the ground.
        pub grid: Grid,
        /// Width, height.
        pub sizes: [u32; 2],
        /// The march's step (m).
        pub march_step: f32,
        /// Padding.
        pub pad_step: f32,
        /// The transport grid's upper corner (its lower is the frame grid's).
        pub sh_max: [f32; 3],
        /// Padding.
        pub pad0: f32,
        /// The transport grid's voxels along x, y, z.
        pub sh_dims: [u32; 3],
        /// Padding.
        pub pad1: u32,
        /// 1: the δ-split (f = g², δ-scaled gather).
        pub delta_split: u32,
        /// 1: the P1 radiance (0: I_0 alone).
        pub p1_radiance: u32,
        /// 1: the transport's moments.
        pub transport_moments: u32,
        /// 1: the sun's single scattering blurred by the forward peak (coupled::peak).
        pub peak_blur: u32,
        /// Per field, σ_ext per channel (m²).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// Per field, g per channel.
        pub asymmetry: [[f32; 4]; MAX_FIELDS],
        /// Per field, the forward peak f per channel; w = the blur's peak share s (green).
        pub peak: [[f32; 4]; MAX_FIELDS],
        /// Per Legendre degree l ≤ 4 and field, the phase function's χ_l per channel.
        pub chi: [[[f32; 4]; MAX_FIELDS]; 5],
        /// The sun and the air.
        pub sky: Sky,
    }
}

runtime::uniform! {
    /// `Channel` of `gather.wgsl`: one channel's diffusion flux and skylight.
    pub struct Channel as "Channel" {
        /// The diffusion's I_1 (x, y, z).
        pub i1: [f32; 3],
        /// The skylight's mean.
        pub sky_mean: f32,
    }
}

/// Rows of four the transport's 75 moments take per voxel of its grid.
const SH_ROWS: usize = crate::lighting::transport::PER_VOXEL.div_ceil(4);

runtime::uniform! {
    /// `Moments` of `gather.wgsl`: a voxel's 75 moments of the transport (25 per channel, R
    /// then G then B), four a row, zero past the last.
    pub struct Moments as "Moments" {
        /// The rows.
        pub rows: [[f32; 4]; SH_ROWS],
    }
}

runtime::uniform! {
    /// `LightVoxel` of `gather.wgsl`: a voxel's [`Lighting`] in f32.
    pub struct LightVoxel as "LightVoxel" {
        /// The beam I per channel.
        pub beam: [f32; 3],
        /// The peak's depth n.
        pub peak_depth: f32,
        /// The diffusion's I_0 per channel.
        pub i0: [f32; 3],
        /// 1 if in the diffusion solve, else 0.
        pub in_solve: f32,
        /// Per channel, its flux and skylight.
        pub channel: [Channel; 3],
    }
}

/// The bytes of the two large buffers the gather binds for a lighting of `voxels` voxels
/// whose transport's moments are at `moments` voxels (0 without the transport): its rows per
/// voxel, and the moments. Each must be within the adapter's storage-binding limit.
pub fn binding_sizes(voxels: usize, moments: usize) -> [(&'static str, u64); 2] {
    [
        (
            "the lighting",
            (std::mem::size_of::<LightVoxel>() * voxels) as u64,
        ),
        (
            "the transport's moments",
            (std::mem::size_of::<Moments>() * moments) as u64,
        ),
    ]
}

/// A lighting's buffers on the GPU, kept while its views are gathered (module docs).
struct Resident {
    /// The lighting they hold (weak: the renderer does not keep a lighting alive, and an
    /// allocation a `Weak` points to is not reused, so a live match is the same lighting).
    of: Weak<Lighting>,
    /// The relight it came from ([`Lighting::relight`]): its other steps' lightings keep
    /// `lighting` and `blurred` and bring their own moments.
    relight: Weak<()>,
    lighting: wgpu::Buffer,
    moments: wgpu::Buffer,
    blurred: wgpu::Buffer,
}

/// The gather's WGSL ([`crate::gpu::gather_source`] puts the shared parts before it).
pub const GATHER_WGSL: &str = include_str!("gather.wgsl");

/// The model's whole shader module, as the renderer compiles it: the blur table's depths
/// ([`super::peak::DEPTH_STEP`], [`super::peak::DEPTHS`]) as constants before the gather.
pub fn source() -> String {
    let depths = format!(
        "const PEAK_DEPTH_STEP: f32 = {:?};\nconst PEAK_DEPTHS: u32 = {}u;\n",
        super::peak::DEPTH_STEP as f32,
        super::peak::DEPTHS
    );
    gather_source(&format!("{depths}{GATHER_WGSL}"))
}

/// The gather's pipeline, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    /// The per-sun passes' pipelines, compiled on first use.
    per_sun: crate::lighting::Pipelines,
    /// The last lighting's buffers: a view of the same lighting uploads only its own.
    resident: Mutex<Option<Resident>>,
}

/// Per field, a per-channel quantity as the uniform's rows (zero past the fields).
fn per_field(values: &[[f64; 3]]) -> [[f32; 4]; MAX_FIELDS] {
    std::array::from_fn(|f| {
        values
            .get(f)
            .map_or([0.0; 4], |v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
    })
}

/// Per field, the forward peak f per channel and the blur's peak share s (green) as w.
fn peaks(lighting: &Lighting) -> [[f32; 4]; MAX_FIELDS] {
    let mut rows = per_field(&lighting.peak);
    if let Some(blur) = &lighting.blur {
        for (row, field) in rows.iter_mut().zip(&blur.fields) {
            row[3] = field.share[1] as f32;
        }
    }
    rows
}

impl Renderer {
    /// Compiles `gather.wgsl` after the tables' and the slicing renderers' WGSL, `tables`'
    /// layout as bind group 0.
    pub fn new(gpu: &Gpu, tables: &GpuTables) -> Self {
        // Bindings: params, densities and lighting (read-only), image, the blurred phase
        // functions and the transport's moments (read-only).
        let (layout, pipelines) = build(
            gpu,
            tables,
            "photometeor coupled gather",
            source(),
            (6, true),
            &[1, 2, 4, 5],
            &["gather"],
        );
        let [pipeline] = <[_; 1]>::try_from(pipelines).expect("one pipeline");
        Self {
            layout,
            pipeline,
            per_sun: crate::lighting::Pipelines::default(),
            resident: Mutex::new(None),
        }
    }

    /// The per-sun passes on `gpu` (the adapter this renderer was built for), each compiled
    /// on its first use.
    pub fn per_sun<'a>(&'a self, gpu: &'a Gpu) -> crate::lighting::OnGpu<'a> {
        self.per_sun.on(gpu)
    }

    /// Step 4 of the model for `frame` from `lighting` ([`super::light::light`] of a frame with
    /// the same grid and sun), as [`super::gather::gather`]. The lighting's buffers stay on the
    /// GPU until a view of another lighting: the next view of this one uploads only its own
    /// parameters, densities and image.
    pub fn gather(
        &self,
        gpu: &Gpu,
        tables: &Tables,
        gpu_tables: &GpuTables,
        frame: &Frame,
        settings: &Settings,
        lighting: &Arc<Lighting>,
    ) -> Result<(Image, Timings), RenderError> {
        check(tables, frame, settings)?;
        lighting.check_frame(frame)?;
        let device = &gpu.device;
        let start = Instant::now();
        let (w, h) = (frame.width, frame.height);
        let grid = &frame.grid;
        let voxels = grid.data.len();
        let transport = lighting.has_transport();
        let GatherView { view, step } =
            gather_view(device, frame, std::mem::size_of::<LightVoxel>() as u64)?;
        let FieldsAndSky { sigma_ext, sky } = fields_and_sky(tables, frame);
        let params = CoupledParams {
            view,
            grid: Grid::of(frame, tables.fields.len()),
            sizes: [w as u32, h as u32],
            march_step: step as f32,
            pad_step: 0.0,
            sh_max: v3(lighting.sh_grid.max_m),
            pad0: 0.0,
            sh_dims: lighting.sh_grid.dims.map(|n| n as u32),
            pad1: 0,
            delta_split: u32::from(delta_scaled(settings)),
            p1_radiance: u32::from(settings.emergent == super::Emergent::P1),
            transport_moments: u32::from(transport),
            peak_blur: u32::from(lighting.blur.is_some()),
            sigma_ext,
            asymmetry: per_field(&lighting.g),
            peak: peaks(lighting),
            chi: std::array::from_fn(|l| {
                per_field(&lighting.chis.iter().map(|m| m[l]).collect::<Vec<_>>())
            }),
            sky,
        };
        let mut resident = self.resident.lock().expect("not poisoned");
        let kept = resident
            .as_ref()
            .and_then(|r| r.of.upgrade())
            .is_some_and(|of| Arc::ptr_eq(&of, lighting));
        if !kept {
            let same_relight = resident
                .as_ref()
                .and_then(|r| r.relight.upgrade())
                .is_some_and(|of| Arc::ptr_eq(&of, &lighting.relight));
            match resident.as_mut() {
                // Another step of the same relight: only its moments are new.
                Some(held) if same_relight => {
                    held.moments = moments_buffer(device, lighting);
                    held.of = Arc::downgrade(lighting);
                }
                _ => {
                    // The old lighting's buffers go before the new ones are made.
                    *resident = None;
                    *resident = Some(upload(device, lighting, voxels));
                }
            }
        }
        let held = resident.as_ref().expect("uploaded");
        let params = filled(
            device,
            "photometeor coupled params",
            bytemuck::bytes_of(&params),
            wgpu::BufferUsages::UNIFORM,
        );
        let density = filled(
            device,
            "photometeor coupled densities",
            bytemuck::cast_slice(&grid.data),
            wgpu::BufferUsages::STORAGE,
        );
        let image = storage(
            device,
            "photometeor coupled image",
            16 * (w * h) as u64,
            true,
        );
        let bind_group = bind(
            device,
            &self.layout,
            "photometeor coupled gather bindings",
            &[
                &params,
                &density,
                &held.lighting,
                &image,
                &held.blurred,
                &held.moments,
            ],
            Some(&sky_light_buffer(
                device,
                frame,
                Some(lighting.shadow.gpu_rows()),
            )),
        );
        timed_frame(
            gpu,
            start,
            |pass| {
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &gpu_tables.bind_group, &[]);
                pass.set_bind_group(1, &bind_group, &[]);
                pass.dispatch_workgroups(w.div_ceil(8) as u32, h.div_ceil(8) as u32, 1);
            },
            &image,
            (w, h),
        )
        .map_err(Into::into)
    }
}

/// `lighting`'s buffers for the gather (`voxels` of the frame's grid): its [`LightVoxel`]s, the
/// blurred phase functions (one unread value without the δ-split) and the transport's moments
/// ([`moments_buffer`]).
fn upload(device: &wgpu::Device, lighting: &Arc<Lighting>, voxels: usize) -> Resident {
    // Converted on every thread (dense_cumulus, 1.1 M voxels, a first view at 64 × 48 on 2
    // cores and lavapipe: 0.45 s with the conversion on one thread, 0.38 s).
    let rows: Vec<LightVoxel> = (0..voxels)
        .into_par_iter()
        .map(|i| {
            let [r, g, b, n] = lighting.buffer[i];
            LightVoxel {
                beam: a3([r, g, b]),
                peak_depth: n as f32,
                i0: a3(lighting.i0[i]),
                in_solve: f32::from(u8::from(lighting.active[i])),
                channel: std::array::from_fn(|c| {
                    let i1 = &lighting.p1[i][3 * c..3 * c + 3];
                    Channel {
                        i1: a3([i1[0], i1[1], i1[2]]),
                        sky_mean: lighting.sky_mean[i][c] as f32,
                    }
                }),
            }
        })
        .collect();
    let blurred = lighting.blur.as_ref().map_or(vec![0.0f32], |b| b.rows());
    let storage =
        |label: &str, bytes: &[u8]| filled(device, label, bytes, wgpu::BufferUsages::STORAGE);
    Resident {
        of: Arc::downgrade(lighting),
        relight: Arc::downgrade(&lighting.relight),
        lighting: storage("photometeor coupled lighting", bytemuck::cast_slice(&rows)),
        moments: moments_buffer(device, lighting),
        blurred: storage(
            "photometeor coupled blurred phase functions",
            bytemuck::cast_slice(&blurred),
        ),
    }
}

/// The transport's moments of `lighting` for the gather (one unread row without the
/// transport): the buffer they were computed in where that is on this device, else uploaded.
fn moments_buffer(device: &wgpu::Device, lighting: &Lighting) -> wgpu::Buffer {
    if let Some(m) = lighting
        .sh_on_gpu
        .as_ref()
        .filter(|m| &m.gpu.device == device)
    {
        return m.buffer.clone();
    }
    let mut moments: Vec<Moments> = lighting
        .sh
        .par_iter()
        .map(|m| Moments {
            rows: std::array::from_fn(|r| {
                std::array::from_fn(|j| m.get(4 * r + j).map_or(0.0, |&v| v as f32))
            }),
        })
        .collect();
    if moments.is_empty() {
        moments.push(Moments::default());
    }
    filled(
        device,
        "photometeor coupled transport moments",
        bytemuck::cast_slice(&moments),
        wgpu::BufferUsages::STORAGE,
    )
}
