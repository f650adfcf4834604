//! A contact sheet of a take: one panel (row) per camera, each a strip of tiles at evenly spaced
//! frames and at the trial's worst frames, showing what that camera sees: bones between joint
//! centres (coloured by side: left blue, right red, midline grey), model markers (filled dots, by
//! side) and observed markers (yellow rings). Each panel frames the subject: every tile shows a
//! window of the camera image centred on the subject in that frame, all windows of a panel of one
//! size (the largest the subject needs there, with a margin), so that sizes compare across it. The worst frames (highest marker RMSE, apart from one another) get a red border; a frame
//! whose observed markers sit off the model's rings stands out. Drawn with plotters' bitmap
//! backend, encoded as an 8-bit RGB PNG (the same bytes for the same input).

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

/// A frame shown on the sheet.
#[derive(Clone, Debug, PartialEq)]
pub struct ShownFrame {
    /// Index in the take.
    pub index: usize,
    /// Time (s since the trial's first sample).
    pub time: f64,
    /// Unweighted RMS of observed − model marker positions (mm); `None` when none is observed.
    pub rmse_mm: Option<f64>,
    /// One of the trial's worst frames (red border).
    pub worst: bool,
}

/// Border colour of a worst frame's tiles (sRGB).
pub const WORST_RGB: [u8; 3] = [235, 40, 40];

/// Each frame's unweighted marker RMSE (mm; `None` where no marker is observed).
pub fn frame_rmse_mm(take: &Take, ws: &mut Workspace) -> Vec<Option<f64>> {
    (0..take.len())
        .map(|i| {
            let pose = take.pose(i, ws);
            let (mut sq, mut n) = (0.0, 0usize);
            for (m, o) in pose.markers.iter().zip(&pose.observed) {
                if let Some(o) = o {
                    sq += (m - o).norm_squared();
                    n += 1;
                }
            }
            (n > 0).then(|| (sq / n as f64).sqrt() * 1e3)
        })
        .collect()
}

/// The `n` worst frames by RMSE, at least `apart` frames from one another (one per event), in
/// order of RMSE (worst first; ties to the earlier frame).
pub fn worst_frames(rmse: &[Option<f64>], n: usize, apart: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..rmse.len()).filter(|&i| rmse[i].is_some()).collect();
    order.sort_by(|&a, &b| rmse[b].unwrap_or(0.0).total_cmp(&rmse[a].unwrap_or(0.0)).then(a.cmp(&b)));
    let mut out: Vec<usize> = Vec::new();
    for i in order {
        if out.len() == n {
            break;
        }
        if out.iter().all(|&j| i.abs_diff(j) >= apart.max(1)) {
            out.push(i);
        }
    }
    out
}

/// The bounding box `(lo, hi)` (px) of the points given that fall inside the image.
fn pixel_box(points: impl IntoIterator<Item = Pixel>) -> Option<([f64; 2], [f64; 2])> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points.into_iter().filter(|p| p.in_image) {
        lo = [lo[0].min(p.u), lo[1].min(p.v)];
        hi = [hi[0].max(p.u), hi[1].max(p.v)];
    }
    lo[0].is_finite().then_some((lo, hi))
}

/// The windows of camera pixels `(u0, v0, width)` the tiles of a panel show, one per frame: each
/// centred on that frame's subject (the bounding box of its points inside the image), all of one
/// size — the largest box of the panel grown by a margin of 8 % (at least 8 px) and to the
/// image's aspect ratio, never wider than the image — so that sizes compare across the panel. A
/// frame with no point inside the image shows the whole image.
pub fn panel_windows(cam: &Camera, boxes: &[Option<([f64; 2], [f64; 2])>]) -> Vec<(f64, f64, f64)> {
    let (iw, ih) = (cam.width_px as f64, cam.height_px as f64);
    let aspect = iw / ih;
    let (mut w, mut h) = (0.0f64, 0.0f64);
    for (lo, hi) in boxes.iter().flatten() {
        let margin = (0.08 * (hi[0] - lo[0]).max(hi[1] - lo[1])).max(8.0);
        w = w.max(hi[0] - lo[0] + 2.0 * margin);
        h = h.max(hi[1] - lo[1] + 2.0 * margin);
    }
    if w / h.max(1e-9) < aspect {
        w = h * aspect;
    }
    let w = w.min(iw);
    let h = w / aspect;
    boxes
        .iter()
        .map(|b| match b {
            Some((lo, hi)) => ((lo[0] + hi[0] - w) / 2.0, (lo[1] + hi[1] - h) / 2.0, w),
            None => (-0.5, -0.5, iw),
        })
        .collect()
}

/// Draws the contact sheet of `take` seen from `cameras` at `columns` evenly spaced frames plus
/// its `worst` worst frames (by marker RMSE, one per event), in time order, tiles `tile_width`
/// px wide; returns the PNG bytes, the layout and the frames shown.
pub fn contact_sheet(
    take: &Take,
    cameras: &[Camera],
    columns: usize,
    worst: usize,
    tile_width: u32,
) -> Result<(Vec<u8>, SheetLayout, Vec<ShownFrame>), RenderError> {
    let mut ws = Workspace::new(&take.model);
    let rmse = frame_rmse_mm(take, &mut ws);
    let bad = worst_frames(&rmse, worst, (take.len() / (2 * columns.max(1))).max(1));
    let mut frames = evenly_spaced(take.len(), columns);
    frames.extend(&bad);
    frames.sort_unstable();
    frames.dedup();
    let shown: Vec<ShownFrame> = frames
        .iter()
        .map(|&i| ShownFrame { index: i, time: take.times[i], rmse_mm: rmse[i], worst: bad.contains(&i) })
        .collect();
    let aspect = cameras.first().map_or(1.5, |c| c.width_px as f64 / c.height_px as f64);
    let tile = (tile_width.max(16), ((tile_width.max(16) as f64 / aspect).round() as u32).max(8));
    let layout = SheetLayout { columns: frames.len().max(1), tile, gap: 6, rows: cameras.len() };
    let (w, h) = layout.size();
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let draw_err = |e: String| RenderError::Image { file: take.name.clone(), what: e };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&rgb(SHEET_RGB)).map_err(|e| draw_err(e.to_string()))?;
        let poses: Vec<_> = frames.iter().map(|&i| take.pose(i, &mut ws)).collect();
        for (row, cam) in cameras.iter().enumerate() {
            let boxes: Vec<_> = poses
                .iter()
                .map(|p| {
                    pixel_box(
                        p.joints.iter().chain(&p.markers).chain(p.observed.iter().flatten()).map(|x| cam.project(x)),
                    )
                })
                .collect();
            let windows = panel_windows(cam, &boxes);
            for (col, ((pose, f), &(u0, v0, win))) in poses.iter().zip(&shown).zip(&windows).enumerate() {
                let s = tile.0 as f64 / win;
                let (x0, y0) = layout.origin(row, col);
                let (tw, th) = (tile.0 as i32, tile.1 as i32);
                root.draw(&Rectangle::new([(x0, y0), (x0 + tw - 1, y0 + th - 1)], rgb(TILE_RGB).filled()))
                    .map_err(|e| draw_err(e.to_string()))?;
                // A pixel of the camera image in sheet coordinates, when inside the image and
                // the panel's window.
                let at = |p: Pixel| {
                    let (x, y) = (((p.u - u0) * s).floor() as i32, ((p.v - v0) * s).floor() as i32);
                    (p.in_image && (0..tw).contains(&x) && (0..th).contains(&y)).then_some((x0 + x, y0 + y))
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
                if f.worst {
                    for k in 0..3 {
                        let r = [(x0 + k, y0 + k), (x0 + tw - 1 - k, y0 + th - 1 - k)];
                        root.draw(&Rectangle::new(r, rgb(WORST_RGB))).map_err(|e| draw_err(e.to_string()))?;
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
    Ok((png_bytes, layout, shown))
}

/// Writes the contact sheet of `take` to `out` (PNG); returns its layout and the frames shown.
pub fn write_contact_sheet(
    take: &Take,
    cameras: &[Camera],
    columns: usize,
    worst: usize,
    tile_width: u32,
    out: &Path,
) -> Result<(SheetLayout, Vec<ShownFrame>), RenderError> {
    let (bytes, layout, shown) = contact_sheet(take, cameras, columns, worst, tile_width)?;
    write_file(out, &bytes)?;
    Ok((layout, shown))
}
