//! Converting a 60-link humanoid URDF (primitive geometry, no meshes) to MJCF: the converter
//! itself, and the converter plus MuJoCo compiling the result. Target: < 100 ms.
//!
//! `cargo bench --bench convert`

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;
use twin_core::convert::{ConvertOptions, convert_urdf_str};
use twin_core::mj::Model;

/// A humanoid-shaped tree: a pelvis and six chains (2 legs, 2 arms, spine + head, 2 hands)
/// of revolute joints, 60 links in all, with transmissions, foot friction and an IMU.
fn humanoid_urdf(links: usize) -> String {
    let mut s = String::from("<robot name=\"bench\">\n");
    let link = |s: &mut String, name: &str, mass: f64| {
        let _ = writeln!(
            s,
            "<link name=\"{name}\"><inertial><origin xyz=\"0 0 -0.05\" rpy=\"0.1 0 0\"/><mass value=\"{mass}\"/>\
             <inertia ixx=\"0.002\" ixy=\"0.0001\" ixz=\"0\" iyy=\"0.002\" iyz=\"0\" izz=\"0.001\"/></inertial>\
             <visual><origin xyz=\"0 0 -0.05\"/><geometry><cylinder radius=\"0.03\" length=\"0.1\"/></geometry></visual>\
             <collision><origin xyz=\"0 0 -0.05\"/><geometry><box size=\"0.05 0.05 0.1\"/></geometry></collision></link>"
        );
    };
    link(&mut s, "pelvis", 5.0);
    let per_chain = (links - 1) / 6;
    let axes = ["1 0 0", "0 1 0", "0 0 1"];
    let mut n = 1;
    for c in 0..6 {
        let mut parent = "pelvis".to_string();
        for k in 0..per_chain {
            let name = format!("c{c}_l{k}");
            link(&mut s, &name, 0.5);
            let _ = writeln!(
                s,
                "<joint name=\"{name}_joint\" type=\"revolute\"><origin xyz=\"0 {} -0.1\"/><parent link=\"{parent}\"/>\
                 <child link=\"{name}\"/><axis xyz=\"{}\"/><limit lower=\"-1\" upper=\"1\" effort=\"50\" velocity=\"10\"/>\
                 <dynamics damping=\"0.5\" friction=\"0.1\"/></joint>\
                 <transmission name=\"{name}_t\"><type>transmission_interface/SimpleTransmission</type>\
                 <joint name=\"{name}_joint\"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>\
                 <actuator name=\"{name}_m\"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>",
                if k == 0 { 0.05 * c as f64 - 0.125 } else { 0.0 },
                axes[k % 3]
            );
            parent = name;
            n += 1;
        }
        let _ = writeln!(s, "<gazebo reference=\"{parent}\"><mu1>0.9</mu1><mu2>0.9</mu2></gazebo>");
    }
    let _ = writeln!(
        s,
        "<gazebo reference=\"pelvis\"><sensor name=\"imu\" type=\"imu\"><update_rate>200</update_rate>\
         <plugin name=\"p\" filename=\"libgazebo_ros_imu_sensor.so\"><ros><namespace>/bench</namespace>\
         <remapping>~/out:=imu/data</remapping></ros></plugin></sensor></gazebo>\n</robot>"
    );
    assert_eq!(n, links - ((links - 1) % 6));
    s
}

fn main() {
    let urdf = humanoid_urdf(61);
    let nlinks = urdf.matches("<link ").count();
    let opts = ConvertOptions::default();
    let path = Path::new("bench.urdf");
    // Warm up (MuJoCo init, allocator).
    let converted = convert_urdf_str(path, &urdf, &opts).expect("convert");
    let model = Model::from_xml_str(&converted.mjcf).expect("compile");
    let mut convert_ms = Vec::new();
    let mut total_ms = Vec::new();
    for _ in 0..30 {
        let t = Instant::now();
        let c = convert_urdf_str(path, &urdf, &opts).expect("convert");
        convert_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let m = Model::from_xml_str(&c.mjcf).expect("compile");
        total_ms.push(t.elapsed().as_secs_f64() * 1e3);
        assert_eq!(m.nbody(), model.nbody());
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (c, t) = (median(&mut convert_ms), median(&mut total_ms));
    println!("convert: {nlinks} links, {} joints, {} actuators, {} sensors", model.njnt(), model.nu(), model.nsensor());
    println!("convert_urdf (incl. its 2 MuJoCo compiles for placement and home pose): median {c:.2} ms");
    println!("convert_urdf + compiling the result: median {t:.2} ms (target < 100 ms)");
}
