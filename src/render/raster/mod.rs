//! The rasterizer of `smocap render`: skinned bodies, a floor and a background through the
//! cameras of a rig, offscreen on wgpu (any Vulkan, Metal or DX12 adapter; lavapipe on CPUs).
//!
//! Per camera, one render pass draws the bodies ([`passes::BodyPass`]) then the floor
//! ([`passes::FloorPass`]) into three targets read back together ([`targets::Targets`]): RGB
//! (Lambert shading), depth along the camera axis (m, the bodies only, 0 elsewhere) and segment
//! labels (the bodies only, 0 background). The projection is exactly [`Camera::project`]'s
//! (OpenCV pinhole with principal point; the rigs have no distortion). Skinning is on the CPU
//! ([`crate::body::Dressed::pose`], ~60 µs a frame, BENCHMARKS.md): uploading 13 380 posed
//! vertices a frame costs less than a GPU skinning pass would save. Pixels are a function of
//! the inputs and the adapter: the same render twice on one machine gives the same bytes.

pub mod device;
pub mod layout;
pub mod passes;
pub mod targets;

use crate::render::rig::Camera;
pub use device::Gpu;
pub use layout::{Fixed, Lighting, Posed, View};
use nalgebra::Vector3;

/// Errors of the rasterizer.
#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    /// No wgpu adapter at all (tests skip on this).
    #[error("{0}")]
    NoAdapter(String),
    #[error("wgpu device: {0}")]
    Device(String),
}

/// The images of one camera: RGB (3 bytes a pixel, row-major from the top left), segment
/// labels (0 background) and depth along the camera axis (m; 0 where no body).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Images {
    pub size: (u32, u32),
    pub rgb: Vec<u8>,
    pub mask: Vec<u16>,
    pub depth_m: Vec<f32>,
}

impl Images {
    /// Sizes the buffers for `size` (keeps their allocations when it is unchanged).
    pub fn resize(&mut self, size: (u32, u32)) {
        let n = size.0 as usize * size.1 as usize;
        self.size = size;
        self.rgb.resize(3 * n, 0);
        self.mask.resize(n, 0);
        self.depth_m.resize(n, 0.0);
    }

    /// Pixel `(x, y)`'s index, or `None` outside the image.
    pub fn index(&self, x: i64, y: i64) -> Option<usize> {
        let (w, h) = (self.size.0 as i64, self.size.1 as i64);
        (x >= 0 && y >= 0 && x < w && y < h).then(|| (y * w + x) as usize)
    }
}

/// What surrounds the bodies: lighting, floor and the background colour (sRGB bytes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scene {
    pub lighting: Lighting,
    pub background: [u8; 3],
}

/// A scene's meshes on a device, with everything a frame needs created once.
pub struct Rasterizer {
    gpu: Gpu,
    body: passes::BodyPass,
    floor: passes::FloorPass,
    bind_layout: wgpu::BindGroupLayout,
    uniforms: Option<(wgpu::Buffer, wgpu::BindGroup, usize)>,
    stride: u64,
    targets: Vec<targets::Targets>,
    triangles: Vec<[u32; 3]>,
    posed: Vec<Posed>,
    origin: Vector3<f64>,
}

impl Rasterizer {
    /// The meshes of a scene: every vertex's colour and label (`fixed`) and the triangles over
    /// them (counter-clockwise seen from outside).
    pub fn new(gpu: Gpu, fixed: &[Fixed], triangles: &[[u32; 3]]) -> Rasterizer {
        let shared = passes::Shared::new(&gpu.device);
        let body = passes::BodyPass::new(&gpu.device, &shared, fixed, triangles);
        let floor = passes::FloorPass::new(&gpu.device, &shared);
        let stride = (std::mem::size_of::<View>() as u64)
            .next_multiple_of(gpu.device.limits().min_uniform_buffer_offset_alignment as u64);
        Rasterizer {
            body,
            floor,
            bind_layout: shared.bind_layout,
            uniforms: None,
            stride,
            targets: Vec::new(),
            triangles: triangles.to_vec(),
            posed: vec![Posed::default(); fixed.len()],
            origin: Vector3::zeros(),
            gpu,
        }
    }

    /// The adapter drawn on.
    pub fn adapter(&self) -> &str {
        &self.gpu.adapter
    }

    /// This frame's vertices (`world`, m; one per fixed vertex): uploaded relative to `origin`
    /// (a point near them, so that the shader's f32 keeps sub-micrometre detail), with
    /// area-weighted vertex normals. Allocates nothing.
    pub fn set_pose(&mut self, vertices: &[[f32; 3]], origin: Vector3<f64>) {
        self.origin = origin;
        for (p, v) in self.posed.iter_mut().zip(vertices) {
            let rel = |k: usize| (v[k] as f64 - origin[k]) as f32;
            *p = Posed { pos: [rel(0), rel(1), rel(2)], normal: [0.0; 3] };
        }
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| Vector3::from(self.posed[i as usize].pos));
            let n = (b - a).cross(&(c - a));
            for &i in t {
                let m = &mut self.posed[i as usize].normal;
                *m = [m[0] + n.x, m[1] + n.y, m[2] + n.z];
            }
        }
        for p in &mut self.posed {
            let n = Vector3::from(p.normal).try_normalize(1e-20).unwrap_or(Vector3::z());
            p.normal = [n.x, n.y, n.z];
        }
        self.body.upload(&self.gpu.queue, &self.posed);
    }

    fn uniforms(&mut self, cameras: usize) -> &(wgpu::Buffer, wgpu::BindGroup, usize) {
        if self.uniforms.as_ref().is_none_or(|u| u.2 < cameras) {
            let buf = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("views"),
                size: self.stride * cameras as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let group = self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("views"),
                layout: &self.bind_layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &buf,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<View>() as u64),
                    }),
                }],
            });
            self.uniforms = Some((buf, group, cameras));
        }
        self.uniforms.as_ref().expect("just made")
    }

    /// Draws the posed scene through each camera into `out` (one per camera).
    pub fn draw(&mut self, cameras: &[Camera], scene: &Scene, out: &mut [Images]) -> Result<(), RasterError> {
        assert_eq!(cameras.len(), out.len(), "one image set per camera");
        let stride = self.stride;
        self.uniforms(cameras.len());
        let buf = &self.uniforms.as_ref().expect("made above").0;
        for (c, cam) in cameras.iter().enumerate() {
            let view = View::new(cam, &self.origin, &scene.lighting);
            self.gpu.queue.write_buffer(buf, c as u64 * stride, bytemuck::bytes_of(&view));
        }
        // Cameras grouped by image size: one set of targets each, one read-back slot per camera.
        let mut slots: Vec<(usize, usize)> = Vec::with_capacity(cameras.len());
        for cam in cameras {
            let size = (cam.width_px, cam.height_px);
            let t = match self.targets.iter().position(|t| t.size == size) {
                Some(t) => t,
                None => {
                    self.targets.push(targets::Targets::new(&self.gpu.device, size));
                    self.targets.len() - 1
                }
            };
            slots.push((t, slots.iter().filter(|s| s.0 == t).count()));
        }
        let mut enc = self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        let bg = scene.background.map(|b| b as f64 / 255.0);
        for (c, &(t, slot)) in slots.iter().enumerate() {
            let group = &self.uniforms.as_ref().expect("written above").1;
            let tg = &self.targets[t];
            let attach = |view, clear: wgpu::Color| {
                Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
                })
            };
            {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("camera"),
                    color_attachments: &[
                        attach(&tg.rgb, wgpu::Color { r: bg[0], g: bg[1], b: bg[2], a: 1.0 }),
                        attach(&tg.depth, wgpu::Color::TRANSPARENT),
                        attach(&tg.segment, wgpu::Color::TRANSPARENT),
                    ],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &tg.zbuffer,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(0.0),
                            store: wgpu::StoreOp::Discard,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_bind_group(0, group, &[(c as u64 * stride) as u32]);
                self.body.draw(&mut pass);
                if scene.lighting.draw_floor {
                    self.floor.draw(&mut pass);
                }
            }
            self.targets[t].copy_out(&self.gpu.device, &mut enc, slot);
        }
        self.gpu.queue.submit([enc.finish()]);
        for (t, tg) in self.targets.iter().enumerate() {
            let mine: Vec<usize> = (0..cameras.len()).filter(|&c| slots[c].0 == t).collect();
            if mine.is_empty() {
                continue;
            }
            let mut group: Vec<Images> = mine.iter().map(|&c| std::mem::take(&mut out[c])).collect();
            tg.read(&self.gpu.device, mine.len(), &mut group)?;
            for (&c, img) in mine.iter().zip(group) {
                out[c] = img;
            }
        }
        Ok(())
    }
}
