// The rasterizer of `smocap render` (src/render/raster/): the skinned bodies and the floor seen
// through one OpenCV pinhole camera. Host-side layouts: src/render/raster/layout.rs (a test
// checks `View`'s size and offsets against this file).
//
// Projection (exactly `Camera::project`): camera point c = R·p + t (m, x right, y down,
// z forward), pixel u = fx·x/z + cx, v = fy·y/z + cy with pixel centres at integers; wgpu's
// pixel centres are at half-integers, hence `intr.zw` = (cx + 0.5, cy + 0.5). Depth is reversed
// (z_ndc = near / z: 1 at the near plane, 0 at infinity), compared with `greater`.

struct View {
    // Rows of R (world → camera); w unused.
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    // t (m) for points given relative to the upload origin; w: the near plane (m).
    trans: vec4<f32>,
    // fx, fy (px), cx + 0.5, cy + 0.5 (px).
    intr: vec4<f32>,
    // Image width, height (px); the floor's height relative to the upload origin (m); the grid's
    // spacing (m, 0: no grid).
    size: vec4<f32>,
    // Unit direction towards the light (world); w: the ambient share of the shading.
    light: vec4<f32>,
    // The floor's colour (linear 0–1 values written as they are); w: the grid lines' darkening.
    floor: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;

fn camera_point(p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(view.rot0.xyz, p), dot(view.rot1.xyz, p), dot(view.rot2.xyz, p)) + view.trans.xyz;
}

fn clip(c: vec3<f32>) -> vec4<f32> {
    let x = 2.0 * (view.intr.x * c.x + view.intr.z * c.z) / view.size.x - c.z;
    let y = c.z - 2.0 * (view.intr.y * c.y + view.intr.w * c.z) / view.size.y;
    return vec4<f32>(x, y, view.trans.w, c.z);
}

fn lambert(albedo: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let a = view.light.w;
    return albedo * (a + (1.0 - a) * max(dot(n, view.light.xyz), 0.0));
}

struct BodyOut {
    @builtin(position) position: vec4<f32>,
    @location(0) depth: f32,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec3<f32>,
    @location(3) @interpolate(flat) segment: u32,
}

@vertex
fn body_vs(
    @location(0) pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec4<f32>,
    @location(3) segment: u32,
) -> BodyOut {
    let c = camera_point(pos);
    var o: BodyOut;
    o.position = clip(c);
    o.depth = c.z;
    o.normal = normal;
    o.albedo = albedo.rgb;
    o.segment = segment;
    return o;
}

struct Targets {
    @location(0) rgb: vec4<f32>,
    @location(1) depth: f32,
    @location(2) segment: u32,
}

@fragment
fn body_fs(i: BodyOut) -> Targets {
    var o: Targets;
    let n = normalize(i.normal);
    o.rgb = vec4<f32>(lambert(i.albedo, n), 1.0);
    o.depth = i.depth;
    o.segment = i.segment;
    return o;
}

struct FloorOut {
    @builtin(position) position: vec4<f32>,
    @location(0) ground: vec2<f32>,
}

@vertex
fn floor_vs(@location(0) ground: vec2<f32>) -> FloorOut {
    var o: FloorOut;
    o.position = clip(camera_point(vec3<f32>(ground, view.size.z)));
    o.ground = ground;
    return o;
}

// Writes the colour only (the pipeline masks depth and segment): the floor is scenery.
@fragment
fn floor_fs(i: FloorOut) -> Targets {
    var shade = lambert(view.floor.rgb, vec3<f32>(0.0, 0.0, 1.0));
    if view.size.w > 0.0 {
        let g = i.ground / view.size.w;
        let d = abs(fract(g - 0.5) - 0.5) / max(fwidth(g), vec2<f32>(1e-6));
        let line = 1.0 - min(min(d.x, d.y), 1.0);
        shade = shade * (1.0 - view.floor.w * line);
    }
    var o: Targets;
    o.rgb = vec4<f32>(shade, 1.0);
    o.depth = 0.0;
    o.segment = 0u;
    return o;
}
