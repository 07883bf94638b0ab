//! The MJCF reader: a Menagerie-style hand is read with MuJoCo's semantics, and everything
//! outside the subset is refused with its element and line.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::f64::consts::FRAC_PI_2;

use nalgebra::Vector3;
use vge_hand::{GeomMass, GeomShape, Hand, HandError};

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

/// A one-finger hand with `extra` inside the finger's distal body and `after` after the
/// worldbody; fingertip site `fingertip`.
fn finger(extra: &str, after: &str) -> String {
    format!(
        r#"<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="palm">
      <body name="prox" pos="0 0 -0.01">
        <joint name="j0" axis="0 1 0" range="-1 1"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.05" size="0.01"/>
        <body name="dist" pos="0 0 -0.05">
          <joint name="j1" axis="0 1 0" range="-1 1"/>
          <site name="fingertip" pos="0 0 -0.04"/>
{extra}
        </body>
      </body>
    </body>
  </worldbody>
{after}
</mujoco>
"#
    )
}

/// The 1-based line of the first line of `xml` containing `marker`.
fn line_of(xml: &str, marker: &str) -> usize {
    xml.lines().position(|l| l.contains(marker)).expect("marker in the XML") + 1
}

/// Reads `xml` (no TOML), expects a refusal, and checks it names the element at the marker's
/// line and contains every one of `words`.
fn refused(xml: &str, marker: &str, element: &str, words: &[&str]) -> String {
    let err = Hand::from_strs(xml, None, "t").expect_err("refused");
    let message = err.to_string();
    let at = format!("t.xml:{}: <{element}>", line_of(xml, marker));
    assert!(message.starts_with(&at), "expected `{at}` in: {message}");
    for word in words {
        assert!(message.contains(word), "expected `{word}` in: {message}");
    }
    message
}

#[test]
fn the_base_finger_loads() {
    let hand = Hand::from_strs(&finger("", ""), None, "t").unwrap();
    assert_eq!(hand.name(), "t");
    assert_eq!(hand.num_joints(), 2);
    assert_eq!(hand.fingers()[0].name, "fingertip");
    let tip = hand.fingertip_positions_m(&[0.0f64, 0.0]).unwrap();
    assert!((tip[0] - Vector3::new(0.0, 0.0, -0.1)).norm() < 1e-7);
    // Flexing j1 by a quarter turn about +y swings the 4 cm distal link to -x.
    let tip = hand.fingertip_positions_m(&[0.0, FRAC_PI_2]).unwrap();
    assert!((tip[0] - Vector3::new(-0.04, 0.0, -0.06)).norm() < 1e-7, "{}", tip[0]);
}

#[test]
fn a_tendon_is_refused_at_its_line() {
    let after = r#"  <tendon>
    <fixed name="couple">
      <joint joint="j0" coef="1"/>
    </fixed>
  </tendon>"#;
    refused(&finger("", after), "<fixed", "fixed", &["tendon", "outside vge's MJCF subset"]);
}

#[test]
fn an_equality_mimic_joint_is_refused_at_its_line() {
    let after = r#"  <equality>
    <joint name="mimic" joint1="j0" joint2="j1"/>
  </equality>"#;
    refused(&finger("", after), "joint1=", "joint", &["equality", "mimic"]);
}

#[test]
fn ball_slide_and_free_joints_are_refused_at_their_lines() {
    let ball = finger(r#"          <joint name="wobble" type="ball"/>"#, "");
    refused(&ball, "wobble", "joint", &["joint `wobble`", "`ball`"]);
    let slide = finger(r#"          <joint name="slider" type="slide"/>"#, "");
    refused(&slide, "slider", "joint", &["`slide`"]);
    let free = finger(r#"          <joint name="loose" type="free"/>"#, "");
    refused(&free, "loose", "joint", &["`free`"]);
    let freejoint = finger(r#"          <freejoint name="loose"/>"#, "");
    refused(&freejoint, "freejoint", "freejoint", &["<freejoint>"]);
}

#[test]
fn a_colliding_mesh_is_refused_and_a_visual_one_is_kept_without_opening_its_file() {
    let colliding = finger(r#"          <geom name="shell" type="mesh" mesh="no_such_file"/>"#, "");
    refused(&colliding, "shell", "geom", &["geom `shell`", "mesh that collides"]);
    let visual = finger(
        r#"          <geom name="shell" type="mesh" mesh="absent" contype="0" conaffinity="0" mass="0"/>"#,
        "",
    );
    let hand = Hand::from_strs(&visual, None, "t").unwrap();
    let dist = &hand.bodies()[hand.body_index("dist").unwrap()];
    assert!(matches!(&dist.geoms[0].shape, GeomShape::VisualMesh { mesh } if mesh == "absent"));
    assert!(!dist.geoms[0].collides());
    // Without mass="0" MuJoCo would weigh the mesh (the body has no <inertial>): refused.
    let weighed =
        finger(r#"          <geom name="shell" type="mesh" mesh="absent" contype="0" conaffinity="0"/>"#, "");
    refused(&weighed, "shell", "geom", &["mass of a mesh geom", "<inertial>"]);
}

#[test]
fn unknown_elements_and_attributes_are_refused_at_their_lines() {
    refused(&finger("          <wibble/>", ""), "wibble", "wibble", &["element <wibble>", "does not know"]);
    refused(&finger("", "  <wobble/>"), "wobble", "wobble", &["element <wobble>"]);
    let attr = finger(r#"          <geom name="g" size="0.01" springiness="3"/>"#, "");
    refused(&attr, "springiness", "geom", &["attribute `springiness` of <geom>"]);
    let stiff = finger(r#"          <joint name="sprung" axis="1 0 0" stiffness="2"/>"#, "");
    refused(&stiff, "sprung", "joint", &["`stiffness` of joint `sprung`"]);
    refused(&finger("", r#"  <include file="other.xml"/>"#), "include", "include", &["<include>"]);
    let plane = finger(r#"          <geom name="floor" type="plane" size="1 1 1"/>"#, "");
    refused(&plane, "floor", "geom", &["geom `floor` of type `plane`"]);
}

#[test]
fn actuators_other_than_position_servos_are_refused() {
    let motor = r#"  <actuator>
    <motor name="m" joint="j0"/>
  </actuator>"#;
    refused(&finger("", motor), "<motor", "motor", &["<motor> actuator"]);
    let not_servo = r#"  <actuator>
    <general name="g" joint="j0" biastype="affine" gainprm="5" biasprm="0 -4 -1"/>
  </actuator>"#;
    refused(&finger("", not_servo), "<general", "general", &["not a position servo"]);
    let servo = r#"  <actuator>
    <general name="g" joint="j1" biastype="affine" gainprm="5" biasprm="0 -5 -0.5" forcerange="-1 2"/>
    <position name="p" joint="j0" kp="7" inheritrange="0.5"/>
  </actuator>"#;
    let hand = Hand::from_strs(&finger("", servo), None, "t").unwrap();
    let g = hand.joints()[1].servo.as_ref().unwrap();
    assert_eq!((g.kp_nm_per_rad, g.kv_nms_per_rad, g.force_range_nm), (5.0, 0.5, Some([-1.0, 2.0])));
    let p = hand.joints()[0].servo.as_ref().unwrap();
    assert_eq!((p.kp_nm_per_rad, p.kv_nms_per_rad, p.ctrl_range_rad), (7.0, 0.0, Some([-0.5, 0.5])));
    let twice = r#"  <actuator>
    <position joint="j0"/>
    <position name="again" joint="j0"/>
  </actuator>"#;
    refused(&finger("", twice), "again", "position", &["second actuator"]);
}

/// A palm with a wrist joint and two fingers below it.
fn two_fingers(wrist: &str) -> String {
    format!(
        r#"<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="palm">
{wrist}
      <body name="a">
        <joint name="a0"/>
        <site name="tip_a"/>
      </body>
      <body name="b">
        <joint name="b0"/>
        <body name="b_tip" pos="0 0 -0.03"/>
      </body>
      <body name="c">
        <joint name="c0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"#
    )
}

#[test]
fn finger_paths_own_every_joint_once_in_order() {
    let toml = r#"fingertips = ["tip_a", "b_tip"]"#;
    // A wrist joint lies on both fingers' paths.
    let xml = two_fingers(r#"      <joint name="wrist"/>"#);
    let err = Hand::from_strs(&xml, Some(toml), "t").unwrap_err().to_string();
    assert!(err.starts_with(&format!("t.xml:{}: <joint>", line_of(&xml, "wrist"))), "{err}");
    assert!(err.contains("joint `wrist` is on the paths of fingers `tip_a` and `b_tip`"), "{err}");
    // Body c's joint is on no finger's path.
    let xml = two_fingers("");
    let err = Hand::from_strs(&xml, Some(toml), "t").unwrap_err().to_string();
    assert!(err.starts_with(&format!("t.xml:{}: <joint>", line_of(&xml, "c0"))), "{err}");
    assert!(err.contains("joint `c0` is on no finger's path"), "{err}");
    // With c a finger too (by body name), it loads; listed out of file order it does not.
    let hand = Hand::from_strs(&xml, Some(r#"fingertips = ["tip_a", "b_tip", "c"]"#), "t").unwrap();
    let joints: Vec<_> = hand.fingers().iter().map(|f| f.joints.clone()).collect();
    assert_eq!(joints, [0..1, 1..2, 2..3]);
    let err = Hand::from_strs(&xml, Some(r#"fingertips = ["b_tip", "tip_a", "c"]"#), "t").unwrap_err();
    assert!(err.to_string().contains("finger `tip_a` (joints 0..1) is listed after `b_tip`"), "{err}");
    // A fingertip that is neither a site nor a body.
    let err =
        Hand::from_strs(&xml, Some(r#"fingertips = ["tip_a", "b_tip", "no_such_tip"]"#), "t").unwrap_err();
    assert!(matches!(err, HandError::Spec { .. }), "{err}");
    assert!(
        err.to_string().starts_with("t.toml: fingertip `no_such_tip` is neither a site nor a body"),
        "{err}"
    );
    // An unknown TOML key is refused, not ignored.
    let err = Hand::from_strs(&xml, Some("fingertip = [\"tip_a\"]"), "t").unwrap_err();
    assert!(err.to_string().contains("unknown field `fingertip`"), "{err}");
}

#[test]
fn without_a_toml_the_fingertips_are_the_fingertip_sites_and_nothing_is_guessed() {
    let xml = finger("", "").replace("fingertip", "tip");
    let err = Hand::from_strs(&xml, None, "t").unwrap_err();
    assert!(err.to_string().contains("no fingertips"), "{err}");
}

#[test]
fn malformed_xml_autolimits_and_bad_numbers_name_their_line() {
    let xml = finger("          <geom size=\"0.01\">", "");
    let err = Hand::from_strs(&xml, None, "t").unwrap_err();
    assert!(matches!(err, HandError::Xml { .. }), "{err}");
    let xml = finger("", "").replace("angle=\"radian\"", "angle=\"radian\" autolimits=\"false\"");
    refused(&xml, "\"j0\"", "joint", &["autolimits is false"]);
    let xml = finger(r#"          <geom name="g" size="0.01 x"/>"#, "");
    refused(&xml, "name=\"g\"", "geom", &["`x` is not a finite number"]);
    let xml = finger(r#"          <geom name="g" size="0.01" quat="1 0 0 0" euler="0 0 1"/>"#, "");
    refused(&xml, "name=\"g\"", "geom", &["more than one orientation"]);
}

#[test]
fn queries_refuse_wrong_lengths_non_finite_angles_and_bad_fingers() {
    let hand = Hand::from_strs(&finger("", ""), None, "t").unwrap();
    assert!(matches!(
        hand.fingertip_positions_m(&[0.0f32]),
        Err(HandError::JointCount { expected: 2, got: 1 })
    ));
    assert!(matches!(
        hand.fingertip_jacobians(&[0.0, f64::NAN]),
        Err(HandError::NonFiniteJoint { index: 1 })
    ));
    let p = Vector3::new(0.0, f64::INFINITY, 0.0);
    assert!(matches!(
        hand.fingertip_jacobian_at_point(0, &[0.0, 0.0], &p),
        Err(HandError::NonFinitePoint { .. })
    ));
    let p = Vector3::zeros();
    assert!(matches!(
        hand.fingertip_jacobian_at_point(1, &[0.0, 0.0], &p),
        Err(HandError::FingerOutOfRange { .. })
    ));
}

#[test]
fn load_refuses_directories_pipes_and_oversized_files() {
    let dir = std::env::temp_dir().join(format!("vge-hand-test-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("sub.xml")).unwrap();
    assert!(matches!(Hand::load(dir.join("sub.xml")), Err(HandError::NotAFile { .. })));
    let big = dir.join("big.xml");
    let file = std::fs::File::create(&big).unwrap();
    file.set_len(vge_hand::MAX_FILE_BYTES + 1).unwrap();
    assert!(matches!(Hand::load(&big), Err(HandError::TooLarge { .. })));
    assert!(matches!(Hand::load(dir.join("absent.xml")), Err(HandError::Io { .. })));
    // A named pipe is refused unopened (opening it would wait for a writer), as the XML or
    // as the TOML beside it.
    let xml = dir.join("hand.xml");
    std::fs::write(&xml, finger("", "")).unwrap();
    assert!(Hand::load(&xml).is_ok());
    let made = std::process::Command::new("mkfifo").arg(dir.join("hand.toml")).status();
    if made.is_ok_and(|s| s.success()) {
        assert!(matches!(Hand::load(&xml), Err(HandError::NotAFile { path }) if path.ends_with("hand.toml")));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_menagerie_style_hand_is_read_with_mujoco_s_semantics() {
    let hand = Hand::load(format!("{FIXTURES}/menagerie_style.xml")).unwrap();
    assert_eq!(hand.name(), "two_finger");
    let names: Vec<_> = hand.joints().iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["ff_abd", "ff_flex", "th_rot", "th_flex"]);
    let fingers: Vec<_> = hand.fingers().iter().map(|f| (f.name.as_str(), f.joints.clone())).collect();
    assert_eq!(fingers, [("index", 0..2), ("thumb", 2..4)]);
    // Degrees (the compiler's default), limited by autolimits; nested classes and childclass.
    let ff_abd = &hand.joints()[0];
    let limit = ff_abd.limit.unwrap();
    assert!((f64::from(limit.upper_rad) - 30f64.to_radians()).abs() < 1e-7);
    assert_eq!((ff_abd.damping_nms_per_rad, ff_abd.armature_kg_m2), (0.1, 0.001));
    assert_eq!(ff_abd.axis_in_body.into_inner(), Vector3::z());
    let th_rot = &hand.joints()[2];
    assert_eq!((th_rot.damping_nms_per_rad, th_rot.axis_in_body.into_inner()), (0.2, Vector3::x()));
    // ctrlrange is not converted from degrees (MuJoCo leaves it as written).
    assert_eq!(ff_abd.servo.as_ref().unwrap().ctrl_range_rad, Some([-0.5, 0.5]));
    assert_eq!(hand.joints()[3].servo.as_ref().unwrap().kv_nms_per_rad, 0.03);
    // Fingertips are bodies: their origins; the tip radius is the tip sphere's.
    assert_eq!(hand.fingers()[0].tip_radius_m, Some(0.011));
    assert_eq!(hand.fingers()[0].tip_offset_in_body_m, Vector3::zeros());
    // quat="0 1 0 1" (normalised) is a half turn about (x + z): palm x -> world z, y -> -y,
    // z -> x. The index tip is 0.16 m along the palm's z at q = 0, 0.04 m along its y; a
    // quarter turn of ff_flex about +y swings its last 0.05 m from palm z to palm x.
    let tips = hand.fingertip_positions_m(&[0.0f64; 4]).unwrap();
    assert!((tips[0] - Vector3::new(0.16, -0.04, 0.0)).norm() < 1e-7, "{}", tips[0]);
    let tips = hand.fingertip_positions_m(&[0.0, FRAC_PI_2, 0.0, 0.0]).unwrap();
    assert!((tips[0] - Vector3::new(0.11, -0.04, 0.05)).norm() < 1e-7, "{}", tips[0]);
    // Visual meshes kept by name, never opened; the palm's <inertial>; masses from geoms.
    let palm = &hand.bodies()[hand.palm().unwrap()];
    assert!(matches!(&palm.geoms[0].shape, GeomShape::VisualMesh { mesh } if mesh == "palm_mesh"));
    assert_eq!(palm.inertial.unwrap().mass_kg, 0.4);
    let ff_base = &hand.bodies()[hand.body_index("ff_base").unwrap()];
    assert_eq!(ff_base.geoms[1].mass, GeomMass::DensityKgPerM3(800.0));
    assert_eq!(ff_base.geoms[1].friction, [0.9, 0.005, 0.0001]);
    let capsule =
        std::f64::consts::PI * 0.008f64.powi(2) * 0.02 + 4.0 / 3.0 * std::f64::consts::PI * 0.008f64.powi(3);
    assert!((f64::from(ff_base.mass_properties.mass_kg) - 800.0 * capsule).abs() < 1e-8);
    let excludes: Vec<_> = hand.contact_excludes().iter().map(|e| (e.body1, e.body2)).collect();
    assert_eq!(excludes, [(1, 2), (1, 5)]);
    assert_eq!(hand.start_grasp_rad(), Some(vec![0.1, 0.8, -0.2, 0.6]));
    assert_eq!(hand.physics_options().timestep_s, Some(0.005));
    // The hash covers the XML and the TOML.
    let xml = std::fs::read_to_string(format!("{FIXTURES}/menagerie_style.xml")).unwrap();
    let toml = std::fs::read_to_string(format!("{FIXTURES}/menagerie_style.toml")).unwrap();
    let same = Hand::from_strs(&xml, Some(&toml), "two_finger").unwrap();
    assert_eq!(same.description_sha256(), hand.description_sha256());
    let other = Hand::from_strs(&xml, Some(&toml.replace("\"grasp\"", "\"open\"")), "two_finger").unwrap();
    assert_ne!(other.description_sha256(), hand.description_sha256());
}

#[test]
fn jacobians_match_finite_differences_on_every_orientation_form() {
    let hand = Hand::load(format!("{FIXTURES}/orientations.xml")).unwrap();
    assert_eq!(hand.num_fingers(), 2);
    let q = [0.3, -0.5, 0.7, -0.2, 0.4];
    let jacobians = hand.fingertip_jacobians(&q).unwrap();
    let h = 1e-6;
    for j in 0..q.len() {
        let (mut plus, mut minus) = (q, q);
        plus[j] += h;
        minus[j] -= h;
        let (p, m) =
            (hand.fingertip_positions_m(&plus).unwrap(), hand.fingertip_positions_m(&minus).unwrap());
        for f in 0..2 {
            let numeric = (p[f] - m[f]) / (2.0 * h);
            assert!((jacobians[f].column(j) - numeric).norm() < 1e-6, "finger {f} joint {j}");
        }
    }
    // Finger a's columns of finger b's joints are zero.
    assert_eq!(jacobians[0].column(2).norm(), 0.0);
}
