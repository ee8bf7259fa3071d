//! ros2msg schema texts of the message types the project writes, in the form rosbag2 stores them:
//! the type's own definition followed by each dependency after a `====` separator line and an
//! `MSG: package/Type` line.

const SEP: &str =
    "================================================================================\n";

const TIME: &str = include_str!("msg/Time.msg");
const HEADER: &str = include_str!("msg/Header.msg");
const IMAGE: &str = include_str!("msg/Image.msg");
const COMPRESSED: &str = include_str!("msg/CompressedImage.msg");
const CLOUD: &str = include_str!("msg/PointCloud2.msg");
const FIELD: &str = include_str!("msg/PointField.msg");
const STRING: &str = include_str!("msg/String.msg");

fn with_deps(main: &str, deps: &[(&str, &str)]) -> String {
    let mut s = main.to_string();
    for (name, text) in deps {
        s.push_str(SEP);
        s.push_str("MSG: ");
        s.push_str(name);
        s.push('\n');
        s.push_str(text);
    }
    s
}

/// The full ros2msg schema text of `type_name` (`sensor_msgs/msg/Image`, ...), if the project
/// knows it.
pub fn ros2msg(type_name: &str) -> Option<String> {
    let header_deps = [
        ("std_msgs/Header", HEADER),
        ("builtin_interfaces/Time", TIME),
    ];
    Some(match type_name {
        "sensor_msgs/msg/Image" => with_deps(IMAGE, &header_deps),
        "sensor_msgs/msg/CompressedImage" => with_deps(COMPRESSED, &header_deps),
        "sensor_msgs/msg/PointCloud2" => with_deps(
            CLOUD,
            &[
                header_deps[0],
                header_deps[1],
                ("sensor_msgs/PointField", FIELD),
            ],
        ),
        "std_msgs/msg/String" => STRING.to_string(),
        _ => return None,
    })
}

/// Type names with a known schema.
pub const KNOWN_TYPES: [&str; 4] = [
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/PointCloud2",
    "std_msgs/msg/String",
];

/// The `offered_qos_profiles` YAML rosbag2 writes for a sensor-data publisher (best effort, keep
/// last 5, volatile), so `ros2 bag play` republishes with the QoS the sensors use.
pub const SENSOR_QOS_YAML: &str = "- history: 1\n  depth: 5\n  reliability: 2\n  durability: 2\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false\n";
