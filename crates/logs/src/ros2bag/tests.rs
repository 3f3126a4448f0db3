use super::*;
use crate::ros2msg::{
    site_tf, solve, DiagnosticStatus, Header, KeyValue, Odometry, PoseWithCovarianceStamped,
    SiteTf, Time, DIAG_WARN,
};
use lightpose_core::{Angle, PoseEstimate, Status, StdDev};

fn solved() -> Solved<'static> {
    let mut e = PoseEstimate::empty(3, 0.6, Status::Ok, "test");
    (e.x, e.y, e.z, e.pitch_deg, e.yaw_deg, e.surge) = (
        Some(6.0),
        Some(0.4),
        Some(-0.2),
        Some(5.0),
        Some(12.0),
        Some(0.25),
    );
    e.std = StdDev {
        x: Some(0.1),
        y: Some(0.2),
        z: Some(0.05),
        pitch: Some(1.0),
        yaw: Some(2.0),
        surge: Some(0.02),
        roll: None,
    };
    solve(&e, 1_700_000_000.25).expect("ok and complete")
}

fn cdr<'a, T: serde::Deserialize<'a>>(data: &'a [u8]) -> T {
    assert_eq!(data[..4], CDR_LE_HEADER);
    cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(&data[4..])
        .expect("CDR")
        .0
}

/// Every message written comes back from the MCAP as the struct it was,
/// on its topic with its schema, encoding, QoS and log time; `/tf_static`
/// and `/diagnostics` are declared at their first message only.
#[test]
fn a_bag_holds_what_was_written() {
    let s = solved();
    let frames = Frames::default();
    let mut bag = Ros2Bag::new(Vec::new(), &Ros2BagOptions::default()).unwrap();
    let t = nanos(&s.stamp);
    bag.write_estimate(&s, t).unwrap();
    let site = site_tf(
        &frames,
        Angle::from_deg(30.0),
        [1.0, 2.0, 3.0],
        Time::default(),
    );
    bag.write_site(&site, t).unwrap();
    let diag = DiagnosticArray {
        header: Header {
            stamp: s.stamp,
            frame_id: String::new(),
        },
        status: vec![DiagnosticStatus {
            level: DIAG_WARN,
            name: "lightposed".into(),
            message: "initialising".into(),
            hardware_id: "dome".into(),
            values: vec![KeyValue {
                key: "frames".into(),
                value: "3".into(),
            }],
        }],
    };
    bag.write_diagnostics(&diag, t + 1).unwrap();
    bag.write_diagnostics(&diag, t + 2).unwrap();
    assert_eq!(bag.estimates_written(), 1);
    let bytes = bag.finish().unwrap();
    // The header record: op 1, then the profile string.
    assert_eq!(bytes[8], 0x01);
    assert_eq!(bytes[17..25], *b"\x04\x00\x00\x00ros2");

    let mut topics = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let c = &m.channel;
        let schema = c.schema.as_ref().expect("a schema");
        assert_eq!(
            (schema.encoding.as_str(), c.message_encoding.as_str()),
            ("ros2msg", "cdr")
        );
        assert!(c.metadata["offered_qos_profiles"].starts_with("- history: 1\n"));
        let qos = &c.metadata["offered_qos_profiles"];
        let want = match c.topic.as_str() {
            topic::POSE => {
                assert_eq!(cdr::<PoseWithCovarianceStamped>(&m.data), s.pose(&frames));
                "reliability: 2\n  durability: 2"
            }
            topic::ODOM => {
                assert_eq!(cdr::<Odometry>(&m.data), s.odometry(&frames));
                "reliability: 2\n  durability: 2"
            }
            topic::TF => {
                assert_eq!(cdr::<TFMessage>(&m.data), s.tf(&frames));
                "reliability: 1\n  durability: 2"
            }
            topic::TF_STATIC => {
                assert_eq!(cdr::<TFMessage>(&m.data), site);
                "reliability: 1\n  durability: 1"
            }
            topic::DIAGNOSTICS => {
                assert_eq!(cdr::<DiagnosticArray>(&m.data), diag);
                "reliability: 1\n  durability: 2"
            }
            other => panic!("topic {other}"),
        };
        assert!(qos.contains(want), "{}: {qos}", c.topic);
        let text = std::str::from_utf8(&schema.data).unwrap();
        assert!(text.contains("\nMSG: std_msgs/msg/Header\n"), "{text}");
        topics.push((c.topic.clone(), m.log_time));
    }
    assert_eq!(
        topics,
        [
            (topic::POSE.to_string(), t),
            (topic::ODOM.to_string(), t),
            (topic::TF.to_string(), t),
            (topic::TF_STATIC.to_string(), t),
            (topic::DIAGNOSTICS.to_string(), t + 1),
            (topic::DIAGNOSTICS.to_string(), t + 2),
        ]
    );
    assert_eq!(t, 1_700_000_000_250_000_000);
}

/// A bag made with the node's settings: the namespace names the pose's
/// and the odometry's topics, the frames are the configured ones, and
/// with a site `/tf_static` comes before the first pose, and again (with
/// the station's frame as its child) when the poses move to a station's
/// frame, never for each pose.
#[test]
fn a_bag_follows_the_namespace_the_frames_and_the_site() {
    let frames = Frames {
        beacon: "dock_light".into(),
        base_link: "auv1/base_link".into(),
        map: "world".into(),
    };
    let site = SiteTf {
        axis_heading: Angle::from_deg(30.0),
        ned: [1.0, 2.0, 3.0],
    };
    let opts = Ros2BagOptions {
        frames: frames.clone(),
        namespace: "/auv1/lightpose/".into(),
        site: Some(site),
        qos: TopicQos {
            pose: Qos::TransientLocal,
            depth: 5,
            ..TopicQos::default()
        },
        ..Ros2BagOptions::default()
    };
    let mut bag = Ros2Bag::new(Vec::new(), &opts).unwrap();
    let s = solved();
    let t = nanos(&s.stamp);
    bag.write_estimate(&s, t).unwrap();
    bag.write_estimate(&s, t + 10).unwrap();
    let d = Solved {
        station: Some("dock"),
        ..s
    };
    bag.write_estimate(&d, t + 20).unwrap();
    bag.write_estimate(&d, t + 30).unwrap();
    let bytes = bag.finish().unwrap();

    let mut got = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        // As offered: `[ros2.qos]`'s, /tf_static the node's own.
        let want = match m.channel.topic.as_str() {
            "/auv1/lightpose/pose" | topic::TF_STATIC => "reliability: 1\n  durability: 1",
            "/auv1/lightpose/odom" => "reliability: 2\n  durability: 2",
            _ => "reliability: 1\n  durability: 2",
        };
        let depth = if m.channel.topic == topic::TF_STATIC {
            1
        } else {
            5
        };
        let qos = &m.channel.metadata["offered_qos_profiles"];
        assert!(qos.contains(want), "{}: {qos}", m.channel.topic);
        assert!(
            qos.contains(&format!("depth: {depth}\n")),
            "{}: {qos}",
            m.channel.topic
        );
        match m.channel.topic.as_str() {
            "/auv1/lightpose/pose" => {
                let p = cdr::<PoseWithCovarianceStamped>(&m.data);
                got.push(format!("pose in {}", p.header.frame_id));
            }
            "/auv1/lightpose/odom" => {
                let o = cdr::<Odometry>(&m.data);
                assert_eq!(o.child_frame_id, "auv1/base_link");
            }
            topic::TF => {
                let tf = cdr::<TFMessage>(&m.data);
                let x = &tf.transforms[0];
                got.push(format!("tf {} -> {}", x.header.frame_id, x.child_frame_id));
            }
            topic::TF_STATIC => {
                let tf = cdr::<TFMessage>(&m.data);
                let x = &tf.transforms[0];
                // The site's transform, whichever frame it places.
                let want = site_tf(&frames, site.axis_heading, site.ned, s.stamp);
                assert_eq!(x.transform, want.transforms[0].transform);
                got.push(format!(
                    "static {} -> {}",
                    x.header.frame_id, x.child_frame_id
                ));
            }
            other => panic!("topic {other}"),
        }
    }
    assert_eq!(
        got,
        [
            "static world -> dock_light",
            "pose in dock_light",
            "tf dock_light -> auv1/base_link",
            "pose in dock_light",
            "tf dock_light -> auv1/base_link",
            "static world -> dock",
            "pose in dock",
            "tf dock -> auv1/base_link",
            "pose in dock",
            "tf dock -> auv1/base_link",
        ]
    );
}
