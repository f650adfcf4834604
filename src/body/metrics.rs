//! Measures of a posed body mesh: enclosed volume, whether a point is inside (winding number),
//! and edge lengths against the rest pose.

/// Each undirected edge of `triangles` once, `(lower, higher)` vertex index, sorted.
pub fn edges(triangles: &[[u32; 3]]) -> Vec<(u32, u32)> {
    let mut e: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

fn v3(p: &[f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Area-weighted vertex normals (unit; zero-area stays zero) of counter-clockwise `triangles`.
pub fn vertex_normals(vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<nalgebra::Vector3<f64>> {
    use nalgebra::Vector3;
    let p = |i: u32| Vector3::from(vertices[i as usize].map(|x| x as f64));
    let mut n = vec![Vector3::zeros(); vertices.len()];
    for t in triangles {
        let c = (p(t[1]) - p(t[0])).cross(&(p(t[2]) - p(t[0])));
        for &i in t {
            n[i as usize] += c;
        }
    }
    n.iter().map(|x| x / x.norm().max(1e-30)).collect()
}

/// Each vertex's neighbours along the edges of `triangles` (`n` vertices), ascending.
pub fn neighbours(triangles: &[[u32; 3]], n: usize) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); n];
    for (a, b) in edges(triangles) {
        out[a as usize].push(b);
        out[b as usize].push(a);
    }
    for v in &mut out {
        v.sort_unstable();
    }
    out
}

/// Signed enclosed volume (m³; positive for outward counter-clockwise triangles).
pub fn volume(vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let (a, b, c) = (v3(&vertices[t[0] as usize]), v3(&vertices[t[1] as usize]), v3(&vertices[t[2] as usize]));
            dot(a, cross(b, c)) / 6.0
        })
        .sum()
}

/// Generalised winding number of the closed surface around `p`: about 1 inside, 0 outside
/// (the sum of the triangles' signed solid angles over 4π, Van Oosterom and Strackee's formula).
pub fn winding_number(vertices: &[[f32; 3]], triangles: &[[u32; 3]], p: [f64; 3]) -> f64 {
    let mut total = 0.0;
    for t in triangles {
        let a = sub(v3(&vertices[t[0] as usize]), p);
        let b = sub(v3(&vertices[t[1] as usize]), p);
        let c = sub(v3(&vertices[t[2] as usize]), p);
        let (la, lb, lc) = (dot(a, a).sqrt(), dot(b, b).sqrt(), dot(c, c).sqrt());
        let num = dot(a, cross(b, c));
        let den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
        total += 2.0 * num.atan2(den);
    }
    total / (4.0 * std::f64::consts::PI)
}

/// Length ratio of each edge, posed over rest.
pub fn edge_ratios(rest: &[[f32; 3]], posed: &[[f32; 3]], edges: &[(u32, u32)], out: &mut Vec<f64>) {
    out.clear();
    let len = |v: &[[f32; 3]], (a, b): (u32, u32)| {
        let d = sub(v3(&v[a as usize]), v3(&v[b as usize]));
        dot(d, d).sqrt()
    };
    out.extend(edges.iter().map(|&e| len(posed, e) / len(rest, e).max(1e-12)));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's 12 outward triangles.
    fn cube() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let v: Vec<[f32; 3]> = (0..8).map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32]).collect();
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let t = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        (v, t)
    }

    #[test]
    fn a_cube_has_unit_volume_and_winds_once_around_its_inside() {
        let (v, t) = cube();
        assert!((volume(&v, &t) - 1.0).abs() < 1e-12);
        assert!((winding_number(&v, &t, [0.5, 0.4, 0.3]) - 1.0).abs() < 1e-9);
        assert!(winding_number(&v, &t, [1.5, 0.4, 0.3]).abs() < 1e-9);
        assert_eq!(edges(&t).len(), 18);
    }
}
