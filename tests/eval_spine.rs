//! The spine ablation: its three profile variants are what they claim to be, and a tiny run
//! reports finite metrics of the right shape for each (no thresholds on the values: those are
//! the evaluation's findings, recorded in docs/EVALUATION.md).

use smocap::eval::spine::{roughness, run, variant_profile, SpineOptions, Variant, AXES, LEVELS};
use smocap::io::mjcf;
use smocap::model::profile::Profile;
use smocap::model::proxy::ProxyMap;
use smocap::pipeline::context::{SHIPPED_MODEL, SHIPPED_PROFILE};
use std::path::Path;

fn shipped() -> (smocap::model::Model, Profile) {
    let m = mjcf::parse_mjcf(SHIPPED_MODEL, "models/fullbody.xml").unwrap();
    let p = Profile::parse(SHIPPED_PROFILE, Path::new("models/fullbody.toml")).unwrap();
    (m, p)
}

#[test]
fn variants_drive_the_lumbar_levels_as_named() {
    let (m, base) = shipped();
    let map = |v| ProxyMap::new(&m, &variant_profile(&base, v, "L3_L4").unwrap()).unwrap();
    let spine_proxies = |pm: &ProxyMap| {
        pm.proxies
            .iter()
            .filter(|p| p.name.starts_with("lumbar_") || LEVELS.iter().any(|l| p.name.starts_with(l)))
            .count()
    };
    let (poly, nopoly, classical) = (map(Variant::Poly), map(Variant::Nopoly), map(Variant::Classical));
    assert_eq!(spine_proxies(&poly), 3);
    assert_eq!(spine_proxies(&nopoly), 18);
    assert_eq!(spine_proxies(&classical), 3);
    // Classical: a lumbar proxy moves its level one to one and nothing else of the spine.
    let k = classical.proxy_index("lumbar_flexion").unwrap();
    let mut p = classical.default_proxies();
    p[k] = 0.7;
    let y = classical.state(&p);
    for level in LEVELS {
        for axis in AXES {
            let q = y[m.coordinate_index(&format!("{level}_{axis}")).unwrap()];
            let expect = if level == "L3_L4" && axis == "flexion" { 0.7 } else { 0.0 };
            assert!((q - expect).abs() < 1e-12, "{level}_{axis} = {q}");
        }
    }
    assert!(variant_profile(&base, Variant::Classical, "C7_T1").is_err());
}

#[test]
fn roughness_of_a_linear_spine_is_zero_and_of_a_kink_is_positive() {
    let linear: Vec<[[f64; 6]; 3]> =
        (0..5).map(|t| [0, 1, 2].map(|a| [0, 1, 2, 3, 4, 5].map(|l| 0.01 * (t + a + l) as f64))).collect();
    let r = roughness(&linear);
    assert!(r.spatial_deg2.abs() < 1e-20 && r.temporal_deg2.values().all(|v| v.abs() < 1e-20));
    let mut kinked = linear.clone();
    kinked[2][0][3] += 0.1;
    let r = roughness(&kinked);
    assert!(r.spatial_axis_deg2[0] > 0.0 && r.temporal_deg2["L2_L3_flexion"] > 0.0);
    assert!(r.spatial_axis_deg2[1] < 1e-20);
}

#[test]
fn tiny_ablation_reports_finite_metrics_for_every_variant() {
    let opt = SpineOptions { frames: 40, repeats: 1, ..SpineOptions::default() };
    let r = run(&opt).expect("runs");
    assert_eq!(r.variants.len(), 3);
    assert_eq!(r.truth.temporal_deg2.len(), 18);
    for v in &r.variants {
        let name = v.variant.name();
        assert_eq!(v.roughness.temporal_deg2.len(), 18, "{name}");
        assert!(v.marker_rmse_mm.mean.is_finite() && v.marker_rmse_mm.mean > 0.0, "{name}");
        assert!(v.ms_per_frame.p50.is_finite() && v.iterations.p50 >= 1.0, "{name}");
        assert!(v.spine_error_deg.is_finite() && v.roughness.spatial_deg2.is_finite(), "{name}");
        assert!(v.roughness.temporal_deg2.values().all(|x| x.is_finite()), "{name}");
    }
    // Classical's fixed levels do not move at all.
    let c = r.variants.iter().find(|v| v.variant == Variant::Classical).unwrap();
    assert_eq!(c.roughness.temporal_deg2["L5_S1_bending"], 0.0);
}
