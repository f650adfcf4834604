//! Seeded variety for training sets: per subject a skin tone and a clothing split (upper body,
//! lower body, shoes); per scene a light direction, a background colour and a floor (plain or
//! with a 1 m grid). Everything from one seed: the same seed, the same pictures.

use super::raster::{Fixed, Lighting, Scene};
use crate::body::{BodyAsset, Dressed};
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Skin tones (sRGB), light to dark; a subject's tone lies between two neighbours.
const SKIN: [[u8; 3]; 6] =
    [[241, 213, 189], [226, 185, 153], [198, 151, 115], [160, 112, 79], [114, 76, 52], [74, 49, 35]];

/// The colours of one subject (sRGB).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Look {
    pub skin: [u8; 3],
    pub upper: [u8; 3],
    pub lower: [u8; 3],
    pub shoes: [u8; 3],
}

/// What a body segment of the mesh wears.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cover {
    Skin,
    Upper,
    Lower,
    Shoes,
}

/// The cover of a mesh segment by its name (`models/body/`: pelvis, torso, head, femur_r, …):
/// head and hands skin, pelvis and legs the lower garment, feet shoes, the rest the upper one.
pub fn cover(segment: &str) -> Cover {
    let base = segment.trim_end_matches("_r").trim_end_matches("_l");
    match base {
        "head" | "hand" => Cover::Skin,
        "pelvis" | "femur" | "tibia" => Cover::Lower,
        "calcn" | "toes" => Cover::Shoes,
        _ => Cover::Upper,
    }
}

fn hsv(h: f64, s: f64, v: f64) -> [u8; 3] {
    let c = v * s;
    let x = c * (1.0 - ((h / 60.0) % 2.0 - 1.0).abs());
    let (r, g, b) = match (h / 60.0) as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [r, g, b].map(|k| ((k + m) * 255.0).round().clamp(0.0, 255.0) as u8)
}

fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

impl Look {
    /// Subject `subject`'s look from `seed`.
    pub fn seeded(seed: u64, subject: usize) -> Look {
        let mut r = rng(seed, 1 + subject as u64);
        let t = r.random_range(0.0..(SKIN.len() - 1) as f64);
        let (i, f) = (t as usize, t.fract());
        let skin = [0, 1, 2].map(|k| (SKIN[i][k] as f64 * (1.0 - f) + SKIN[i + 1][k] as f64 * f).round() as u8);
        let mut cloth = || hsv(r.random_range(0.0..360.0), r.random_range(0.1..0.8), r.random_range(0.2..0.9));
        let (upper, lower, shoes) = (cloth(), cloth(), cloth());
        Look { skin, upper, lower, shoes }
    }

    fn of(&self, c: Cover) -> [u8; 3] {
        match c {
            Cover::Skin => self.skin,
            Cover::Upper => self.upper,
            Cover::Lower => self.lower,
            Cover::Shoes => self.shoes,
        }
    }
}

/// The scene of `seed`: light from above at a random azimuth (30–75° elevation), ambient
/// 0.25–0.45, a background colour, and a floor (two scenes in three with a grid).
pub fn scene(seed: u64) -> Scene {
    let mut r = rng(seed, 0);
    let az = r.random_range(0.0..std::f64::consts::TAU);
    let el = r.random_range(30f64..75.0).to_radians();
    let light = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    let background = hsv(r.random_range(0.0..360.0), r.random_range(0.0..0.4), r.random_range(0.5..0.95));
    let floor = hsv(r.random_range(0.0..360.0), r.random_range(0.0..0.3), r.random_range(0.3..0.7));
    let grid = r.random_range(0..3) > 0;
    Scene {
        lighting: Lighting {
            light,
            ambient: r.random_range(0.25..0.45),
            floor: floor.map(|c| c as f64 / 255.0),
            grid: if grid { 0.5 } else { 0.0 },
            grid_m: 1.0,
            draw_floor: true,
        },
        background,
    }
}

/// Every vertex's colour and label for a dressed body: the colour of its mesh segment's
/// [`cover`], its label `first_label` + the model body carrying it (the largest influence).
pub fn fixed_attributes(asset: &BodyAsset, body: &Dressed, look: &Look, first_label: u16, out: &mut Vec<Fixed>) {
    for (skin, inf) in asset.skin.iter().zip(&body.binding.influences) {
        let k = (0..4).fold(0, |best, k| if skin.weights[k] > skin.weights[best] { k } else { best });
        let c = look.of(cover(&asset.segments[skin.segments[k] as usize]));
        out.push(Fixed { albedo: [c[0], c[1], c[2], 255], segment: (first_label + inf[0].body) as u32 });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn looks_follow_the_seed_and_differ_between_subjects() {
        assert_eq!(Look::seeded(3, 0), Look::seeded(3, 0));
        assert_ne!(Look::seeded(3, 0), Look::seeded(3, 1));
        assert_ne!(scene(3), scene(4));
        assert_eq!(cover("femur_l"), Cover::Lower);
        assert_eq!(cover("hand_r"), Cover::Skin);
        assert_eq!(cover("humerus_r"), Cover::Upper);
    }
}
