//! Shared test fixtures: seeded random models covering every joint and function kind.
#![allow(dead_code)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use smocap::model::{
    Body, Coordinate, CoordinateCoupling, CoordinateKind, CubicSpline, Function, Joint, Marker, Model, Motion,
    MotionKind,
};

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

fn unit(r: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(r.random_range(-1.0..1.0), r.random_range(-1.0..1.0), r.random_range(-1.0..1.0));
        if v.norm() > 0.2 {
            return v.normalize();
        }
    }
}

fn iso(r: &mut ChaCha8Rng, reach: f64) -> Isometry3<f64> {
    let t =
        Translation3::new(r.random_range(-reach..reach), r.random_range(-reach..reach), r.random_range(-reach..reach));
    Isometry3::from_parts(t, UnitQuaternion::from_scaled_axis(unit(r) * r.random_range(0.0..2.0)))
}

/// One of every function kind, chosen by `kind % 7`.
pub fn function(r: &mut ChaCha8Rng, kind: usize) -> Function {
    match kind % 7 {
        0 => Function::IDENTITY,
        1 => Function::Linear { slope: r.random_range(-2.0..2.0), intercept: r.random_range(-0.3..0.3) },
        2 => Function::Polynomial { coefficients: (0..4).map(|_| r.random_range(-0.5..0.5)).collect() },
        3 => {
            let x: Vec<f64> = (0..6).map(|i| -2.5 + i as f64).collect();
            let y: Vec<f64> = x.iter().map(|_| r.random_range(-0.2..0.2)).collect();
            Function::Spline(CubicSpline::natural(&x, &y).expect("valid knots"))
        }
        4 => {
            let x = vec![-3.0, -1.05, 0.37, 3.0];
            Function::PiecewiseLinear { x, y: (0..4).map(|_| r.random_range(-0.5..0.5)).collect() }
        }
        5 => Function::Multiplier {
            scale: r.random_range(0.5..1.5),
            inner: Box::new(Function::Polynomial { coefficients: vec![0.1, 0.8, 0.2] }),
        },
        _ => Function::Constant { value: r.random_range(-0.3..0.3) },
    }
}

/// A random tree of `nb` bodies with every motion kind, function kind, scaled translations,
/// offsets on both sides, markers on every body, and one coordinate coupling.
pub fn random_model(seed: u64, nb: usize) -> Model {
    let mut r = rng(seed);
    let mut bodies = Vec::new();
    let mut motions = Vec::new();
    let mut coords = Vec::new();
    let mut markers = Vec::new();
    let mut counter = 0usize;
    for b in 0..nb {
        let parent = if b == 0 { None } else { Some(r.random_range(0..b)) };
        let start = motions.len();
        let nmot = if b == 0 { 6 } else { r.random_range(1..4) };
        for i in 0..nmot {
            let kind = if b == 0 {
                if i < 3 {
                    MotionKind::Translation
                } else {
                    MotionKind::Rotation
                }
            } else if r.random_range(0..4) == 0 {
                MotionKind::Translation
            } else {
                MotionKind::Rotation
            };
            let c = coords.len();
            coords.push(Coordinate {
                name: format!("q{c}"),
                kind: if kind == MotionKind::Rotation {
                    CoordinateKind::Rotational
                } else {
                    CoordinateKind::Translational
                },
                default: 0.0,
                range: (-2.0, 2.0),
                locked: false,
                clamped: true,
            });
            counter += 1;
            let func = if b == 0 { Function::IDENTITY } else { function(&mut r, counter) };
            let weights = (kind == MotionKind::Translation && parent.is_some() && r.random_range(0..2) == 0)
                .then(|| Vector3::new(r.random_range(0.0..1.0), r.random_range(0.0..1.0), r.random_range(0.0..1.0)));
            motions.push(Motion { kind, axis: unit(&mut r), coordinate: Some(c), func, parent_scale_weights: weights });
        }
        bodies.push(Body {
            name: format!("b{b}"),
            parent,
            joint: Joint {
                name: format!("j{b}"),
                parent_offset: iso(&mut r, 0.4),
                child_offset: iso(&mut r, 0.1),
                motions: start..motions.len(),
            },
        });
        for k in 0..3 {
            markers.push(Marker {
                name: format!("m{b}_{k}"),
                body: b,
                offset: Vector3::new(r.random_range(-0.2..0.2), r.random_range(-0.2..0.2), r.random_range(-0.2..0.2)),
                weight: r.random_range(0.5..2.0),
                fixed: false,
                class: None,
            });
        }
    }
    let nq = coords.len();
    let couplings = vec![CoordinateCoupling {
        dependent: nq - 1,
        independent: nq - 2,
        func: Function::Polynomial { coefficients: vec![0.05, 0.7, -0.1] },
    }];
    Model::new(format!("random{seed}"), bodies, motions, coords, markers, couplings).expect("valid random model")
}

/// A random state `y = [q; s]` with scales in [0.7, 1.3].
pub fn random_state(model: &Model, seed: u64) -> Vec<f64> {
    let mut r = rng(seed);
    let mut y = vec![0.0; model.ny()];
    for (j, v) in y.iter_mut().enumerate() {
        *v = if j < model.nq() { r.random_range(-1.5..1.5) } else { r.random_range(0.7..1.3) };
    }
    y
}

/// A path under the shared data folder beside the repository (`../shared/<rel>`).
pub fn shared(rel: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared").join(rel)
}

/// Reads an OpenSim `ScaleSet` file: `<Scale><scales>x y z</scales><segment>name</segment>` entries.
pub fn scale_set(path: &std::path::Path) -> Vec<(String, [f64; 3])> {
    let text = std::fs::read_to_string(path).expect("scale set");
    let doc = roxmltree::Document::parse(&text).expect("xml");
    doc.descendants()
        .filter(|n| n.has_tag_name("Scale"))
        .map(|n| {
            let get = |t: &str| n.children().find(|c| c.has_tag_name(t)).and_then(|c| c.text()).unwrap_or("").trim();
            let v: Vec<f64> = get("scales").split_whitespace().map(|s| s.parse().expect("number")).collect();
            (get("segment").to_string(), [v[0], v[1], v[2]])
        })
        .collect()
}

/// A `datasets.toml` for archives written by `smocap::archive::synthetic::generate` under `data`.
pub const SYNTHETIC_DATASETS: &str = "[[dataset]]\nname = \"lab\"\nroot = \"data\"\ntrials = [\"*/walk*.trc\"]\nsubject = \"{subject}/{trial}.trc\"\nstatic = \"{subject}/static.trc\"\n";

/// Converts `toml_body`'s datasets (written to `dir/datasets.toml`) into `dir/out` with the
/// built binary; the converted trial `rel` there.
pub fn convert_archive(dir: &std::path::Path, toml_body: &str, rel: &str) -> std::path::PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let toml = dir.join("datasets.toml");
    std::fs::write(&toml, toml_body).unwrap();
    let out = dir.join("out");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_smocap"))
        .args(["convert", toml.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out.join(rel)
}

/// One synthetic trial of the shipped model (`frames` frames, seed 5), converted.
pub fn converted_synthetic(dir: &std::path::Path, frames: usize) -> std::path::PathBuf {
    let spec = smocap::archive::config::SyntheticSpec { subjects: 1, trials: 1, frames, seed: 5 };
    smocap::archive::synthetic::generate(&spec, &dir.join("data")).unwrap();
    convert_archive(dir, SYNTHETIC_DATASETS, "lab/subj01/walk01.mcap")
}
