//! The two pipelines drawn in one render pass per camera: the bodies (colour, depth along the
//! axis, segment labels, depth-buffer writes), then the floor (colour only, behind the bodies).
//! Each owns its buffers, created once; the bodies' posed vertices are rewritten every frame.

use super::layout::{Fixed, Posed, View, FIXED_ATTRIBUTES, FLOOR_ATTRIBUTES, POSED_ATTRIBUTES, SHADER};
use super::targets::{DEPTH_FORMAT, RGB_FORMAT, SEGMENT_FORMAT, ZBUFFER_FORMAT};
use wgpu::util::DeviceExt as _;

/// The pipeline layout both passes share: one uniform `View` with a dynamic offset (one slot
/// per camera).
pub struct Shared {
    pub module: wgpu::ShaderModule,
    pub layout: wgpu::PipelineLayout,
    pub bind_layout: wgpu::BindGroupLayout,
}

impl Shared {
    pub fn new(device: &wgpu::Device) -> Shared {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raster.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<View>() as u64),
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("raster"),
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        Shared { module, layout, bind_layout }
    }
}

/// Colour targets: RGB always; depth and segment written by the bodies only.
fn targets(write_labels: bool) -> [Option<wgpu::ColorTargetState>; 3] {
    let mask = if write_labels { wgpu::ColorWrites::ALL } else { wgpu::ColorWrites::empty() };
    let t = |format, write_mask| Some(wgpu::ColorTargetState { format, blend: None, write_mask });
    [t(RGB_FORMAT, wgpu::ColorWrites::ALL), t(DEPTH_FORMAT, mask), t(SEGMENT_FORMAT, mask)]
}

fn pipeline(
    device: &wgpu::Device,
    shared: &Shared,
    entry: (&str, &str),
    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
    cull: Option<wgpu::Face>,
    write_labels: bool,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(entry.0),
        layout: Some(&shared.layout),
        vertex: wgpu::VertexState {
            module: &shared.module,
            entry_point: Some(entry.0),
            compilation_options: Default::default(),
            buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: cull,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: ZBUFFER_FORMAT,
            depth_write_enabled: Some(write_labels),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &shared.module,
            entry_point: Some(entry.1),
            compilation_options: Default::default(),
            targets: &targets(write_labels),
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The bodies of a scene: every subject's mesh in one vertex and index buffer.
pub struct BodyPass {
    pipeline: wgpu::RenderPipeline,
    posed: wgpu::Buffer,
    fixed: wgpu::Buffer,
    index: wgpu::Buffer,
    indices: u32,
    pub vertices: usize,
}

impl BodyPass {
    /// `fixed`: every vertex's colour and label; `triangles`: indices into them, counter-clockwise
    /// seen from outside (back faces are culled).
    pub fn new(device: &wgpu::Device, shared: &Shared, fixed: &[Fixed], triangles: &[[u32; 3]]) -> BodyPass {
        let posed_layout = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Posed>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &POSED_ATTRIBUTES,
        };
        let fixed_layout = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Fixed>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &FIXED_ATTRIBUTES,
        };
        let pipeline = pipeline(
            device,
            shared,
            ("body_vs", "body_fs"),
            &[Some(posed_layout), Some(fixed_layout)],
            Some(wgpu::Face::Back),
            true,
        );
        let posed = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("posed"),
            size: (std::mem::size_of::<Posed>() * fixed.len().max(1)) as u64,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let init = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let fixed_buf = init("fixed", bytemuck::cast_slice(fixed), wgpu::BufferUsages::VERTEX);
        let index = init("triangles", bytemuck::cast_slice(triangles), wgpu::BufferUsages::INDEX);
        BodyPass {
            pipeline,
            posed,
            fixed: fixed_buf,
            index,
            indices: 3 * triangles.len() as u32,
            vertices: fixed.len(),
        }
    }

    /// Uploads this frame's posed vertices (one per fixed vertex).
    pub fn upload(&self, queue: &wgpu::Queue, posed: &[Posed]) {
        debug_assert_eq!(posed.len(), self.vertices);
        queue.write_buffer(&self.posed, 0, bytemuck::cast_slice(posed));
    }

    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_vertex_buffer(0, self.posed.slice(..));
        pass.set_vertex_buffer(1, self.fixed.slice(..));
        pass.set_index_buffer(self.index.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..self.indices, 0, 0..1);
    }
}

/// Half the floor's side (m): a square this far around the upload origin.
pub const FLOOR_HALF_M: f32 = 60.0;

/// The floor: a square on `world` z = 0 around the upload origin, drawn after the bodies,
/// depth-tested against them, writing colour only.
pub struct FloorPass {
    pipeline: wgpu::RenderPipeline,
    quad: wgpu::Buffer,
}

impl FloorPass {
    pub fn new(device: &wgpu::Device, shared: &Shared) -> FloorPass {
        let layout = wgpu::VertexBufferLayout {
            array_stride: 8,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &FLOOR_ATTRIBUTES,
        };
        // Seen from above it is counter-clockwise; not culled (a camera below the floor sees it too).
        let pipeline = pipeline(device, shared, ("floor_vs", "floor_fs"), &[Some(layout)], None, false);
        let h = FLOOR_HALF_M;
        let quad: [[f32; 2]; 6] = [[-h, -h], [h, -h], [h, h], [-h, -h], [h, h], [-h, h]];
        let quad = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("floor"),
            contents: bytemuck::cast_slice(&quad),
            usage: wgpu::BufferUsages::VERTEX,
        });
        FloorPass { pipeline, quad }
    }

    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_vertex_buffer(0, self.quad.slice(..));
        pass.draw(0..6, 0..1);
    }
}
