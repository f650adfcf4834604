//! A contact sheet of a take: one panel (row) per camera, each a strip of tiles at evenly spaced
//! frames showing what that camera sees: bones between joint centres (coloured by side: left
//! blue, right red, midline grey), model markers (filled dots, by side) and observed markers
//! (yellow rings). Tiles are the camera image scaled to `tile_width` px; a frame whose observed
//! markers sit off the model's rings stands out. Drawn with plotters' bitmap backend, encoded as
//! an 8-bit RGB PNG (the same bytes for the same input).

use super::rig::{Camera, Pixel};
use super::take::{side_of, Take};
use super::{write_file, RenderError};
use crate::kinematics::Workspace;
use plotters::prelude::*;
use std::path::Path;

/// Layout of a contact sheet.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SheetLayout {
    /// Tiles per camera (frames shown).
    pub columns: usize,
    /// One tile's size (px).
    pub tile: (u32, u32),
    /// Gap between tiles and around the sheet (px).
    pub gap: u32,
    /// Cameras (panels, one row each).
    pub rows: usize,
}

impl SheetLayout {
    /// The sheet's size (px).
    pub fn size(&self) -> (u32, u32) {
        let (c, r) = (self.columns as u32, self.rows as u32);
        (c * self.tile.0 + (c + 1) * self.gap, r * self.tile.1 + (r + 1) * self.gap)
    }

    /// The top-left corner (px) of tile `col` of panel `row`.
    pub fn origin(&self, row: usize, col: usize) -> (i32, i32) {
        let g = self.gap as i32;
        (g + col as i32 * (self.tile.0 as i32 + g), g + row as i32 * (self.tile.1 as i32 + g))
    }
}

/// Background of the sheet and of a tile (sRGB).
pub const SHEET_RGB: [u8; 3] = [255, 255, 255];
pub const TILE_RGB: [u8; 3] = [24, 24, 28];

/// `n` evenly spaced frame indices of `len` frames, first and last included.
pub fn evenly_spaced(len: usize, n: usize) -> Vec<usize> {
    match (len, n) {
        (0, _) | (_, 0) => Vec::new(),
        (_, 1) => vec![0],
        _ => {
            let mut v: Vec<usize> = (0..n).map(|k| (k * (len - 1) + (n - 1) / 2) / (n - 1)).collect();
            v.dedup();
            v
        }
    }
}

fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

/// Draws the contact sheet of `take` seen from `cameras` at `columns` evenly spaced frames,
/// tiles `tile_width` px wide; returns the PNG bytes and the layout.
pub fn contact_sheet(
    take: &Take,
    cameras: &[Camera],
    columns: usize,
    tile_width: u32,
) -> Result<(Vec<u8>, SheetLayout), RenderError> {
    let frames = evenly_spaced(take.len(), columns);
    let aspect = cameras.first().map_or(1.5, |c| c.width_px as f64 / c.height_px as f64);
    let tile = (tile_width.max(16), ((tile_width.max(16) as f64 / aspect).round() as u32).max(8));
    let layout = SheetLayout { columns: frames.len().max(1), tile, gap: 6, rows: cameras.len() };
    let (w, h) = layout.size();
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let draw_err = |e: String| RenderError::Image { file: take.name.clone(), what: e };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&rgb(SHEET_RGB)).map_err(|e| draw_err(e.to_string()))?;
        let mut ws = Workspace::new(&take.model);
        let poses: Vec<_> = frames.iter().map(|&i| take.pose(i, &mut ws)).collect();
        for (row, cam) in cameras.iter().enumerate() {
            for (col, pose) in poses.iter().enumerate() {
                let (x0, y0) = layout.origin(row, col);
                let (tw, th) = (tile.0 as i32, tile.1 as i32);
                root.draw(&Rectangle::new([(x0, y0), (x0 + tw - 1, y0 + th - 1)], rgb(TILE_RGB).filled()))
                    .map_err(|e| draw_err(e.to_string()))?;
                let s = tile.0 as f64 / cam.width_px as f64;
                // A pixel of the camera image in sheet coordinates, when inside the image.
                let at = |p: Pixel| {
                    p.in_image.then(|| (x0 + ((p.u + 0.5) * s).floor() as i32, y0 + ((p.v + 0.5) * s).floor() as i32))
                };
                for (b, body) in take.model.bodies.iter().enumerate() {
                    let Some(parent) = body.parent else { continue };
                    let (a, c) = (cam.project(&pose.joints[parent]), cam.project(&pose.joints[b]));
                    if let (Some(a), Some(c)) = (at(a), at(c)) {
                        let style = rgb(side_of(&body.name).rgb()).stroke_width(2);
                        root.draw(&PathElement::new(vec![a, c], style)).map_err(|e| draw_err(e.to_string()))?;
                    }
                }
                for (m, mk) in take.model.markers.iter().enumerate() {
                    let side = match side_of(&mk.name) {
                        super::take::Side::Centre => side_of(&take.model.bodies[mk.body].name),
                        side => side,
                    };
                    if let Some(p) = at(cam.project(&pose.markers[m])) {
                        root.draw(&Circle::new(p, 2, rgb(side.rgb()).filled())).map_err(|e| draw_err(e.to_string()))?;
                    }
                }
                for o in pose.observed.iter().flatten() {
                    if let Some(p) = at(cam.project(o)) {
                        root.draw(&Circle::new(p, 4, RGBColor(250, 210, 40))).map_err(|e| draw_err(e.to_string()))?;
                    }
                }
            }
        }
        root.present().map_err(|e| draw_err(e.to_string()))?;
    }
    let mut png_bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut png_bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().map_err(|e| draw_err(e.to_string()))?;
        wr.write_image_data(&buf).map_err(|e| draw_err(e.to_string()))?;
    }
    Ok((png_bytes, layout))
}

/// Writes the contact sheet of `take` to `out` (PNG); returns its layout.
pub fn write_contact_sheet(
    take: &Take,
    cameras: &[Camera],
    columns: usize,
    tile_width: u32,
    out: &Path,
) -> Result<SheetLayout, RenderError> {
    let (bytes, layout) = contact_sheet(take, cameras, columns, tile_width)?;
    write_file(out, &bytes)?;
    Ok(layout)
}
