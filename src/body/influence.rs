//! A vertex's skinning influence on a model body ([`super::bind`] makes them, [`super::helpers`]
//! spreads them over helper joints).

/// One skinning influence of a vertex: the model body, its weight, and the vertex in the body's
/// frame at unit scale (m; the bind position divided by the bind scales, axis by axis), so that
/// a pose at scales `s` puts it at `R_b (s_b ⊙ local) + p_b`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Influence {
    pub body: u16,
    pub weight: f32,
    pub local: [f32; 3],
}
