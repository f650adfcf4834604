//! MJCF import: structure, units, orientations, joints, defaults, equalities, errors, robustness.

use nalgebra::{Isometry3, Matrix3, Point3, UnitQuaternion, Vector3};
use smocap::io::mjcf::{parse_mjcf, parse_mjcf_with_warnings, read_mjcf, MjcfError};
use smocap::model::{CoordinateKind, Function, Model, MotionKind};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_6, PI};

const EPS: f64 = 1e-12;

fn parse(xml: &str) -> Model {
    match parse_mjcf(xml, "test.xml") {
        Ok(m) => m,
        Err(e) => panic!("parse failed: {e}"),
    }
}

fn parse_err(xml: &str) -> MjcfError {
    match parse_mjcf(xml, "test.xml") {
        Ok(_) => panic!("expected an error"),
        Err(e) => e,
    }
}

/// World pose of body `b` at unit scale: `Π parent_offset · motions · child_offset⁻¹` down the chain.
fn body_pose(m: &Model, q: &[f64], b: usize) -> Isometry3<f64> {
    let mut x = Isometry3::identity();
    for &i in m.chain(b) {
        let j = &m.bodies[i].joint;
        let mut t = j.parent_offset;
        for mo in &m.motions[j.motions.clone()] {
            let amount = mo.func.eval(mo.coordinate.map_or(0.0, |c| q[c])).0;
            t *= match mo.kind {
                MotionKind::Rotation => Isometry3::rotation(mo.axis * amount),
                MotionKind::Translation => {
                    Isometry3::translation(mo.axis.x * amount, mo.axis.y * amount, mo.axis.z * amount)
                }
            };
        }
        x = x * t * j.child_offset.inverse();
    }
    x
}

fn body_rotation(xml_body_attrs: &str, compiler: &str) -> Matrix3<f64> {
    let xml = format!("<mujoco>{compiler}<worldbody><body name='b' {xml_body_attrs}/></worldbody></mujoco>");
    parse(&xml).bodies[0].joint.parent_offset.rotation.to_rotation_matrix().into_inner()
}

fn assert_mat(a: Matrix3<f64>, b: Matrix3<f64>) {
    assert!((a - b).abs().max() < 1e-9, "{a} != {b}");
}

fn assert_vec(a: Vector3<f64>, b: Vector3<f64>) {
    assert!((a - b).norm() < 1e-9, "{a} != {b}");
}

#[test]
fn nested_bodies_get_document_order_and_parent_indices() {
    let m = parse(
        "<mujoco model='tree'><worldbody>
           <body name='a'><body name='b'><body name='c'/></body><body name='d'/></body>
           <body name='e'/>
         </worldbody></mujoco>",
    );
    assert_eq!(m.name, "tree");
    let names: Vec<_> = m.bodies.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(names, ["a", "b", "c", "d", "e"]);
    let parents: Vec<_> = m.bodies.iter().map(|b| b.parent).collect();
    assert_eq!(parents, [None, Some(0), Some(1), Some(0), None]);
    // Welded bodies: no motions, joint named after the body.
    assert_eq!(m.bodies[2].joint.name, "c");
    assert!(m.motions.is_empty());
}

#[test]
fn body_pos_places_children_in_parent_frame() {
    let m = parse("<mujoco><worldbody><body name='a' pos='1 0 0' euler='0 0 90'><body name='b' pos='2 0 0'/></body></worldbody></mujoco>");
    let p = body_pose(&m, &m.default_state(), 1).translation.vector;
    assert_vec(p, Vector3::new(1.0, 2.0, 0.0));
}

#[test]
fn hinge_range_and_ref_use_compiler_angle_unit() {
    let body = "<worldbody><body name='b'><joint name='h' range='-90 45' ref='30'/></body></worldbody>";
    let deg = parse(&format!("<mujoco>{body}</mujoco>"));
    let c = &deg.coordinates[0];
    assert_eq!(c.kind, CoordinateKind::Rotational);
    assert!((c.range.0 + FRAC_PI_2).abs() < EPS && (c.range.1 - PI / 4.0).abs() < EPS);
    assert!((c.default - FRAC_PI_6).abs() < EPS);
    assert!(c.clamped && !c.locked);
    let rad = parse(&format!("<mujoco><compiler angle='radian'/>{body}</mujoco>"));
    assert_eq!(rad.coordinates[0].range, (-90.0, 45.0));
    assert_eq!(rad.coordinates[0].default, 30.0);
}

#[test]
fn hinge_motion_is_q_minus_ref_about_axis() {
    let m =
        parse("<mujoco><worldbody><body name='b'><joint name='h' axis='0 2 0' ref='30'/></body></worldbody></mujoco>");
    assert_eq!(m.motions.len(), 1);
    assert_eq!(m.motions[0].kind, MotionKind::Rotation);
    assert_vec(m.motions[0].axis, Vector3::y());
    match m.motions[0].func {
        Function::Linear { slope, intercept } => {
            assert!(slope == 1.0 && (intercept + FRAC_PI_6).abs() < EPS)
        }
        ref f => panic!("unexpected {f:?}"),
    }
    // At q = ref the body sits in its modelled pose; unlimited without a range.
    assert!(body_pose(&m, &m.default_state(), 0).rotation.angle() < EPS);
    assert!(!m.coordinates[0].clamped && m.coordinates[0].range.0 == f64::NEG_INFINITY);
}

#[test]
fn limited_flags_and_autolimits() {
    let j = "<joint name='a' range='0 1'/><joint name='b' range='0 1' limited='false'/><joint name='c' range='0 1' limited='true'/>";
    let on = parse(&format!("<mujoco><worldbody><body name='b'>{j}</body></worldbody></mujoco>"));
    let clamped: Vec<_> = on.coordinates.iter().map(|c| c.clamped).collect();
    assert_eq!(clamped, [true, false, true]);
    // Without autolimits a range needs an explicit `limited`, as in MuJoCo.
    let off = |j: &str| {
        parse_mjcf(
            &format!(
                "<mujoco><compiler autolimits='false'/><worldbody><body name='b'>\n{j}</body></worldbody></mujoco>"
            ),
            "t.xml",
        )
    };
    let e = off(j).expect_err("range without limited");
    assert!(e.to_string().contains("not 'limited'") && e.line() == Some(2), "{e}");
    let m = off(&j.replace("<joint name='a' range='0 1'/>", "<joint name='a'/>")).expect("parses");
    let clamped: Vec<_> = m.coordinates.iter().map(|c| c.clamped).collect();
    assert_eq!(clamped, [false, false, true]);
}

#[test]
fn slide_joint_translates_in_metres() {
    let m = parse("<mujoco><worldbody><body name='b' pos='0 0 1'><joint name='s' type='slide' axis='1 0 0' range='-0.5 0.5' ref='0.1'/></body></worldbody></mujoco>");
    let c = &m.coordinates[0];
    assert_eq!((c.kind, c.range, c.default), (CoordinateKind::Translational, (-0.5, 0.5), 0.1));
    assert_eq!(m.motions[0].kind, MotionKind::Translation);
    let p = body_pose(&m, &[0.4], 0).translation.vector;
    assert_vec(p, Vector3::new(0.3, 0.0, 1.0));
}

#[test]
fn quat_is_normalised_w_first() {
    let r = body_rotation("quat='2 2 0 0'", "");
    assert_mat(r, Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)); // 90° about x
}

#[test]
fn euler_lowercase_is_intrinsic_uppercase_extrinsic() {
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
    let ry = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
    // Rotating axes: R = Rx · Ry; fixed axes: R = Ry · Rx.
    assert_mat(body_rotation("euler='90 90 0'", ""), Matrix3::new(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0));
    assert_mat(body_rotation("euler='90 90 0'", ""), rx * ry);
    assert_mat(body_rotation("euler='90 90 0'", "<compiler eulerseq='XYZ'/>"), ry * rx);
    assert_mat(
        body_rotation("euler='1.5707963267948966 0 0'", "<compiler angle='radian' eulerseq='zyx'/>"),
        Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
    );
}

#[test]
fn axisangle_xyaxes_and_zaxis() {
    let rz90 = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    assert_mat(body_rotation("axisangle='0 0 3 90'", ""), rz90);
    assert_mat(body_rotation("axisangle='0 0 1 1.5707963267948966'", "<compiler angle='radian'/>"), rz90);
    // x axis → (0 1 0), y axis (made orthogonal to x) → (−1 0 0).
    assert_mat(body_rotation("xyaxes='0 1 0 -1 1 0'", ""), rz90);
    // +z onto +x: 90° about y.
    assert_mat(body_rotation("zaxis='2 0 0'", ""), Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0));
    // +z onto −z: 180° about x.
    assert_mat(body_rotation("zaxis='0 0 -1'", ""), Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0));
}

#[test]
fn ball_expands_to_three_rotations() {
    let m = parse(
        "<mujoco><worldbody><body name='b'><joint name='sh' type='ball' range='0 60'/></body></worldbody></mujoco>",
    );
    let names: Vec<_> = m.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["sh_x", "sh_y", "sh_z"]);
    let axes: Vec<_> = m.motions.iter().map(|mo| (mo.kind, mo.axis)).collect();
    assert_eq!(
        axes,
        [
            (MotionKind::Rotation, Vector3::x()),
            (MotionKind::Rotation, Vector3::y()),
            (MotionKind::Rotation, Vector3::z())
        ]
    );
    assert!(m.coordinates.iter().all(|c| c.clamped && (c.range.1 - PI / 3.0).abs() < EPS && c.range.0 == -c.range.1));
    assert_eq!(m.bodies[0].joint.name, "sh");
}

#[test]
fn free_joint_coordinates_are_the_body_pose() {
    let m = parse("<mujoco><worldbody><body name='pelvis' pos='1 2 3' euler='10 20 30'><joint name='root' type='free'/></body></worldbody></mujoco>");
    let names: Vec<_> = m.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["root_tx", "root_ty", "root_tz", "root_rz", "root_ry", "root_rx"]);
    let kinds: Vec<_> = m.motions.iter().map(|mo| (mo.kind, mo.axis)).collect();
    use MotionKind::*;
    assert_eq!(
        kinds,
        [
            (Translation, Vector3::x()),
            (Translation, Vector3::y()),
            (Translation, Vector3::z()),
            (Rotation, Vector3::z()),
            (Rotation, Vector3::y()),
            (Rotation, Vector3::x())
        ]
    );
    let pose = body_pose(&m, &m.default_state(), 0);
    let d = PI / 180.0;
    let expected = UnitQuaternion::from_euler_angles(10.0 * d, 0.0, 0.0)
        * UnitQuaternion::from_euler_angles(0.0, 20.0 * d, 0.0)
        * UnitQuaternion::from_euler_angles(0.0, 0.0, 30.0 * d);
    assert!(pose.rotation.angle_to(&expected) < 1e-9);
    assert_vec(pose.translation.vector, Vector3::new(1.0, 2.0, 3.0));
    assert!(m.coordinates.iter().all(|c| !c.clamped));
    // <freejoint/> is the same; unnamed joints are named after their body.
    let m = parse("<mujoco><worldbody><body name='b'><freejoint/></body></worldbody></mujoco>");
    assert_eq!(m.coordinates[0].name, "b_joint0_tx");
}

#[test]
fn joint_pos_turns_the_body_about_the_anchor() {
    let xml = "<mujoco><worldbody><body name='a' pos='0 0 1'>
        <body name='b' pos='1 0 0' euler='0 0 90'>
          <joint name='h' axis='0 0 1' pos='0.5 0 0'/><site name='tip' pos='1 0 0'/>
        </body></body></worldbody></mujoco>";
    let m = parse(xml);
    let j = &m.bodies[1].joint;
    // Anchor in parent frame: (1,0,0) + Rz(90)·(0.5,0,0) = (1, 0.5, 0).
    assert_vec(j.parent_offset.translation.vector, Vector3::new(1.0, 0.5, 0.0));
    assert_vec(j.child_offset.translation.vector, Vector3::new(0.5, 0.0, 0.0));
    let tip = m.markers[0].offset;
    let world = |q: f64| body_pose(&m, &[q], 1) * Point3::from(tip);
    // Rest: body b origin at (1,0,1), its x axis along world y: tip at (1,1,1).
    assert_vec(world(0.0).coords, Vector3::new(1.0, 1.0, 1.0));
    // +90° about z through the anchor (1, 0.5, 1): tip offset (0, 0.5) → (−0.5, 0).
    assert_vec(world(FRAC_PI_2).coords, Vector3::new(0.5, 0.5, 1.0));
}

#[test]
fn differing_joint_anchors_and_mixed_free_joints_are_rejected() {
    let e = parse_err("<mujoco><worldbody><body name='b'>\n<joint name='a' pos='0 0 1'/>\n<joint name='c' axis='1 0 0'/></body></worldbody></mujoco>");
    assert_eq!(e.line(), Some(3), "{e}");
    let e = parse_err("<mujoco><worldbody><body name='b'><freejoint/><joint name='h'/></body></worldbody></mujoco>");
    assert!(e.to_string().contains("free joint"), "{e}");
}

#[test]
fn default_classes_with_childclass_and_class_override() {
    let m = parse(
        "<mujoco><compiler angle='radian'/>
          <default>
            <joint axis='1 0 0' range='-1 1'/>
            <default class='leg'>
              <joint axis='0 1 0'/><site pos='0 0 -1'/>
              <default class='knee'><joint range='0 2'/></default>
            </default>
          </default>
          <worldbody>
            <body name='a'><joint name='j0'/>
              <body name='b' childclass='leg'><joint name='j1'/>
                <body name='c'><joint name='j2' class='knee'/><joint name='j3' class='main' axis='0 0 1'/><site name='s'/></body>
              </body>
            </body>
          </worldbody></mujoco>",
    );
    let axes: Vec<_> = m.motions.iter().map(|mo| mo.axis).collect();
    assert_eq!(axes, [Vector3::x(), Vector3::y(), Vector3::y(), Vector3::z()]);
    let ranges: Vec<_> = m.coordinates.iter().map(|c| c.range).collect();
    assert_eq!(ranges, [(-1.0, 1.0), (-1.0, 1.0), (0.0, 2.0), (-1.0, 1.0)]);
    assert_eq!(m.markers[0].offset, Vector3::new(0.0, 0.0, -1.0));
    let e = parse_err("<mujoco><worldbody><body name='b'><joint class='nope'/></body></worldbody></mujoco>");
    assert!(e.to_string().contains("unknown default class 'nope'"), "{e}");
}

#[test]
fn equality_polycoef_folds_in_joint_refs() {
    let xml = "<mujoco><compiler angle='radian'/><worldbody><body name='a'>
        <joint name='j1' ref='0.3'/><joint name='j2' ref='-0.2' type='slide'/><joint name='j3' ref='0.5'/></body></worldbody>
        <equality><joint joint1='j1' joint2='j2' polycoef='0.1 2 -1 0.5 0.25'/><joint joint1='j3' polycoef='0.25'/>
        <weld body1='a'/></equality></mujoco>";
    let (m, warnings) = parse_mjcf_with_warnings(xml, "t.xml").expect("parses");
    assert_eq!(m.couplings.len(), 1);
    let c = &m.couplings[0];
    assert_eq!((c.dependent, c.independent), (0, 1));
    let coef = [0.1, 2.0, -1.0, 0.5, 0.25];
    for b in [-1.0, 0.0, 0.4, 2.0] {
        let d: f64 = b - (-0.2);
        let expected = 0.3 + coef.iter().enumerate().map(|(k, ck)| ck * d.powi(k as i32)).sum::<f64>();
        assert!((c.func.eval(b).0 - expected).abs() < 1e-12);
    }
    assert!((m.coordinates[0].default - (0.3 + 0.1)).abs() < EPS, "dependent default follows the coupling");
    let j3 = &m.coordinates[2];
    assert!(j3.locked && (j3.default - 0.75).abs() < EPS);
    assert!(warnings.iter().any(|w| w.contains("<weld>")), "{warnings:?}");
}

#[test]
fn equality_on_unknown_or_ball_joint_is_an_error() {
    let e = parse_err("<mujoco><worldbody><body name='a'><joint name='b' type='ball'/></body></worldbody><equality><joint joint1='b'/></equality></mujoco>");
    assert!(e.to_string().contains("not a hinge or slide"), "{e}");
    let e = parse_err("<mujoco><worldbody/><equality><joint joint1='zz'/></equality></mujoco>");
    assert!(e.to_string().contains("unknown joint 'zz'"), "{e}");
}

#[test]
fn sites_become_markers_on_their_body() {
    let xml = "<mujoco><worldbody><site name='w'/><body name='a'><geom size='1'/><site name='m1' pos='0.1 0.2 0.3'/><site pos='1 1 1'/>
        <body name='b'><site name='m2' fromto='0 0 0 0 0 2'/><camera/><light/><inertial mass='1' pos='0 0 0'/></body></body></worldbody></mujoco>";
    let (m, warnings) = parse_mjcf_with_warnings(xml, "t.xml").expect("parses");
    let markers: Vec<_> = m.markers.iter().map(|k| (k.name.as_str(), k.body, k.offset, k.weight)).collect();
    assert_eq!(markers, [("m1", 0, Vector3::new(0.1, 0.2, 0.3), 1.0), ("m2", 1, Vector3::new(0.0, 0.0, 1.0), 1.0)]);
    assert_eq!(warnings.len(), 1, "only the worldbody site: {warnings:?}");
}

fn err_line_col(e: &MjcfError) -> (u32, u32, &str) {
    match e {
        MjcfError::Element { line, column, element, .. } => (*line, *column, element.as_str()),
        other => panic!("unexpected {other}"),
    }
}

#[test]
fn unknown_joint_type_error_names_line_and_alternatives() {
    let e = parse_err(
        "<mujoco>\n<worldbody>\n<body name='b'>\n  <joint name='j' type='hing'/>\n</body></worldbody></mujoco>",
    );
    assert_eq!(err_line_col(&e), (4, 19, "joint"));
    let msg = e.to_string();
    assert!(msg.starts_with("test.xml:4:19:") && msg.contains("expected one of hinge, slide, ball, free"), "{msg}");
}

#[test]
fn malformed_numbers_are_reported_with_line() {
    let e = parse_err("<mujoco><worldbody>\n<body name='b' pos='1 2'/></worldbody></mujoco>");
    assert_eq!(err_line_col(&e).0, 2);
    assert!(e.to_string().contains("expected 3 finite numbers"), "{e}");
    let e = parse_err("<mujoco><worldbody><body name='b'>\n\n<joint range='0 x'/></body></worldbody></mujoco>");
    assert_eq!(err_line_col(&e), (3, 8, "joint"));
}

#[test]
fn two_orientation_attributes_are_rejected() {
    let e = parse_err("<mujoco><worldbody>\n\n<body name='b' quat='1 0 0 0' euler='0 0 0'/></worldbody></mujoco>");
    assert_eq!(err_line_col(&e).0, 3);
    assert!(e.to_string().contains("'quat' and 'euler'"), "{e}");
}

#[test]
fn unsupported_elements_are_rejected_by_name() {
    for (tag, line) in
        [("include file='x.xml'", 2), ("frame", 3), ("replicate count='2'", 3), ("composite", 3), ("attach", 3)]
    {
        let inner = format!("<{tag}/>");
        let xml = if line == 2 {
            format!("<mujoco>\n{inner}<worldbody/></mujoco>")
        } else {
            format!("<mujoco>\n<worldbody>\n<body name='b'>{inner}</body></worldbody></mujoco>")
        };
        let e = parse_err(&xml);
        let name = tag.split(' ').next().unwrap_or(tag);
        assert_eq!(err_line_col(&e), (line, if line == 2 { 1 } else { 16 }, name), "{e}");
    }
}

#[test]
fn other_structural_errors() {
    for (xml, needle) in [
        ("<robot/>", "<mujoco>"),
        ("<mujoco><worldbody><joint/></worldbody></mujoco>", "worldbody"),
        ("<mujoco><compiler angle='grad'/></mujoco>", "one of degree, radian"),
        ("<mujoco><compiler eulerseq='xy'/></mujoco>", "eulerseq"),
        ("<mujoco><worldbody><body name='b'><joint limited='true'/></body></worldbody></mujoco>", "range"),
        ("<mujoco><worldbody><body name='b'><joint axis='0 0 0'/></body></worldbody></mujoco>", "axis"),
        ("<mujoco><worldbody><body name='b' quat='0 0 0 0'/></worldbody></mujoco>", "quat"),
        ("<mujoco><worldbody><body name='b'/><body name='b'/></worldbody></mujoco>", "duplicate body"),
        ("<mujoco><worldbody><body name='b'><joint name='j' type='ball'/><joint name='j'/></body></worldbody></mujoco>", "duplicate joint"),
        ("<mujoco><default><joint/><default/></default></mujoco>", "needs a 'class'"),
        ("<mujoco><default><default class='a'/><default class='a'/></default></mujoco>", "duplicate default class"),
        ("<mujoco><worldbody><body name='b'><geom><body name='c'/></geom></body></worldbody></mujoco>", "child of"),
        ("<mujoco><worldbody><body", "malformed XML"),
    ] {
        let e = parse_err(xml);
        assert!(e.to_string().contains(needle), "{xml}: {e}");
        assert!(e.line().is_some());
    }
}

#[test]
fn read_mjcf_reads_files_and_reports_missing_ones() {
    let dir = std::env::temp_dir().join(format!("smocap_mjcf_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("arm.xml");
    std::fs::write(&path, "<mujoco><worldbody><body name='b'><joint name='h'/></body></worldbody></mujoco>")
        .expect("write");
    let (m, warnings) = read_mjcf(&path).expect("reads");
    assert_eq!((m.name.as_str(), m.nq(), warnings.len()), ("arm", 1, 0));
    let missing = dir.join("missing.xml");
    let e = read_mjcf(&missing).expect_err("missing file fails");
    assert!(matches!(e, MjcfError::Io { .. }) && e.to_string().contains("missing.xml"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn byte_mutations_never_panic() {
    let base = "<mujoco model='m'><compiler angle='degree' eulerseq='zyx' autolimits='true'/>
      <default><joint axis='0 1 0' range='-10 10'/><default class='c'><site pos='0 0 1'/></default></default>
      <worldbody><site name='w'/><body name='a' pos='0 0 1' euler='10 20 30' childclass='c'>
        <freejoint name='root'/><site name='s1'/>
        <body name='b' xyaxes='1 0 0 0 1 0'><joint name='h' pos='0 0 0.1' ref='5'/><joint name='ball' type='ball' pos='0 0 0.1' range='0 30'/>
          <body name='c' zaxis='0 1 0'><joint name='s' type='slide' range='0 1'/><site name='s2' fromto='0 0 0 1 1 1'/></body>
        </body></body></worldbody>
      <equality><joint joint1='h' joint2='s' polycoef='0 1 0.5'/><connect body1='a' body2='b' anchor='0 0 0'/></equality></mujoco>";
    assert!(parse_mjcf(base, "base.xml").is_ok());
    let alphabet = b"<>/='\" 0123456789.-exyzXYZ\n\x00\xff";
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut ok = 0;
    for _ in 0..1000 {
        let mut bytes = base.as_bytes().to_vec();
        for _ in 0..1 + next() % 4 {
            let i = (next() % bytes.len() as u64) as usize;
            let c = alphabet[(next() % alphabet.len() as u64) as usize];
            match next() % 3 {
                0 => bytes[i] = c,
                1 => bytes.insert(i, c),
                _ => {
                    bytes.remove(i);
                }
            }
        }
        let text = String::from_utf8_lossy(&bytes);
        ok += usize::from(parse_mjcf_with_warnings(&text, "fuzz.xml").is_ok());
    }
    assert!(ok > 0 && ok < 1000, "mutations reach both outcomes: {ok} parsed");
}

#[test]
fn shipped_fullbody_model_imports_with_documented_counts() {
    let xml = include_str!("../models/fullbody.xml");
    let (m, warnings) = parse_mjcf_with_warnings(xml, "models/fullbody.xml").expect("shipped model parses");
    assert_eq!((m.name.as_str(), m.nb(), m.nq(), m.markers.len()), ("fullbody", 26, 55, 53));
    assert!(warnings.is_empty(), "{warnings:?}");
    let pelvis = m.coordinates.iter().find(|c| c.name == "pelvis_tz").expect("pelvis_tz");
    assert!(!pelvis.clamped && pelvis.kind == CoordinateKind::Translational);
}

#[test]
fn colliding_geoms_are_read_and_the_shipped_models_give_no_warning() {
    let xml = "<mujoco><default><default class='c'><geom type='capsule' size='0.02'/></default></default>\
        <worldbody><body name='a'><geom class='c' fromto='0 0 0 0 0 -0.3'/><geom type='sphere' size='0.05' pos='0 0 0.1'/>\
        <geom type='capsule' size='0.01 0.2' euler='90 0 0'/><geom type='box' size='1 1 1'/>\
        <geom type='sphere' size='1' contype='0' conaffinity='0'/><geom type='capsule'/></body></worldbody>\
        <contact><exclude body1='a' body2='a'/></contact></mujoco>";
    let d = smocap::io::mjcf::parse_mjcf_document(xml, "t.xml").unwrap();
    use smocap::io::mjcf::GeomShape;
    assert_eq!(d.geoms.len(), 5, "the non-colliding sphere is left out");
    assert!(matches!(d.geoms[0].shape, GeomShape::Capsule { radius, .. } if radius == 0.02));
    assert!(matches!(d.geoms[1].shape, GeomShape::Sphere { radius, .. } if radius == 0.05));
    // euler 90° about x turns the capsule's z axis onto −y: ends at ∓0.2 along y.
    let GeomShape::Capsule { a, b, .. } = &d.geoms[2].shape else { panic!() };
    assert!((a.y - 0.2).abs() < 1e-12 && (b.y + 0.2).abs() < 1e-12, "{a:?} {b:?}");
    assert_eq!(d.geoms[3].shape, GeomShape::Other("box".into()));
    assert!(matches!(&d.geoms[4].shape, GeomShape::Other(s) if s.contains("without a usable size")));
    assert_eq!(d.excludes, vec![("a".to_string(), "a".to_string())]);
    assert_eq!(d.warnings.len(), 1, "{:?}", d.warnings);
    for model in ["models/fullbody.xml", "models/dog.xml"] {
        let (_, w) = read_mjcf(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(model)).unwrap();
        assert!(w.is_empty(), "{model}: {w:?}");
    }
}
