//! `smocap render` on lavapipe (or any wgpu adapter; without one each test prints a note and
//! passes): the mask against a CPU rasterization of the same posed mesh and cameras (pixel
//! centres sampled, as the GPU does), the depth buffer against the mesh's depths, keypoint
//! visibility against the buffers, and the same bytes from two runs.

mod common;

use smocap::render::raster::{Gpu, Images, RasterError};
use smocap::render::rig::Camera;
use smocap::render::video::{Actor, Keypoints, Renderer};
use smocap::render::visibility::DEPTH_TOLERANCE_M;
use std::path::{Path, PathBuf};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("smocap-render-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn gpu() -> Option<Gpu> {
    // Mesa's Vulkan drivers print a harmless libwayland error without a runtime directory (the
    // command line sets one the same way, src/main.rs).
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    match Gpu::new() {
        Ok(g) => Some(g),
        Err(RasterError::NoAdapter(why)) => {
            eprintln!("note: no wgpu adapter ({why}); render tests skipped");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

fn actor(file: &Path) -> Actor {
    let rec = smocap::archive::export::read_trial_record(file).unwrap();
    let take = smocap::render::Take::from_record(&rec, file).unwrap();
    let asset = smocap::body::BodyAsset::shipped().unwrap();
    let sub = smocap::body::SubjectBody { stature_m: rec.subject_stature_m, info: rec.subject_info };
    Actor::dress(take, &asset, &sub).unwrap().0
}

/// The silhouette of `tris` over `uv` (px) sampled at pixel centres; each pixel's nearest depth.
fn cpu_raster(uv: &[[f64; 3]], tris: &[[u32; 3]], w: usize, h: usize) -> (Vec<bool>, Vec<f64>) {
    let (mut inside, mut depth) = (vec![false; w * h], vec![f64::INFINITY; w * h]);
    for t in tris {
        let [a, b, c] = t.map(|i| uv[i as usize]);
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if area.abs() < 1e-12 {
            continue;
        }
        let lo = |k: usize| a[k].min(b[k]).min(c[k]).ceil().max(0.0) as usize;
        let hi = |k: usize, n: usize| (a[k].max(b[k]).max(c[k]).floor() as i64).min(n as i64 - 1);
        let (x1, y1) = (hi(0, w), hi(1, h));
        for y in lo(1)..=y1.max(-1) as usize {
            for x in lo(0)..=x1.max(-1) as usize {
                let (px, py) = (x as f64, y as f64);
                let e = |p: [f64; 3], q: [f64; 3]| ((q[0] - p[0]) * (py - p[1]) - (q[1] - p[1]) * (px - p[0])) / area;
                let (wa, wb, wc) = (e(b, c), e(c, a), e(a, b));
                if wa >= 0.0 && wb >= 0.0 && wc >= 0.0 {
                    // perspective-correct depth: 1/z is affine in the image
                    let z = 1.0 / (wa / a[2] + wb / b[2] + wc / c[2]);
                    inside[y * w + x] = true;
                    depth[y * w + x] = depth[y * w + x].min(z);
                }
            }
        }
    }
    (inside, depth)
}

#[test]
fn the_render_matches_a_cpu_rasterization_and_the_visibility_rules_hold() {
    let Some(gpu) = gpu() else { return };
    let dir = tmp("match");
    let file = common::converted_synthetic(&dir, 40);
    let a = actor(&file);
    let cams = smocap::render::cameras(&a.take, None, 3).unwrap();
    let cams = smocap::render::video::resized(cams, Some((320, 240)));
    let scene = smocap::render::look::scene(3);
    let mut r = Renderer::new(gpu, vec![a], cams.clone(), scene, 3);
    let mut images = vec![Images::default(); cams.len()];
    let (mut kp, mut counts) = (Keypoints::default(), [0usize; 3]);
    let mut ws = smocap::body::PoseWorkspace::new(&r.actors[0].take.model, &r.actors[0].body);
    for i in [0, 13, 39] {
        r.draw(i, &mut images).unwrap();
        let take = &r.actors[0].take;
        let mut y = take.q[i].clone();
        y.extend_from_slice(&take.scales);
        r.actors[0].body.pose(&take.model, &y, &mut ws);
        for (c, cam) in cams.iter().enumerate() {
            let img = &images[c];
            let uv: Vec<[f64; 3]> = ws
                .vertices
                .iter()
                .map(|v| cam.project(&nalgebra::Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)))
                .map(|p| [p.u, p.v, p.depth])
                .collect();
            let (inside, depth) = cpu_raster(&uv, &r.actors[0].body.triangles, 320, 240);
            let both = inside.iter().zip(&img.mask).filter(|(a, m)| **a && **m > 0).count();
            let either = inside.iter().zip(&img.mask).filter(|(a, m)| **a || **m > 0).count();
            let iou = both as f64 / either as f64;
            assert!(either > 500 && iou > 0.995, "frame {i} camera {}: IoU {iou} over {either} px", cam.name);
            // where both see the body the depths agree (a pixel centre on an occluding contour may
            // fall either side of it: 99 % within 0.5 mm)
            let mut off: Vec<f64> = (0..inside.len())
                .filter(|&p| inside[p] && img.mask[p] > 0)
                .map(|p| (depth[p] - img.depth_m[p] as f64).abs())
                .collect();
            off.sort_by(f64::total_cmp);
            let (p50, p99) = (off[off.len() / 2], off[off.len() * 99 / 100]);
            eprintln!(
                "frame {i} camera {}: IoU {iou:.5}, depth error median {p50:.1e} m, p99 {p99:.1e} m, max {:.1e} m",
                cam.name,
                off[off.len() - 1]
            );
            assert!(
                p50 < 1e-4 && p99 < 5e-4,
                "frame {i} camera {}: depth off by {p50} (median) {p99} (p99) m",
                cam.name
            );
            r.keypoints(0, i, c, img, &mut kp);
            check_visibility(cam, img, &kp, (&ws.vertices, &r.actors[0].body.triangles), &mut counts);
        }
    }
    eprintln!("keypoints: {} outside, {} occluded, {} visible", counts[0], counts[1], counts[2]);
    assert!(counts[1] > 0 && counts[2] > 0, "{counts:?}");
}

/// v = 0 only outside the image; v = 1 more than the tolerance behind the buffer (a surface
/// keypoint there: behind the mesh, by its ray); bbox holds v = 2.
fn check_visibility(
    cam: &Camera,
    img: &Images,
    kp: &Keypoints,
    mesh: smocap::render::visibility::Mesh,
    counts: &mut [usize; 3],
) {
    for (j, d) in kp.depths_m.iter().enumerate() {
        let (x, y, v) = (kp.xyv[3 * j], kp.xyv[3 * j + 1], kp.xyv[3 * j + 2] as usize);
        counts[v] += 1;
        if v == 0 {
            continue;
        }
        let (px, py) = ((x + 0.5).floor() as i64, (y + 0.5).floor() as i64);
        let p = img.index(px, py).unwrap_or_else(|| panic!("{}: v={v} outside the image", cam.name));
        if v == 1 {
            let behind = img.mask[p] > 0 && *d > img.depth_m[p] as f64 + DEPTH_TOLERANCE_M;
            // a surface keypoint behind a sliver thinner than a pixel: the mesh is in front on its ray
            let sliver = j < smocap::body::keypoints::NAMES.len() && {
                let on_ray = cam.k.try_inverse().unwrap() * nalgebra::Vector3::new(x, y, 1.0) * *d;
                let world = cam.r.transpose() * (on_ray - cam.t);
                smocap::render::visibility::occluded_on_meshes(cam, &world, *d, &[mesh])
            };
            assert!(behind || sliver, "keypoint {j} occluded");
        } else {
            let b = kp.bbox;
            assert!(x >= b[0] && x <= b[0] + b[2] && y >= b[1] && y <= b[1] + b[3], "keypoint {j} outside its box");
        }
    }
}

fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out: Vec<(PathBuf, Vec<u8>)> = walkdir::WalkDir::new(dir)
        .sort_by_file_name()
        .into_iter()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().is_file() && e.file_name() != "render.json")
        .map(|e| (e.path().strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(e.path()).unwrap()))
        .collect();
    out.sort();
    out
}

#[test]
fn two_renders_write_the_same_bytes() {
    if gpu().is_none() {
        return;
    }
    let dir = tmp("twice");
    let file = common::converted_synthetic(&dir, 12);
    let run = |out: &Path| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
            .arg("render")
            .arg(&file)
            .args(["--size", "200x150", "--every", "3", "--seed", "7", "-q", "--out"])
            .arg(out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(&dir.join("a"));
    run(&dir.join("b"));
    let (a, b) = (files(&dir.join("a")), files(&dir.join("b")));
    assert!(a.len() >= 2 * 3 * 4 + 3, "{} files", a.len());
    for ((pa, ba), (pb, bb)) in a.iter().zip(&b) {
        assert_eq!(pa, pb);
        assert!(ba == bb, "{} differs", pa.display());
    }
    assert_eq!(a.len(), b.len());
    let coco: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("a/frontal.coco.json")).unwrap()).unwrap();
    assert_eq!(coco["images"].as_array().unwrap().len(), 4);
    assert_eq!(
        coco["annotations"][0]["keypoint_depths_m"].as_array().unwrap().len(),
        coco["categories"][0]["keypoints"].as_array().unwrap().len()
    );
}

#[test]
fn subjects_rendered_together_have_their_own_labels_and_categories() {
    if gpu().is_none() {
        return;
    }
    let dir = tmp("together");
    let spec = smocap::archive::config::SyntheticSpec { subjects: 2, trials: 1, frames: 8, seed: 5 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    let first = common::convert_archive(&dir, common::SYNTHETIC_DATASETS, "lab/subj01/walk01.mcap");
    let second = dir.join("out/lab/subj02/walk01.mcap");
    let out = dir.join("r");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
        .arg("render")
        .args([&first, &second])
        .args(["--together", "--size", "200x150", "--every", "4", "-q", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let coco: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("sagittal.coco.json")).unwrap()).unwrap();
    let cats = coco["categories"].as_array().unwrap();
    assert_eq!(cats.len(), 2);
    let nb = cats[0]["mask_labels"]["bodies"].as_array().unwrap().len() as u64;
    assert_eq!(cats[1]["mask_labels"]["first"].as_u64(), Some(1 + nb));
    let anns = coco["annotations"].as_array().unwrap();
    assert_eq!(anns.len(), 2 * coco["images"].as_array().unwrap().len());
    assert!(anns.iter().all(|a| a["area"].as_f64().unwrap() > 0.0), "both subjects seen in every image");
}
