//! Backgrounds from the user's pictures (`render --backgrounds DIR`): a PNG per scene, chosen by
//! the seed, behind the bodies instead of the floor and the plain colour (scaled to cover each
//! camera's image, centred, nearest sample).

use super::raster::Images;
use super::RenderError;
use std::path::{Path, PathBuf};

/// A background picture (8-bit RGB).
#[derive(Clone, Debug)]
pub struct Backdrop {
    pub file: PathBuf,
    size: (u32, u32),
    rgb: Vec<u8>,
}

/// The `.png` files of `dir`, sorted by name.
pub fn pictures(dir: &Path) -> Result<Vec<PathBuf>, RenderError> {
    let io = |source| RenderError::Io { file: dir.display().to_string(), source };
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(io)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
        .collect();
    out.sort();
    if out.is_empty() {
        return Err(RenderError::Content { file: dir.display().to_string(), what: "no .png picture".into() });
    }
    Ok(out)
}

impl Backdrop {
    /// Reads a PNG (any colour type and depth: expanded to 8-bit RGB).
    pub fn read(path: &Path) -> Result<Backdrop, RenderError> {
        let bad = |what: String| RenderError::Image { file: path.display().to_string(), what };
        let file =
            std::fs::File::open(path).map_err(|source| RenderError::Io { file: path.display().to_string(), source })?;
        let mut dec = png::Decoder::new(std::io::BufReader::new(file));
        dec.set_transformations(png::Transformations::normalize_to_color8());
        let mut reader = dec.read_info().map_err(|e| bad(e.to_string()))?;
        let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| bad("too large".into()))?];
        let info = reader.next_frame(&mut buf).map_err(|e| bad(e.to_string()))?;
        let channels = info.color_type.samples();
        let n = info.width as usize * info.height as usize;
        let mut rgb = Vec::with_capacity(3 * n);
        for px in buf[..n * channels].chunks_exact(channels) {
            rgb.extend_from_slice(&if channels < 3 { [px[0]; 3] } else { [px[0], px[1], px[2]] });
        }
        Ok(Backdrop { file: path.to_path_buf(), size: (info.width, info.height), rgb })
    }

    /// Puts the picture into `img` wherever the mask shows no body.
    pub fn composite(&self, img: &mut Images) {
        let (w, h) = (img.size.0 as usize, img.size.1 as usize);
        let (bw, bh) = (self.size.0 as f64, self.size.1 as f64);
        let scale = (bw / w as f64).min(bh / h as f64);
        let (ox, oy) = ((bw - scale * w as f64) / 2.0, (bh - scale * h as f64) / 2.0);
        for y in 0..h {
            let sy = ((oy + (y as f64 + 0.5) * scale) as usize).min(self.size.1 as usize - 1);
            for x in 0..w {
                if img.mask[y * w + x] != 0 {
                    continue;
                }
                let sx = ((ox + (x as f64 + 0.5) * scale) as usize).min(self.size.0 as usize - 1);
                let s = 3 * (sy * self.size.0 as usize + sx);
                img.rgb[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&self.rgb[s..s + 3]);
            }
        }
    }
}
