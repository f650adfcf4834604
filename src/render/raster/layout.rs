//! The host side of `shaders/raster.wgsl`: the `View` uniform and the vertex layouts, `#[repr(C)]`
//! and checked against the shader by the tests below (sizes and offsets from naga's layouter).

use crate::render::rig::Camera;
use bytemuck::{Pod, Zeroable};
use nalgebra::Vector3;

/// The shader's source.
pub const SHADER: &str = include_str!("../../../shaders/raster.wgsl");

/// The near plane (m): nothing closer to a camera is drawn.
pub const NEAR_M: f32 = 0.05;

/// `View` of the shader: one camera, the light and the floor (see the shader for each field).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct View {
    pub rot: [[f32; 4]; 3],
    pub trans: [f32; 4],
    pub intr: [f32; 4],
    pub size: [f32; 4],
    pub light: [f32; 4],
    pub floor: [f32; 4],
}

/// The lighting and floor of a scene (the seeded look of [`crate::render::look`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Unit direction towards the light, in `world`.
    pub light: Vector3<f64>,
    /// Share of ambient light in the shading, 0–1.
    pub ambient: f64,
    /// Floor colour (0–1 per channel) and how much grid lines darken it (0: no grid).
    pub floor: [f64; 3],
    pub grid: f64,
    /// Grid spacing (m).
    pub grid_m: f64,
    /// Whether the floor is drawn at all.
    pub draw_floor: bool,
}

impl View {
    /// The view of `cam` for points given relative to `origin` (`world`, m); the floor at
    /// `world` z = 0.
    pub fn new(cam: &Camera, origin: &Vector3<f64>, lighting: &Lighting) -> View {
        let r = &cam.r;
        // t' = t + R·origin: the camera point of `origin + p` is R·p + t'; in f64 here, so that
        // the shader's f32 works with metres near the subject, not far from `world`'s origin.
        let t = r * origin + cam.t;
        let row = |i: usize| [r[(i, 0)] as f32, r[(i, 1)] as f32, r[(i, 2)] as f32, 0.0];
        let l = lighting.light.try_normalize(1e-12).unwrap_or(Vector3::z());
        let (w, h) = (cam.width_px as f32, cam.height_px as f32);
        View {
            rot: [row(0), row(1), row(2)],
            trans: [t.x as f32, t.y as f32, t.z as f32, NEAR_M],
            intr: [
                cam.k[(0, 0)] as f32,
                cam.k[(1, 1)] as f32,
                (cam.k[(0, 2)] + 0.5) as f32,
                (cam.k[(1, 2)] + 0.5) as f32,
            ],
            size: [w, h, -origin.z as f32, if lighting.grid > 0.0 { lighting.grid_m as f32 } else { 0.0 }],
            light: [l.x as f32, l.y as f32, l.z as f32, lighting.ambient as f32],
            floor: [lighting.floor[0] as f32, lighting.floor[1] as f32, lighting.floor[2] as f32, lighting.grid as f32],
        }
    }
}

/// A posed vertex, uploaded every frame (relative to the upload origin, m; unit normal).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Posed {
    pub pos: [f32; 3],
    pub normal: [f32; 3],
}

/// A vertex's fixed attributes: colour (sRGB bytes, alpha unused) and segment label.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Fixed {
    pub albedo: [u8; 4],
    pub segment: u32,
}

/// Vertex attributes of `body_vs`: buffer 0 [`Posed`], buffer 1 [`Fixed`].
pub const POSED_ATTRIBUTES: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
pub const FIXED_ATTRIBUTES: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![2 => Unorm8x4, 3 => Uint32];
/// Vertex attribute of `floor_vs`: a point of the floor (x, y relative to the upload origin, m).
pub const FLOOR_ATTRIBUTES: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x2];

#[cfg(test)]
mod tests {
    use super::*;

    fn module() -> naga::Module {
        naga::front::wgsl::parse_str(SHADER).expect("raster.wgsl parses")
    }

    #[test]
    fn the_view_uniform_matches_the_shader() {
        let m = module();
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(m.to_ctx()).unwrap();
        let (handle, ty) = m.types.iter().find(|(_, t)| t.name.as_deref() == Some("View")).expect("struct View");
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("View is a struct") };
        assert_eq!(*span as usize, std::mem::size_of::<View>());
        assert_eq!(layouter[handle].size as usize, std::mem::size_of::<View>());
        let offsets: Vec<(String, u32)> = members.iter().map(|x| (x.name.clone().unwrap(), x.offset)).collect();
        let host = [
            ("rot0", std::mem::offset_of!(View, rot)),
            ("rot1", std::mem::offset_of!(View, rot) + 16),
            ("rot2", std::mem::offset_of!(View, rot) + 32),
            ("trans", std::mem::offset_of!(View, trans)),
            ("intr", std::mem::offset_of!(View, intr)),
            ("size", std::mem::offset_of!(View, size)),
            ("light", std::mem::offset_of!(View, light)),
            ("floor", std::mem::offset_of!(View, floor)),
        ];
        assert_eq!(offsets.len(), host.len());
        for ((name, off), (hname, hoff)) in offsets.iter().zip(host) {
            assert_eq!((name.as_str(), *off as usize), (hname, hoff));
        }
    }

    #[test]
    fn the_vertex_inputs_match_the_shader() {
        let m = module();
        let entry = |name: &str| m.entry_points.iter().find(|e| e.name == name).unwrap();
        let inputs = |name: &str| -> Vec<(u32, String)> {
            entry(name)
                .function
                .arguments
                .iter()
                .map(|a| {
                    let Some(naga::Binding::Location { location, .. }) = a.binding else { panic!("located input") };
                    (location, format!("{:?}", m.types[a.ty].inner))
                })
                .collect()
        };
        let host: Vec<(u32, wgpu::VertexFormat)> =
            POSED_ATTRIBUTES.iter().chain(&FIXED_ATTRIBUTES).map(|a| (a.shader_location, a.format)).collect();
        let shader = inputs("body_vs");
        assert_eq!(shader.len(), host.len());
        for ((loc, ty), (hloc, fmt)) in shader.iter().zip(&host) {
            assert_eq!(loc, hloc);
            let want = match fmt {
                wgpu::VertexFormat::Float32x3 => "size: Tri, scalar: Scalar { kind: Float, width: 4 }",
                wgpu::VertexFormat::Unorm8x4 => "size: Quad, scalar: Scalar { kind: Float, width: 4 }",
                wgpu::VertexFormat::Uint32 => "Scalar(Scalar { kind: Uint, width: 4 })",
                f => panic!("unexpected format {f:?}"),
            };
            assert!(ty.contains(want), "location {loc}: shader {ty}, host {fmt:?}");
        }
        assert_eq!(std::mem::size_of::<Posed>(), 24);
        assert_eq!(std::mem::size_of::<Fixed>(), 8);
        assert_eq!(FIXED_ATTRIBUTES[1].offset as usize, std::mem::offset_of!(Fixed, segment));
        let floor = inputs("floor_vs");
        assert_eq!(floor.len(), 1);
        assert!(floor[0].1.contains("size: Bi"), "{:?}", floor[0]);
    }
}
