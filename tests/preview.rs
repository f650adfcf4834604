//! `smocap preview`: the contact sheet of a converted trial decodes as a PNG of the stated size
//! with one panel (row of tiles) per camera, each showing the projected skeleton; the bytes are
//! the same on every run; each panel frames the subject, and the worst frames are shown with a
//! red border.

mod common;

use common::converted_synthetic;
use smocap::render::preview::{SheetLayout, SHEET_RGB, TILE_RGB};
use std::path::{Path, PathBuf};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("smocap-preview-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn smocap(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_smocap")).args(args).output().unwrap()
}

/// Decodes an 8-bit RGB PNG: (width, height, pixels).
fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().expect("a PNG");
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).expect("its image decodes");
    assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Rgb, png::BitDepth::Eight));
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

#[test]
fn the_preview_of_a_converted_trial_decodes_with_one_panel_per_camera_showing_the_skeleton() {
    let dir = tmp("sheet");
    let file = converted_synthetic(&dir, 40);
    // Three cameras: the panels follow the rig.
    let rig = dir.join("rig.toml");
    let mut text = String::new();
    for (name, pos) in [("front", "[4.5, 0, 1.1]"), ("side", "[0, -4.5, 1.1]"), ("high", "[3, 3, 3]")] {
        text += &format!(
            "[[cameras]]\nname = \"{name}\"\nposition = {pos}\nlook_at = [0, 0, 0.9]\nfocal_mm = 33\nsensor_width_mm = 36\nwidth_px = 1080\nheight_px = 720\n\n"
        );
    }
    std::fs::write(&rig, text).unwrap();
    let (a, b) = (dir.join("a.png"), dir.join("b.png"));
    for out in [&a, &b] {
        let o = smocap(&[
            "preview",
            file.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--cameras",
            rig.to_str().unwrap(),
            "--frames",
            "5",
            "--worst",
            "0",
            "--tile-width",
            "180",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "two previews of one file differ");
    let (w, h, px) = decode(&a);
    let layout = SheetLayout { columns: 5, tile: (180, 120), gap: 6, rows: 3 };
    assert_eq!((w, h), layout.size());
    let at = |x: i32, y: i32| {
        let i = 3 * (y as usize * w as usize + x as usize);
        [px[i], px[i + 1], px[i + 2]]
    };
    for row in 0..3 {
        let mut drawn_tiles = 0;
        for col in 0..5 {
            let (x0, y0) = layout.origin(row, col);
            assert_eq!(at(x0 - 1, y0 - 1), SHEET_RGB, "the gap around panel {row} tile {col}");
            assert_eq!(at(x0 + 1, y0 + 1), TILE_RGB, "the tile's corner is background");
            let drawn = (y0..y0 + 120)
                .flat_map(|y| (x0..x0 + 180).map(move |x| (x, y)))
                .filter(|&(x, y)| at(x, y) != TILE_RGB)
                .count();
            if drawn > 50 {
                drawn_tiles += 1;
            }
        }
        assert_eq!(drawn_tiles, 5, "panel {row}: every tile shows the subject");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The share of a tile's height (inside its border) that rows with drawn pixels span.
fn drawn_height(px: &[u8], w: u32, layout: &SheetLayout, row: usize, col: usize) -> f64 {
    let (x0, y0) = layout.origin(row, col);
    let (tw, th) = (layout.tile.0 as i32, layout.tile.1 as i32);
    let rows: Vec<i32> = (y0 + 3..y0 + th - 3)
        .filter(|&y| {
            (x0 + 3..x0 + tw - 3).any(|x| {
                let i = 3 * (y as usize * w as usize + x as usize);
                px[i..i + 3] != TILE_RGB
            })
        })
        .collect();
    match (rows.first(), rows.last()) {
        (Some(a), Some(b)) => (b - a + 1) as f64 / (th - 6) as f64,
        _ => 0.0,
    }
}

#[test]
fn each_panel_frames_the_subject_and_the_worst_frames_get_a_red_border() {
    use smocap::render::preview::{worst_frames, WORST_RGB};
    let dir = tmp("framing");
    let file = converted_synthetic(&dir, 60);
    let out = dir.join("sheet.png");
    let o =
        smocap(&["preview", file.to_str().unwrap(), "--out", out.to_str().unwrap(), "--frames", "3", "--worst", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("red border: frame"), "the worst frame is named: {err}");
    let (w, h, px) = decode(&out);
    // Three evenly spaced frames and the worst one (unless it is one of them).
    let columns = ((w - 6) / (240 + 6)) as usize;
    assert!(columns == 3 || columns == 4, "{columns} tiles per panel");
    let layout = SheetLayout { columns, tile: (240, (h - 6 * 3) / 2), gap: 6, rows: 2 };
    assert_eq!((w, h), layout.size());
    let mut red = 0;
    for row in 0..2 {
        // Framed: in each panel the subject spans most of a tile's height where it is largest
        // (the window is one size per panel), and half of it everywhere. Unframed, the subject
        // spanned 40–66 % of a tile of the default rig.
        let heights: Vec<f64> = (0..columns).map(|col| drawn_height(&px, w, &layout, row, col)).collect();
        assert!(heights.iter().cloned().fold(0.0, f64::max) >= 0.8, "panel {row}: {heights:.2?}");
        assert!(heights.iter().all(|&h| h >= 0.45), "panel {row}: {heights:.2?}");
        for col in 0..columns {
            let (x0, y0) = layout.origin(row, col);
            let i = 3 * ((y0 + 1) as usize * w as usize + (x0 + 1) as usize);
            red += usize::from(px[i..i + 3] == WORST_RGB);
        }
    }
    assert_eq!(red, 2, "one worst frame, bordered in both panels");
    // Worst frames are one per event: the second worst is apart from the first.
    let rmse = [Some(1.0), Some(9.0), Some(8.5), Some(2.0), Some(7.0), None];
    assert_eq!(worst_frames(&rmse, 2, 2), vec![1, 4]);
    assert_eq!(worst_frames(&rmse, 3, 1), vec![1, 2, 4]);
    let _ = std::fs::remove_dir_all(&dir);
}
