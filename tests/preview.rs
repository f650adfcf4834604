//! `smocap preview`: the contact sheet of a converted trial decodes as a PNG of the stated size
//! with one panel (row of tiles) per camera, each showing the projected skeleton; the bytes are
//! the same on every run.

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
