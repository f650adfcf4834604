//! The render targets of one image size and their read-back: colour (RGBA8), depth along the
//! camera axis (R32Float, m, 0 where no body), segment labels (R16Uint, 0 background), and the
//! reversed-Z depth buffer the passes test against. Created once per size, reused every frame.

use super::{Images, RasterError};

pub const RGB_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
pub const SEGMENT_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R16Uint;
pub const ZBUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Bytes per row of a copy to a buffer: `bytes_per_pixel · width` rounded up to 256.
pub fn padded_row(width: u32, bytes_per_pixel: u32) -> u32 {
    (width * bytes_per_pixel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// The targets of one size, and one read-back buffer per camera slot.
pub struct Targets {
    pub size: (u32, u32),
    pub rgb: wgpu::TextureView,
    pub depth: wgpu::TextureView,
    pub segment: wgpu::TextureView,
    pub zbuffer: wgpu::TextureView,
    textures: [wgpu::Texture; 3],
    readback: Vec<wgpu::Buffer>,
}

/// Bytes per pixel of the three read-back targets.
const BPP: [u32; 3] = [4, 4, 2];

impl Targets {
    pub fn new(device: &wgpu::Device, size: (u32, u32)) -> Targets {
        let tex = |format, label, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let read = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let textures =
            [tex(RGB_FORMAT, "rgb", read), tex(DEPTH_FORMAT, "depth", read), tex(SEGMENT_FORMAT, "segment", read)];
        let zbuffer = tex(ZBUFFER_FORMAT, "zbuffer", wgpu::TextureUsages::RENDER_ATTACHMENT);
        let view = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        Targets {
            size,
            rgb: view(&textures[0]),
            depth: view(&textures[1]),
            segment: view(&textures[2]),
            zbuffer: view(&zbuffer),
            textures,
            readback: Vec::new(),
        }
    }

    /// Bytes of one slot's read-back buffer and the offset of each target in it.
    fn layout(&self) -> ([u64; 3], u64) {
        let mut offsets = [0u64; 3];
        let mut at = 0u64;
        for (k, bpp) in BPP.iter().enumerate() {
            offsets[k] = at;
            at += padded_row(self.size.0, *bpp) as u64 * self.size.1 as u64;
        }
        (offsets, at)
    }

    /// Encodes copies of the three targets into read-back slot `slot` (created on first use).
    pub fn copy_out(&mut self, device: &wgpu::Device, enc: &mut wgpu::CommandEncoder, slot: usize) {
        let (offsets, bytes) = self.layout();
        while self.readback.len() <= slot {
            self.readback.push(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: bytes,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }));
        }
        for k in 0..3 {
            enc.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture: &self.textures[k],
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: &self.readback[slot],
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: offsets[k],
                        bytes_per_row: Some(padded_row(self.size.0, BPP[k])),
                        rows_per_image: Some(self.size.1),
                    },
                },
                wgpu::Extent3d { width: self.size.0, height: self.size.1, depth_or_array_layers: 1 },
            );
        }
    }

    /// Maps every slot up to `slots` after their submission, copies them into `out` (one per
    /// slot, resized to this size) without the rows' padding, and unmaps them.
    pub fn read(&self, device: &wgpu::Device, slots: usize, out: &mut [Images]) -> Result<(), RasterError> {
        let (offsets, _) = self.layout();
        let (tx, rx) = std::sync::mpsc::channel();
        for (s, buf) in self.readback[..slots].iter().enumerate() {
            let tx = tx.clone();
            buf.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send((s, r));
            });
        }
        device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
            .map_err(|e| RasterError::Device(format!("waiting for the device: {e}")))?;
        for _ in 0..slots {
            let (_, r) = rx.recv().map_err(|_| RasterError::Device("a read-back was never mapped".into()))?;
            r.map_err(|e| RasterError::Device(format!("mapping a read-back buffer: {e}")))?;
        }
        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        for (buf, img) in self.readback[..slots].iter().zip(out.iter_mut()) {
            img.resize(self.size);
            {
                let data = buf
                    .slice(..)
                    .get_mapped_range()
                    .map_err(|e| RasterError::Device(format!("reading a mapped buffer: {e:?}")))?;
                let rows = |k: usize| {
                    let pitch = padded_row(self.size.0, BPP[k]) as usize;
                    let start = offsets[k] as usize;
                    (0..h).map(move |y| start + y * pitch)
                };
                for (y, at) in rows(0).enumerate() {
                    for x in 0..w {
                        img.rgb[3 * (y * w + x)..3 * (y * w + x) + 3]
                            .copy_from_slice(&data[at + 4 * x..at + 4 * x + 3]);
                    }
                }
                for (y, at) in rows(1).enumerate() {
                    let src: &[f32] = bytemuck::cast_slice(&data[at..at + 4 * w]);
                    img.depth_m[y * w..(y + 1) * w].copy_from_slice(src);
                }
                for (y, at) in rows(2).enumerate() {
                    let src: &[u16] = bytemuck::cast_slice(&data[at..at + 2 * w]);
                    img.mask[y * w..(y + 1) * w].copy_from_slice(src);
                }
            }
            buf.unmap();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn rows_are_padded_to_256_bytes() {
        assert_eq!(super::padded_row(640, 4), 2560);
        assert_eq!(super::padded_row(641, 4), 2816);
        assert_eq!(super::padded_row(100, 2), 256);
        assert_eq!(super::padded_row(1080, 2), 2304);
    }
}
