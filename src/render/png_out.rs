//! The rendered images as PNG files: RGB (8-bit), segment labels (8-bit grey, 16-bit where a
//! label exceeds 255) and depth along the camera axis (16-bit grey, millimetres, 0 where no
//! body, 65535 at 65.535 m and beyond). Fast compression (fdeflate): the encoder is most of a
//! frame's cost. Every file is written to a temporary name beside it and renamed into place.

use super::raster::Images;
use super::RenderError;
use std::path::Path;

/// Encodes `data` (rows from the top, `channels` samples a pixel of `bits` bits, big-endian for
/// 16) as a PNG into `out`.
fn encode(out: &mut Vec<u8>, size: (u32, u32), color: png::ColorType, bits: png::BitDepth, data: &[u8]) {
    out.clear();
    let mut e = png::Encoder::new(&mut *out, size.0, size.1);
    e.set_color(color);
    e.set_depth(bits);
    e.set_compression(png::Compression::Fast);
    let mut w = e.write_header().expect("writing to memory");
    w.write_image_data(data).expect("the data fit the header");
    w.finish().expect("writing to memory");
}

/// Scratch reused between frames by one writer.
#[derive(Default)]
pub struct Encoder {
    samples: Vec<u8>,
    png: Vec<u8>,
}

impl Encoder {
    /// The RGB image as PNG bytes (borrowed until the next call).
    pub fn rgb(&mut self, img: &Images) -> &[u8] {
        encode(&mut self.png, img.size, png::ColorType::Rgb, png::BitDepth::Eight, &img.rgb);
        &self.png
    }

    /// The segment labels: 8-bit where `max_label` ≤ 255, else 16-bit.
    pub fn mask(&mut self, img: &Images, max_label: u16) -> &[u8] {
        self.samples.clear();
        if max_label <= 255 {
            self.samples.extend(img.mask.iter().map(|&l| l as u8));
            encode(&mut self.png, img.size, png::ColorType::Grayscale, png::BitDepth::Eight, &self.samples);
        } else {
            self.samples.extend(img.mask.iter().flat_map(|l| l.to_be_bytes()));
            encode(&mut self.png, img.size, png::ColorType::Grayscale, png::BitDepth::Sixteen, &self.samples);
        }
        &self.png
    }

    /// The depth (mm, rounded; 0 where no body).
    pub fn depth(&mut self, img: &Images) -> &[u8] {
        self.samples.clear();
        self.samples.extend(img.depth_m.iter().flat_map(|&d| depth_mm(d).to_be_bytes()));
        encode(&mut self.png, img.size, png::ColorType::Grayscale, png::BitDepth::Sixteen, &self.samples);
        &self.png
    }
}

/// A depth (m) as the PNG's millimetres.
pub fn depth_mm(d: f32) -> u16 {
    (d as f64 * 1000.0).round().clamp(0.0, 65535.0) as u16
}

/// Writes `bytes` to `path` through a temporary file beside it and a rename: a reader never
/// sees a partial file, and an interrupted run leaves none behind under the final name.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    crate::io::write_atomic(path, bytes).map_err(|source| RenderError::Io { file: path.display().to_string(), source })
}
