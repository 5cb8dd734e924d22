//! Biri et al. 2006 on wgpu: stage 1 (silhouettes, §5.1.1, and each light's shadow count at
//! the eye) on the CPU, stages 2–5 in one compute dispatch of `biri.wgsl`, one invocation per
//! pixel, the same per-ray algorithm as [`super::cpu`] in f32. Bind group 0: the tables
//! ([`GpuTables`], uploaded with 32-bit texels; the exact kernel is their `biri_primitive`).
//! Bind group 1: the params uniform, then lights, shadow planes, spheres, meshes, triangles,
//! media and the quartic's coefficients (read-only storage), and the image (rgb, T).

use std::time::Instant;

use glam::DVec3;
use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, WGSL};

use crate::geometry::Sphere;
use crate::gpu::{RenderError, Timings, VIEW_WGSL, View, a4, check_sizes, entry, filled, v4};
use crate::objects::{OccluderShape, Region};
use crate::{checks::FrameError, frame::Frame, image::Image};

/// The model's WGSL (after [`WGSL`]).
pub const BIRI_WGSL: &str = include_str!("biri.wgsl");

/// Spheres one GPU frame can hold (their shadow states at the eye are one u32's bits).
pub const MAX_GPU_SPHERES: usize = 32;

runtime::uniform! {
    /// `Params` of `biri.wgsl`.
    pub struct BiriParams as "Params" {
        /// The camera.
        pub view: View,
        /// The ground's albedo.
        pub ground_albedo: f32,
        /// The kernel table's last depth.
        pub depth_max: f32,
        /// 1: the polynomial kernel, 0: the exact one.
        pub polynomial_kernel: u32,
        /// 1: the surfaces only (stage 2).
        pub surfaces_only: u32,
        /// The image's width.
        pub width: u32,
        /// Its height.
        pub height: u32,
        /// Lights.
        pub lights: u32,
        /// Media.
        pub media: u32,
        /// Sphere occluders.
        pub spheres: u32,
        /// Mesh occluders.
        pub meshes: u32,
        /// Padding.
        pub pad0: u32,
        /// Padding.
        pub pad1: u32,
    }
}

/// The pipeline, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

/// A vector and a u32 (the bits of the row's w) as one vec4<f32> row.
fn with_bits(v: DVec3, bits: u32) -> [f32; 4] {
    let [x, y, z, _] = v4(v, 0.0);
    [x, y, z, f32::from_bits(bits)]
}

/// The model's whole shader module, as the renderer compiles it.
pub fn source() -> String {
    format!("{WGSL}\n{VIEW_WGSL}\n{BIRI_WGSL}")
}

impl Renderer {
    /// Compiles `biri.wgsl` after the tables' WGSL and builds the pipeline, `tables`' layout
    /// as bind group 0.
    pub fn new(gpu: &Gpu, tables: &GpuTables) -> Self {
        let device = &gpu.device;
        use wgpu::BufferBindingType::{Storage, Uniform};
        let entries: Vec<_> = (0..9)
            .map(|b| match b {
                0 => entry(0, Uniform, false),
                8 => entry(8, Storage { read_only: false }, false),
                b => entry(b, Storage { read_only: true }, false),
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("photometeor biri layout"),
            entries: &entries,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("photometeor biri"),
            source: wgpu::ShaderSource::Wgsl(source().into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("photometeor biri pipeline layout"),
            bind_group_layouts: &[Some(&tables.layout), Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("render"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("render"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { layout, pipeline }
    }

    /// Renders `frame` (as [`super::cpu::render`]) with `gpu_tables`, `tables` uploaded with
    /// [`runtime::gpu::TexelFormat::F32`] (half floats would round the kernel's Ams_1 bins);
    /// `Timings::upload` includes stage 1.
    pub fn render(
        &self,
        gpu: &Gpu,
        tables: &Tables,
        gpu_tables: &GpuTables,
        frame: &Frame,
        settings: &super::Settings,
    ) -> Result<(Image, Timings), RenderError> {
        self.render_stages(gpu, tables, gpu_tables, frame, settings, false)
    }

    /// [`Renderer::render`], or with `surfaces_only` stage 2 alone (the surfaces, shaded and
    /// attenuated; no medium contribution): what `bench render --model biri` times to split
    /// the frame into the paper's stages.
    pub fn render_stages(
        &self,
        gpu: &Gpu,
        tables: &Tables,
        gpu_tables: &GpuTables,
        frame: &Frame,
        settings: &super::Settings,
        surfaces_only: bool,
    ) -> Result<(Image, Timings), RenderError> {
        super::check_scene(frame)?;
        let start = Instant::now();
        let device = &gpu.device;
        let (forward, right, up) = frame
            .camera
            .axes()
            .ok_or_else(|| FrameError("camera look_at_m equals position_m".into()))?;
        let spheres: Vec<(&Sphere, f64)> = frame
            .occluders
            .iter()
            .filter_map(|oc| match &oc.shape {
                OccluderShape::Sphere(s) => Some((s, oc.albedo)),
                OccluderShape::Mesh(_) => None,
            })
            .collect();
        if spheres.len() > MAX_GPU_SPHERES {
            return Err(FrameError(format!(
                "the scene has {} sphere occluders; the GPU path holds at most \
                 {MAX_GPU_SPHERES} (render it with --cpu)",
                spheres.len()
            ))
            .into());
        }
        let (lights, planes) = light_rows(frame, &spheres);
        let (sphere_rows, mesh_rows, tri_rows) = occluder_rows(frame, &spheres);
        let (media_rows, polynomials, depth_max) = media_rows(tables, frame)?;
        let (w, h) = (frame.width, frame.height);
        let params = BiriParams {
            view: View::of(frame, (forward, right, up)),
            ground_albedo: frame.ground_albedo as f32,
            depth_max: depth_max as f32,
            polynomial_kernel: u32::from(settings.kernel == super::Kernel::Polynomial),
            surfaces_only: u32::from(surfaces_only),
            width: w as u32,
            height: h as u32,
            lights: frame.lights.len() as u32,
            media: frame.media.len() as u32,
            spheres: spheres.len() as u32,
            meshes: mesh_rows.len() as u32 / 2,
            pad0: 0,
            pad1: 0,
        };
        let image_bytes = 16 * (w * h) as u64;
        check_sizes(
            device,
            &[
                ("image bytes", image_bytes),
                ("polynomial bytes", 4 * polynomials.len() as u64),
                ("triangle bytes", 16 * tri_rows.len() as u64),
            ],
        )?;
        let params = filled(
            device,
            "biri params",
            bytemuck::bytes_of(&params),
            wgpu::BufferUsages::UNIFORM,
        );
        let image = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("biri image"),
            size: image_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let rows = [
            ("biri lights", &lights),
            ("biri planes", &planes),
            ("biri spheres", &sphere_rows),
            ("biri meshes", &mesh_rows),
            ("biri triangles", &tri_rows),
            ("biri media", &media_rows),
        ];
        let bind_group = self.bind(device, &params, &rows, &polynomials, &image);
        Ok(crate::gpu::timed_frame(
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
        )?)
    }

    /// Bind group 1: the params uniform, the row buffers in binding order (wgpu refuses empty
    /// storage buffers: each empty one gets one zero row), the polynomials and the image.
    fn bind(
        &self,
        device: &wgpu::Device,
        params: &wgpu::Buffer,
        rows: &[(&str, &Vec<[f32; 4]>)],
        polynomials: &[f32],
        image: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        let storage = wgpu::BufferUsages::STORAGE;
        let padded = |label: &str, bytes: &[u8]| {
            filled(
                device,
                label,
                if bytes.is_empty() { &[0; 16] } else { bytes },
                storage,
            )
        };
        let mut buffers: Vec<wgpu::Buffer> = rows
            .iter()
            .map(|(label, r)| padded(label, bytemuck::cast_slice(r.as_slice())))
            .collect();
        buffers.push(padded(
            "biri polynomials",
            bytemuck::cast_slice(polynomials),
        ));
        let all: Vec<&wgpu::Buffer> = std::iter::once(params)
            .chain(&buffers)
            .chain(std::iter::once(image))
            .collect();
        let entries: Vec<wgpu::BindGroupEntry> = all
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("photometeor biri bindings"),
            layout: &self.layout,
            entries: &entries,
        })
    }
}

/// Rows of vec4<f32>, as the storage buffers hold them.
type Rows = Vec<[f32; 4]>;

/// Stage 1 per light: its row block (position and the shadow count at the eye; intensity and
/// whether it is a spot; the spot's axis and cosine; its first silhouette plane, their count
/// and which spheres block the eye, as bits) and its meshes' silhouette planes (three rows
/// each: the edge's ends, the plane's normal).
fn light_rows(frame: &Frame, spheres: &[(&Sphere, f64)]) -> (Rows, Rows) {
    let o = frame.camera.position_m;
    let mut lights: Vec<[f32; 4]> = Vec::new();
    let mut planes: Vec<[f32; 4]> = Vec::new();
    for l in &frame.lights {
        let s = l.position_m;
        let first = planes.len() / 3;
        for oc in &frame.occluders {
            if let OccluderShape::Mesh(m) = &oc.shape {
                for p in m.silhouette(s) {
                    planes.push(v4(p.a, p.weight as f64));
                    planes.push(v4(p.b, 0.0));
                    planes.push(v4(p.normal, 0.0));
                }
            }
        }
        let count: usize = frame.occluders.iter().map(|oc| oc.blockers(o, s)).sum();
        let blocked = spheres.iter().enumerate().fold(0u32, |b, (i, (sp, _))| {
            b | (u32::from(sp.blocks(o, s)) << i)
        });
        lights.push(v4(s, count as f64));
        lights.push(a4(l.intensity, if l.spot.is_some() { 1.0 } else { 0.0 }));
        let (axis, cos) = l
            .spot
            .map_or((DVec3::Y, 1.0), |(a, half)| (a, half.to_radians().cos()));
        lights.push(v4(axis, cos));
        lights.push([
            f32::from_bits(first as u32),
            f32::from_bits((planes.len() / 3 - first) as u32),
            f32::from_bits(blocked),
            0.0,
        ]);
    }
    (lights, planes)
}

/// The spheres (centre and radius, albedo), the meshes (bounds with their first triangle and
/// count, as bits) and their triangles (three vertices, the first with the albedo).
fn occluder_rows(frame: &Frame, spheres: &[(&Sphere, f64)]) -> (Rows, Rows, Rows) {
    let mut sphere_rows: Vec<[f32; 4]> = Vec::new();
    for (s, albedo) in spheres {
        sphere_rows.push(v4(s.center, s.radius));
        sphere_rows.push([*albedo as f32, 0.0, 0.0, 0.0]);
    }
    let mut mesh_rows: Vec<[f32; 4]> = Vec::new();
    let mut tri_rows: Vec<[f32; 4]> = Vec::new();
    for oc in &frame.occluders {
        if let OccluderShape::Mesh(m) = &oc.shape {
            let first = tri_rows.len() / 3;
            for t in &m.triangles {
                let [a, b, c] = t.map(|i| m.vertices[i]);
                tri_rows.push(v4(a, oc.albedo));
                tri_rows.push(v4(b, 0.0));
                tri_rows.push(v4(c, 0.0));
            }
            mesh_rows.push(with_bits(m.bounds.0, first as u32));
            mesh_rows.push(with_bits(m.bounds.1, m.triangles.len() as u32));
        }
    }
    (sphere_rows, mesh_rows, tri_rows)
}

/// The media (box or everywhere, their field as bits, β_ext, β_sca, ambient), the quartic's
/// coefficients of their fields (`polynomials[f]` = where field f's start; the exact primitive
/// is in the uploaded tables) and the kernel tables' largest depth.
fn media_rows(tables: &Tables, frame: &Frame) -> Result<(Rows, Vec<f32>, f64), FrameError> {
    let mut fields: Vec<usize> = Vec::new();
    let mut media_rows: Vec<[f32; 4]> = Vec::new();
    let mut depth_max = 0f64;
    for m in &frame.media {
        let index = crate::objects::field_index(tables, &m.field)?;
        let f = &tables.fields[index];
        let b = f.biri.as_ref().ok_or_else(|| {
            FrameError(format!(
                "field {:?} of the bake in {} has no Biri kernel table ({}.biri.exr): bake it \
                 again",
                f.name,
                tables.dir.display(),
                f.name
            ))
        })?;
        depth_max = depth_max.max(*b.depths.last().expect("depths"));
        if !fields.contains(&index) {
            fields.push(index);
        }
        let n = m.number_density_per_m3;
        let (lo, hi, is_box) = match m.region {
            Region::Everywhere => (DVec3::ZERO, DVec3::ZERO, 0.0f64),
            Region::Box { min_m, max_m } => (min_m, max_m, 1.0),
        };
        media_rows.push(v4(lo, is_box));
        media_rows.push(with_bits(hi, index as u32));
        media_rows.push(a4(f.sigma_ext_m2.map(|s| n * s), 0.0));
        media_rows.push(a4(f.sigma_sca_m2.map(|s| n * s), 0.0));
        media_rows.push(a4(m.ambient, 0.0));
    }
    // Fields without media get no coefficients.
    let mut polynomials = vec![0f32; tables.fields.len()];
    for &index in &fields {
        polynomials[index] = polynomials.len() as f32;
        let b = tables.fields[index].biri.as_ref().expect("checked above");
        for c in 0..3 {
            polynomials.extend(b.polynomial[c].iter().map(|&v| v as f32));
        }
    }
    Ok((media_rows, polynomials, depth_max))
}
