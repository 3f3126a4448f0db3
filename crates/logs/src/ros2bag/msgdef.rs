//! The `.msg` text of every ROS 2 type a lightpose bag carries, and the
//! complete definition of a type in the `ros2msg` form `ros2 bag record`
//! writes into an MCAP schema (rosbag2's docs/message_definition_encoding.md):
//! the type's own text first, then each type it uses, directly or not,
//! after a line of 80 `=` and a line `MSG: package/msg/Name`. Readers
//! without the ROS messages installed (rosbags, Foxglove) build their
//! deserializers from this text, so it is the `.msg` files of ROS 2 (Jazzy)
//! field for field, default values included; comments are left out.

use crate::ros2msg::TypeName;

/// One `.msg` file: its package resource name, its text, and the types its
/// fields name (resource names).
struct Def {
    name: &'static str,
    text: &'static str,
    uses: &'static [&'static str],
}

const TIME: &str = "builtin_interfaces/msg/Time";
const HEADER: &str = "std_msgs/msg/Header";
const POINT: &str = "geometry_msgs/msg/Point";
const QUATERNION: &str = "geometry_msgs/msg/Quaternion";
const VECTOR3: &str = "geometry_msgs/msg/Vector3";
const POSE: &str = "geometry_msgs/msg/Pose";
const POSE_COV: &str = "geometry_msgs/msg/PoseWithCovariance";
const TWIST: &str = "geometry_msgs/msg/Twist";
const TWIST_COV: &str = "geometry_msgs/msg/TwistWithCovariance";
const TRANSFORM: &str = "geometry_msgs/msg/Transform";
const TRANSFORM_STAMPED: &str = "geometry_msgs/msg/TransformStamped";
const KEY_VALUE: &str = "diagnostic_msgs/msg/KeyValue";
const DIAG_STATUS: &str = "diagnostic_msgs/msg/DiagnosticStatus";

const DEFS: &[Def] = &[
    Def {
        name: TIME,
        text: "int32 sec\nuint32 nanosec\n",
        uses: &[],
    },
    Def {
        name: HEADER,
        text: "builtin_interfaces/Time stamp\nstring frame_id\n",
        uses: &[TIME],
    },
    Def {
        name: POINT,
        text: "float64 x\nfloat64 y\nfloat64 z\n",
        uses: &[],
    },
    Def {
        name: QUATERNION,
        text: "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
        uses: &[],
    },
    Def {
        name: VECTOR3,
        text: "float64 x\nfloat64 y\nfloat64 z\n",
        uses: &[],
    },
    Def {
        name: POSE,
        text: "Point position\nQuaternion orientation\n",
        uses: &[POINT, QUATERNION],
    },
    Def {
        name: POSE_COV,
        text: "Pose pose\nfloat64[36] covariance\n",
        uses: &[POSE],
    },
    Def {
        name: "geometry_msgs/msg/PoseWithCovarianceStamped",
        text: "std_msgs/Header header\nPoseWithCovariance pose\n",
        uses: &[HEADER, POSE_COV],
    },
    Def {
        name: TWIST,
        text: "Vector3 linear\nVector3 angular\n",
        uses: &[VECTOR3],
    },
    Def {
        name: TWIST_COV,
        text: "Twist twist\nfloat64[36] covariance\n",
        uses: &[TWIST],
    },
    Def {
        name: "nav_msgs/msg/Odometry",
        text: "std_msgs/Header header\nstring child_frame_id\n\
               geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
        uses: &[HEADER, POSE_COV, TWIST_COV],
    },
    Def {
        name: TRANSFORM,
        text: "Vector3 translation\nQuaternion rotation\n",
        uses: &[VECTOR3, QUATERNION],
    },
    Def {
        name: TRANSFORM_STAMPED,
        text: "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
        uses: &[HEADER, TRANSFORM],
    },
    Def {
        name: "tf2_msgs/msg/TFMessage",
        text: "geometry_msgs/TransformStamped[] transforms\n",
        uses: &[TRANSFORM_STAMPED],
    },
    Def {
        name: KEY_VALUE,
        text: "string key\nstring value\n",
        uses: &[],
    },
    Def {
        name: DIAG_STATUS,
        text: "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n\
               byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n",
        uses: &[KEY_VALUE],
    },
    Def {
        name: "diagnostic_msgs/msg/DiagnosticArray",
        text: "std_msgs/Header header\nDiagnosticStatus[] status\n",
        uses: &[HEADER, DIAG_STATUS],
    },
];

fn def(name: &str) -> Option<&'static Def> {
    DEFS.iter().find(|d| d.name == name)
}

/// The complete `ros2msg` definition of `t`, or `None` for a type this
/// table does not hold.
pub fn definition(t: &TypeName) -> Option<String> {
    let top = def(&t.ros())?;
    let mut text = top.text.to_string();
    // Each dependency once, in the order they are first met (depth first).
    let mut seen: Vec<&str> = vec![top.name];
    let mut stack: Vec<&str> = top.uses.iter().rev().copied().collect();
    while let Some(name) = stack.pop() {
        if seen.contains(&name) {
            continue;
        }
        seen.push(name);
        let d = def(name)?;
        text.push_str(&"=".repeat(80));
        text.push_str("\nMSG: ");
        text.push_str(d.name);
        text.push('\n');
        text.push_str(d.text);
        stack.extend(d.uses.iter().rev().copied());
    }
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros2msg::{DIAG_TYPE, ODOM_TYPE, POSE_TYPE, TF_TYPE};

    #[test]
    fn every_dependency_is_defined_once() {
        for t in [POSE_TYPE, ODOM_TYPE, TF_TYPE, DIAG_TYPE] {
            let text = definition(&t).expect("defined");
            let sections: Vec<&str> = text.split(&"=".repeat(80)).collect();
            // Every field type named is either primitive or has a section.
            let names: Vec<&str> = sections[1..]
                .iter()
                .map(|s| {
                    s.trim_start()
                        .lines()
                        .next()
                        .unwrap()
                        .trim_start_matches("MSG: ")
                })
                .collect();
            let mut unique = names.clone();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(names.len(), unique.len(), "{text}");
            assert!(names.contains(&HEADER), "{}: {names:?}", t.ros());
        }
        let tf = definition(&TF_TYPE).unwrap();
        for dep in [
            TRANSFORM_STAMPED,
            HEADER,
            TIME,
            TRANSFORM,
            VECTOR3,
            QUATERNION,
        ] {
            assert!(tf.contains(&format!("MSG: {dep}\n")), "{dep} in {tf}");
        }
        assert!(tf.starts_with("geometry_msgs/TransformStamped[] transforms\n"));
    }
}
