//! Kinematics: analytic Jacobians against central finite differences, for every joint and
//! function kind, at random configurations and scales (seeded).

mod common;

use common::{random_model, random_state};
use smocap::kinematics::assembly::{EvalWorkspace, Evaluator, FrameProblem};
use smocap::kinematics::{cpu, Layout};
use smocap::model::profile::Profile;
use smocap::model::proxy::ProxyMap;
use smocap::model::{CubicSpline, Function};

fn markers_at(model: &smocap::model::Model, y: &[f64]) -> Vec<f64> {
    let mut ws = cpu::Workspace::new(model);
    cpu::forward(model, y, &mut ws);
    ws.markers.clone()
}

#[test]
fn marker_jacobian_pose_and_scale_columns_match_central_differences() {
    for seed in 0..12 {
        let model = random_model(seed, 7);
        let y = random_state(&model, 100 + seed);
        assert_jacobian_matches_fd(&model, &y, &format!("random model {seed}"));
    }
}

#[test]
fn every_function_kind_has_a_consistent_derivative() {
    let mut r = common::rng(7);
    for kind in 0..7 {
        let f = common::function(&mut r, kind);
        for i in 0..50 {
            let x = -2.9 + i as f64 * 0.1171;
            let h = 1e-6;
            let fd = (f.eval(x + h).0 - f.eval(x - h).0) / (2.0 * h);
            let d = f.eval(x).1;
            assert!((fd - d).abs() <= 1e-6 * d.abs().max(1.0), "kind {kind} at {x}: {d} vs {fd}");
        }
    }
}

#[test]
fn natural_spline_interpolates_its_knots_and_has_zero_end_curvature() {
    let x = [0.0, 0.5, 1.3, 2.0, 3.1];
    let y = [0.2, -0.1, 0.4, 0.0, 0.3];
    let s = CubicSpline::natural(&x, &y).unwrap();
    for (xi, yi) in x.iter().zip(&y) {
        assert!((s.eval(*xi).0 - yi).abs() < 1e-12);
    }
    assert!(s.c[0].abs() < 1e-12);
    let f = Function::Spline(s);
    let h = 1e-4;
    let curv = |x: f64| (f.eval(x + h).0 - 2.0 * f.eval(x).0 + f.eval(x - h).0) / (h * h);
    assert!(curv(3.1 - 2.0 * h).abs() < 1e-2);
    assert!(CubicSpline::natural(&[0.0, 0.0], &[1.0, 2.0]).is_none());
}

#[test]
fn gradient_is_the_derivative_of_the_energy_and_hessian_is_gauss_newton() {
    for seed in 0..6 {
        let model = random_model(seed, 6);
        let proxy = ProxyMap::new(&model, &Profile::default_for(&model)).unwrap();
        let eval = Evaluator::new(&model, &proxy);
        let mut ws = EvalWorkspace::new(&model, &proxy);
        let mut r = common::rng(seed + 50);
        use rand::RngExt;
        let p: Vec<f64> = proxy
            .proxies
            .iter()
            .map(|px| {
                if px.kind == smocap::model::proxy::ProxyKind::Scale {
                    r.random_range(0.8..1.2)
                } else {
                    r.random_range(-1.0..1.0)
                }
            })
            .collect();
        // Observations near the model, one marker missing, one with weight 0.
        let mut obs = markers_at(&model, &proxy.state(&p));
        for v in obs.iter_mut() {
            *v += r.random_range(-0.05..0.05);
        }
        obs[0] = f64::NAN;
        let mut weights: Vec<f64> = model.markers.iter().map(|m| m.weight).collect();
        weights[2] = 0.0;
        let tref: Vec<f64> = (0..model.ny()).map(|_| r.random_range(-0.5..1.0)).collect();
        let tw: Vec<f64> = (0..model.ny()).map(|j| if j % 3 == 0 { 0.3 } else { 0.0 }).collect();
        let frame =
            FrameProblem { observed: &obs, marker_weights: &weights, tracking_ref: &tref, tracking_weights: &tw };
        eval.linearize(&p, &frame, &mut ws);
        let g = ws.gn.g.clone();
        let hm = ws.gn.h.clone();
        let h = 1e-6;
        for k in 0..p.len() {
            let mut pp = p.clone();
            let mut pm = p.clone();
            pp[k] += h;
            pm[k] -= h;
            let fd = (eval.energy(&pp, &frame, &mut ws).0 - eval.energy(&pm, &frame, &mut ws).0) / (2.0 * h);
            assert!((fd - g[k]).abs() <= 1e-6 * g[k].abs().max(1.0), "seed {seed}: g[{k}] {} vs fd {fd}", g[k]);
        }
        // H = J_mᵀ W J_m + J_Φᵀ W_t J_Φ from finite-difference residual Jacobians.
        let np = p.len();
        let resid = |q: &[f64], ws: &mut EvalWorkspace| -> Vec<f64> {
            eval.energy(q, &frame, ws);
            let mut r = Vec::new();
            for m in 0..model.markers.len() {
                if weights[m] > 0.0 && !obs[3 * m].is_nan() {
                    for a in 0..3 {
                        r.push(weights[m].sqrt() * (ws.kin.markers[3 * m + a] - obs[3 * m + a]));
                    }
                }
            }
            for j in 0..model.ny() {
                if tw[j] > 0.0 {
                    r.push(tw[j].sqrt() * (ws.y[j] - tref[j]));
                }
            }
            r
        };
        let cols: Vec<Vec<f64>> = (0..np)
            .map(|k| {
                let mut pp = p.clone();
                let mut pm = p.clone();
                pp[k] += h;
                pm[k] -= h;
                let (a, b) = (resid(&pp, &mut ws), resid(&pm, &mut ws));
                a.iter().zip(&b).map(|(x, y)| (x - y) / (2.0 * h)).collect()
            })
            .collect();
        for i in 0..np {
            for j in 0..np {
                let fd: f64 = cols[i].iter().zip(&cols[j]).map(|(a, b)| a * b).sum();
                assert!(
                    (fd - hm[(i, j)]).abs() <= 1e-5 * fd.abs().max(1.0),
                    "seed {seed}: H[{i},{j}] {} vs {fd}",
                    hm[(i, j)]
                );
            }
        }
    }
}

#[test]
fn proxy_map_jacobian_matches_finite_differences_for_polynomial_couplings() {
    let model = random_model(3, 7);
    let nq = model.nq();
    let names: Vec<String> = model.coordinates[6..nq - 2].iter().take(3).map(|c| c.name.clone()).collect();
    assert_eq!(names.len(), 3);
    let text = format!(
        "[[coupling]]\nproxy = \"spine\"\nrange = [-1.0, 1.0]\ncoordinates = [{}]\ncoefficients = [[0.0, 0.3, 0.05], [0.1, 0.5], [0.0, 0.2, -0.1, 0.02]]\n",
        names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
    );
    let mut profile = Profile::parse(&text, std::path::Path::new("test.toml")).unwrap();
    profile.scale_groups = Profile::default_for(&model).scale_groups;
    let proxy = ProxyMap::new(&model, &profile).unwrap();
    let k = proxy.proxy_index("spine").unwrap();
    let mut p = proxy.default_proxies();
    p[k] = 0.37;
    let mut y = vec![0.0; proxy.ny()];
    let mut d = vec![0.0; proxy.terms.len()];
    proxy.apply(&p, &mut y, &mut d);
    let h = 1e-6;
    for (t, term) in proxy.terms.iter().enumerate() {
        let mut pp = p.clone();
        let mut pm = p.clone();
        pp[term.proxy] += h;
        pm[term.proxy] -= h;
        let fd = (proxy.state(&pp)[term.y_index] - proxy.state(&pm)[term.y_index]) / (2.0 * h);
        assert!((fd - d[t]).abs() < 1e-7, "term {t}: {} vs {fd}", d[t]);
    }
    let j = model.coordinate_index(&names[1]).unwrap();
    assert!((y[j] - (0.1 + 0.5 * 0.37)).abs() < 1e-12);
}

#[test]
fn batched_evaluation_equals_frame_by_frame_evaluation() {
    use smocap::kinematics::batch::{energy_batch, linearize_batch};
    let model = random_model(9, 6);
    let proxy = ProxyMap::new(&model, &Profile::default_for(&model)).unwrap();
    let eval = Evaluator::new(&model, &proxy);
    let weights: Vec<f64> = model.markers.iter().map(|m| m.weight).collect();
    let zeros = vec![0.0; model.ny()];
    let ps: Vec<Vec<f64>> =
        (0..40).map(|f| proxy.default_proxies().iter().map(|v| v + 0.01 * f as f64).collect()).collect();
    let obs: Vec<Vec<f64>> =
        ps.iter().map(|p| markers_at(&model, &proxy.state(p)).iter().map(|v| v + 0.003).collect()).collect();
    let frames: Vec<FrameProblem> = obs
        .iter()
        .map(|o| FrameProblem { observed: o, marker_weights: &weights, tracking_ref: &zeros, tracking_weights: &zeros })
        .collect();
    let batch = linearize_batch(&eval, &frames, &ps);
    let energies = energy_batch(&eval, &frames, &ps);
    let mut ws = EvalWorkspace::new(&model, &proxy);
    for f in 0..frames.len() {
        eval.linearize(&ps[f], &frames[f], &mut ws);
        assert_eq!(batch[f].gn.h, ws.gn.h);
        assert_eq!(batch[f].gn.g, ws.gn.g);
        assert_eq!(batch[f].gn.energy, ws.gn.energy);
        assert_eq!(energies[f], ws.gn.energy);
    }
}

#[test]
fn dense_marker_jacobian_is_jy_times_jphi() {
    let model = random_model(4, 5);
    let proxy = ProxyMap::new(&model, &Profile::default_for(&model)).unwrap();
    let eval = Evaluator::new(&model, &proxy);
    let mut ws = EvalWorkspace::new(&model, &proxy);
    let p = proxy.default_proxies();
    let obs = markers_at(&model, &proxy.state(&p));
    let weights: Vec<f64> = vec![1.0; model.markers.len()];
    let zeros = vec![0.0; model.ny()];
    let frame =
        FrameProblem { observed: &obs, marker_weights: &weights, tracking_ref: &zeros, tracking_weights: &zeros };
    eval.linearize(&p, &frame, &mut ws);
    cpu::jacobian(&model, &eval.layout, &mut ws.kin);
    let jm = eval.marker_jacobian(&ws);
    // H = J_mᵀ J_m with unit weights and no tracking.
    let h = jm.transpose() * &jm;
    assert!((h - &ws.gn.h).amax() < 1e-10);
}

/// Central-difference check of `J_y` for `model` at `y`.
fn assert_jacobian_matches_fd(model: &smocap::model::Model, y: &[f64], what: &str) {
    let proxy = ProxyMap::new(model, &Profile::default_for(model)).unwrap();
    let layout = Layout::new(model, &proxy);
    let mut ws = cpu::Workspace::new(model);
    cpu::forward(model, y, &mut ws);
    cpu::jacobian(model, &layout, &mut ws);
    let h = 1e-6;
    for j in 0..model.ny() {
        let (mut yp, mut ym) = (y.to_vec(), y.to_vec());
        yp[j] += h;
        ym[j] -= h;
        let (xp, xm) = (markers_at(model, &yp), markers_at(model, &ym));
        for r in 0..xp.len() {
            let fd = (xp[r] - xm[r]) / (2.0 * h);
            let an = ws.jy_t[(j, r)];
            assert!((fd - an).abs() <= 1e-6 * an.abs().max(1.0), "{what}: J[{r}, {j}] analytic {an} vs fd {fd}");
        }
    }
}

#[test]
fn jacobian_matches_finite_differences_for_every_mjcf_joint_type_and_joint_anchors() {
    let xml = r#"<mujoco model="kinds">
      <compiler angle="radian"/>
      <worldbody>
        <body name="root" pos="0.1 0.2 0.9">
          <freejoint name="root"/>
          <site name="r0" pos="0.1 0 0"/><site name="r1" pos="0 0.1 0"/><site name="r2" pos="0 0 0.1"/>
          <body name="ball" pos="0 0.1 -0.1" euler="0.2 0.1 0.3">
            <joint name="b" type="ball" pos="0 0 0.05"/>
            <site name="b0" pos="0.05 0 -0.2"/><site name="b1" pos="0 0.04 -0.3"/>
            <body name="hinge" pos="0 0 -0.4">
              <joint name="h" type="hinge" axis="0.3 1 0" pos="0.01 0 0.02" ref="0.2" range="-2 2"/>
              <site name="h0" pos="0.02 0.01 -0.25"/>
              <body name="slide" pos="0 0 -0.3" quat="0.9 0.1 0.2 0.3">
                <joint name="s" type="slide" axis="0 0 1"/>
                <joint name="s2" type="hinge" axis="1 0 0"/>
                <site name="s0" pos="0.1 0.05 0"/>
              </body>
            </body>
          </body>
        </body>
      </worldbody>
    </mujoco>"#;
    let model = smocap::io::mjcf::parse_mjcf(xml, "kinds.xml").unwrap();
    for seed in 0..4 {
        let y = random_state(&model, 300 + seed);
        assert_jacobian_matches_fd(&model, &y, &format!("mjcf kinds, seed {seed}"));
    }
}

#[test]
fn jacobian_matches_finite_differences_on_the_shipped_model() {
    let model = smocap::io::mjcf::parse_mjcf(smocap::pipeline::context::SHIPPED_MODEL, "fullbody.xml").unwrap();
    let mut y = random_state(&model, 77);
    for (j, c) in model.coordinates.iter().enumerate() {
        y[j] = y[j].clamp(c.range.0.max(-1.5), c.range.1.min(1.5));
    }
    assert_jacobian_matches_fd(&model, &y, "fullbody");
}

#[test]
fn coordinate_targets_fold_into_tracking_with_consistent_derivatives() {
    use smocap::kinematics::assembly::fold_tracking_reference;
    // Targets on two spine coordinates driven by one polynomial proxy, and on a free coordinate.
    let model = random_model(3, 7);
    let nq = model.nq();
    let names: Vec<String> = model.coordinates[6..nq - 2].iter().take(3).map(|c| c.name.clone()).collect();
    let text = format!(
        "[[coupling]]\nproxy = \"spine\"\nrange = [-1.0, 1.0]\ncoordinates = [{}]\ncoefficients = [[0.0, 0.3, 0.05], [0.1, 0.5], [0.0, 0.2, -0.1, 0.02]]\n",
        names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
    );
    let mut profile = Profile::parse(&text, std::path::Path::new("test.toml")).unwrap();
    profile.scale_groups = Profile::default_for(&model).scale_groups;
    let free = model.coordinates[nq - 1].name.clone();
    let mut ctx = smocap::pipeline::Context::new(model, profile, "test.toml", "test".into()).unwrap();
    let setup = format!(
        "<InverseKinematicsTool><IKTaskSet><objects>\
         <IKCoordinateTask name=\"{}\"><weight>4</weight><value_type>manual_value</value_type><value>0.2</value></IKCoordinateTask>\
         <IKCoordinateTask name=\"{}\"><weight>2.5</weight><value_type>manual_value</value_type><value>-0.1</value></IKCoordinateTask>\
         <IKCoordinateTask name=\"{free}\"><weight>7</weight></IKCoordinateTask>\
         </objects></IKTaskSet></InverseKinematicsTool>",
        names[0], names[2]
    );
    let done = ctx.apply_ik_setup(&smocap::io::osim::parse_ik_setup(&setup, "ik.xml").unwrap()).unwrap();
    assert_eq!(done.coordinate_targets, 3);
    ctx.marker_weights.iter_mut().for_each(|w| *w = 1.0);
    let (model, proxy) = (&ctx.model, &ctx.proxy);
    let eval = Evaluator::new(model, proxy);
    let mut ws = EvalWorkspace::new(model, proxy);
    let mut r = common::rng(77);
    use rand::RngExt;
    let (ny, np) = (model.ny(), proxy.np());
    // A pose prior toward a reference (as the trial solver's), with the targets folded in.
    let base_w: Vec<f64> = (0..ny).map(|j| if j < nq { 0.3 } else { 0.0 }).collect();
    let mut reference: Vec<f64> = (0..ny).map(|_| r.random_range(-0.5..0.5)).collect();
    let base_ref = reference.clone();
    let (coord_ref, coord_w) = ctx.coordinate_tracking();
    fold_tracking_reference(&mut reference, &base_w, &coord_ref, &coord_w);
    let weights: Vec<f64> = base_w.iter().zip(&coord_w).map(|(a, b)| a + b).collect();
    let p: Vec<f64> = proxy.proxies.iter().map(|px| px.default + r.random_range(-0.3..0.3)).collect();
    let obs: Vec<f64> = markers_at(model, &proxy.state(&p)).iter().map(|v| v + r.random_range(-0.05..0.05)).collect();
    let folded = FrameProblem {
        observed: &obs,
        marker_weights: &ctx.marker_weights,
        tracking_ref: &reference,
        tracking_weights: &weights,
    };
    // The folded objective equals markers + prior + ½ Σ w (y − target)², up to a constant.
    let separate = |q: &[f64], ws: &mut EvalWorkspace| {
        let base = FrameProblem { tracking_ref: &base_ref, tracking_weights: &base_w, ..folded };
        let y = proxy.state(q);
        eval.energy(q, &base, ws).0 + (0..nq).map(|j| 0.5 * coord_w[j] * (y[j] - coord_ref[j]).powi(2)).sum::<f64>()
    };
    let offset = eval.energy(&p, &folded, &mut ws).0 - separate(&p, &mut ws);
    for _ in 0..5 {
        let q: Vec<f64> = p.iter().map(|v| v + r.random_range(-0.2..0.2)).collect();
        let d = eval.energy(&q, &folded, &mut ws).0 - separate(&q, &mut ws);
        assert!((d - offset).abs() < 1e-10 * offset.abs().max(1.0), "{d} vs {offset}");
    }
    // Gradient: central differences of the energy; H: Gauss–Newton from residual Jacobians.
    eval.linearize(&p, &folded, &mut ws);
    let (g, hm) = (ws.gn.g.clone(), ws.gn.h.clone());
    let h = 1e-6;
    let resid = |q: &[f64], ws: &mut EvalWorkspace| -> Vec<f64> {
        eval.energy(q, &folded, ws);
        let mut out: Vec<f64> = (0..3 * model.markers.len()).map(|i| ws.kin.markers[i] - obs[i]).collect();
        out.extend((0..ny).map(|j| weights[j].sqrt() * (ws.y[j] - reference[j])));
        out
    };
    let mut cols = Vec::with_capacity(np);
    for k in 0..np {
        let (mut pp, mut pm) = (p.clone(), p.clone());
        pp[k] += h;
        pm[k] -= h;
        let fd = (eval.energy(&pp, &folded, &mut ws).0 - eval.energy(&pm, &folded, &mut ws).0) / (2.0 * h);
        assert!((fd - g[k]).abs() <= 1e-6 * g[k].abs().max(1.0), "g[{k}] {} vs fd {fd}", g[k]);
        let (a, b) = (resid(&pp, &mut ws), resid(&pm, &mut ws));
        cols.push(a.iter().zip(&b).map(|(x, y)| (x - y) / (2.0 * h)).collect::<Vec<f64>>());
    }
    for i in 0..np {
        for j in 0..np {
            let fd: f64 = cols[i].iter().zip(&cols[j]).map(|(a, b)| a * b).sum();
            assert!((fd - hm[(i, j)]).abs() <= 1e-5 * fd.abs().max(1.0), "H[{i},{j}] {} vs {fd}", hm[(i, j)]);
        }
    }
}
