//! Unit tests of the converter's entry points (`convert_urdf_str` on small URDFs).

use super::*;

/// A URDF chain of `n` revolute joints (n + 1 links), one element per line.
pub(crate) fn chain_urdf(n: usize) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n<robot name=\"chain\">\n");
    for i in 0..=n {
        out.push_str(&format!(
            "  <link name=\"l{i}\"><inertial><mass value=\"0.1\"/><inertia ixx=\"1e-4\" iyy=\"1e-4\" \
                 izz=\"1e-4\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial><visual><geometry><box size=\"0.01 0.01 \
                 0.01\"/></geometry></visual></link>\n"
        ));
    }
    for i in 0..n {
        out.push_str(&format!(
            "  <joint name=\"j{i}\" type=\"revolute\"><parent link=\"l{i}\"/><child link=\"l{}\"/><origin \
                 xyz=\"0 0 0.01\"/><axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" \
                 velocity=\"1\"/></joint>\n",
            i + 1
        ));
    }
    out + "</robot>\n"
}

/// Issue 15: a MuJoCo error at a line of the generated MJCF (which the user never sees) is
/// reported at the URDF element that line was written for.
#[test]
fn mujoco_errors_at_a_generated_line_point_at_the_urdf_element() {
    let text = chain_urdf(3);
    let path = Path::new("chain.urdf");
    let doc = urdf::parse(path, &text).unwrap();
    let robot = ir::parse_robot(&Ctx { path, doc: &doc }).unwrap();
    let tree = Tree::build(&robot).unwrap();
    let opts = ConvertOptions::default();
    let mut conv = Converter::new(&robot, &tree, &opts).unwrap();
    conv.prepare().unwrap();
    let mjcf = conv.emit(0.0, true, None, None).unwrap();
    let k = mjcf.lines().position(|l| l.contains("name=\"l2_visual_0\"")).unwrap() + 1;
    // MuJoCo's schema errors end with the element and the generated line.
    let message = format!("XML Error: Schema violation: unrecognized attribute: 'x'\n\nElement 'geom', line {k}");
    match conv.translate(&mjcf, message) {
        Error::Urdf { path, line, name, message, .. } => {
            assert_eq!(path, Path::new("chain.urdf"));
            assert_eq!(name.as_deref(), Some("l2"));
            assert_eq!(line, 5, "the line of <link name=\"l2\"> in the URDF");
            assert!(message.contains("l2_visual_0") && message.contains("unrecognized attribute"), "{message}");
        }
        other => panic!("not translated: {other}"),
    }
    // A line before any URDF element is explained with the way to see the generated file.
    match conv.translate(&mjcf, "XML Error: bad option\n\nElement 'option', line 4".into()) {
        Error::Load { message, .. } => {
            assert!(message.contains("line 4 of the MJCF") && message.contains("twin convert"), "{message}")
        }
        other => panic!("{other}"),
    }
}

#[test]
fn topics_resolve_like_gazebo_ros() {
    let doc = roxmltree::Document::parse(
            "<sensor><plugin name=\"imu_plugin\"><ros><namespace>/humanoid</namespace><remapping>~/out:=imu/data</remapping></ros></plugin></sensor>",
        )
        .unwrap();
    assert_eq!(ir::resolve_topic(doc.root_element()).as_deref(), Some("/humanoid/imu/data"));
    let doc = roxmltree::Document::parse(
        "<sensor><plugin name=\"p\"><ros><namespace>robot</namespace></ros></plugin></sensor>",
    )
    .unwrap();
    assert_eq!(ir::resolve_topic(doc.root_element()).as_deref(), Some("/robot/p/out"));
    let doc = roxmltree::Document::parse(
        "<sensor><plugin name=\"p\"><robotNamespace>r1</robotNamespace><topicName>imu</topicName></plugin></sensor>",
    )
    .unwrap();
    assert_eq!(ir::resolve_topic(doc.root_element()).as_deref(), Some("/r1/imu"));
}
