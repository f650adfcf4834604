//! Posed body meshes as Wavefront OBJ: vertices (m, the Z-up world) and triangles
//! (counter-clockwise seen from outside), one object named after the trial and frame.

use std::fmt::Write as _;

/// The OBJ text of one mesh.
pub fn obj(name: &str, vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> String {
    let mut s = String::with_capacity(40 * vertices.len() + 24 * triangles.len());
    let _ = writeln!(s, "# smocap body mesh (metres, Z up, X forward)\no {name}");
    for v in vertices {
        let _ = writeln!(s, "v {:.6} {:.6} {:.6}", v[0], v[1], v[2]);
    }
    for t in triangles {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

#[cfg(test)]
mod tests {
    #[test]
    fn obj_indices_start_at_one() {
        let s = super::obj("t", &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]);
        assert!(s.contains("\nf 1 2 3\n") && s.contains("\nv 1.000000 0.000000 0.000000\n"), "{s}");
    }
}
