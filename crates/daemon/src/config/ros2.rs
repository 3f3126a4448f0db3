//! `[ros2]`: lightposed as a ROS 2 node (docs/ros2.md), a DDS participant
//! of its own with no ROS install. Absent (or `enabled = false`): no
//! participant, no socket, nothing opened. Names are checked here against
//! ROS 2's rules, so that a namespace the graph would refuse is refused at
//! its line at start, not by a subscriber's silence.

use super::locate::Ctx;
use super::ConfigError;
use serde::Deserialize;
use std::net::IpAddr;
use toml::Spanned;

/// What a topic's QoS is, by ROS 2's profile names, and each topic's:
/// the bag's types, one definition for the node and its recordings.
pub use lightpose_logs::ros2bag::{Qos as QosKind, TopicQos};

#[derive(Debug, Clone, PartialEq)]
pub struct Ros2 {
    pub domain_id: u16,
    /// `/lightpose`: the pose and odom topics' namespace.
    pub namespace: String,
    pub node_name: String,
    pub frames: lightpose_logs::ros2msg::Frames,
    pub qos: TopicQos,
    /// The addresses DDS binds (discovery and data); empty: every
    /// interface, as ROS 2's own middlewares do.
    pub networks: Vec<IpAddr>,
    /// `sensor_msgs/msg/Imu` whose orientation becomes the frames'
    /// attitude (needs `[site]`: the heading is referred to the beacon's
    /// axis through it).
    pub imu: Option<ImuInput>,
    /// A depth (`depth_topic`: a pressure or a pose's z), config/ros2in.rs.
    pub depth: Option<super::ros2in::DepthInput>,
    /// A DVL's `geometry_msgs/msg/TwistWithCovarianceStamped` (`dvl_topic`).
    pub dvl: Option<super::ros2in::DvlInput>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ImuInput {
    /// The topic's full name, e.g. `/imu/data`.
    pub topic: String,
    /// A reading older than this is not attached to a frame.
    pub max_age: std::time::Duration,
    /// Compass heading of the beacon's optical axis, degrees (`[site]`).
    pub beacon_axis_heading_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRos2 {
    enabled: Option<bool>,
    domain_id: Option<Spanned<i64>>,
    namespace: Option<Spanned<String>>,
    node_name: Option<Spanned<String>>,
    networks: Option<Vec<Spanned<String>>>,
    frames: Option<RawFrames>,
    qos: Option<RawQos>,
    imu_topic: Option<Spanned<String>>,
    imu_max_age_s: Option<Spanned<f64>>,
    pub(super) depth_topic: Option<Spanned<String>>,
    pub(super) depth_type: Option<Spanned<String>>,
    pub(super) water_density_kg_m3: Option<Spanned<f64>>,
    pub(super) surface_pressure_pa: Option<Spanned<f64>>,
    pub(super) depth_max_age_s: Option<Spanned<f64>>,
    pub(super) dvl_topic: Option<Spanned<String>>,
    pub(super) dvl_max_age_s: Option<Spanned<f64>>,
    pub(super) dvl_max_speed_mps: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFrames {
    beacon: Option<Spanned<String>>,
    base_link: Option<Spanned<String>>,
    map: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawQos {
    pose: Option<Spanned<String>>,
    odom: Option<Spanned<String>>,
    tf: Option<Spanned<String>>,
    diagnostics: Option<Spanned<String>>,
    depth: Option<Spanned<i64>>,
}

/// DDS's port mapping (7400 + 250·domain + …) leaves 232 as the last
/// domain whose ports fit in 16 bits (ROS 2's documentation says so).
const MAX_DOMAIN: i64 = 232;

/// Where `[site]` puts the beacon's frame for `/tf_static`: its axis
/// heading, and its NED position (none given: straight down at its
/// depth, the autopilot's origin above it).
pub fn site_tf(site: &lightpose_vehicle::Site) -> lightpose_logs::ros2msg::SiteTf {
    let n = site.beacon_ned.0;
    let ned = if n == [0.0; 3] {
        [0.0, 0.0, site.beacon_depth_m]
    } else {
        n
    };
    lightpose_logs::ros2msg::SiteTf {
        axis_heading: site.axis_heading,
        ned,
    }
}

/// What a `format = "ros2"` recording's bag names, as the node would:
/// `[ros2]`'s namespace and frames (its defaults without the table), and
/// `[site]`'s `/tf_static`.
pub(super) fn bag_options(
    ros2: Option<&Ros2>,
    site: Option<&lightpose_vehicle::Site>,
) -> lightpose_logs::Ros2BagOptions {
    let mut o = lightpose_logs::Ros2BagOptions::default();
    if let Some(r) = ros2 {
        o.frames = r.frames.clone();
        o.namespace = r.namespace.clone();
        o.qos = r.qos;
    }
    o.site = site.map(site_tf);
    o
}

/// The table checked (when off too: switching it on must not bring a
/// surprise), and whether it is on (`enabled`, default true).
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<RawRos2>>,
    site_heading_deg: Option<f64>,
) -> Result<Option<(Ros2, bool)>, ConfigError> {
    let Some(table) = raw else { return Ok(None) };
    let r = table.get_ref();
    let checked = check(ctx, r, site_heading_deg)?;
    Ok(Some((checked, r.enabled.unwrap_or(true))))
}

fn imu(ctx: &Ctx, r: &RawRos2, heading: Option<f64>) -> Result<Option<ImuInput>, ConfigError> {
    let Some(t) = &r.imu_topic else {
        if let Some(a) = &r.imu_max_age_s {
            return Err(ctx.err(a.span(), "ros2.imu_max_age_s", "without ros2.imu_topic"));
        }
        return Ok(None);
    };
    let name = super::ros2in::topic(ctx, t, "ros2.imu_topic", "/imu/data")?;
    let Some(heading) = heading else {
        let msg = "needs [site] beacon_heading_deg: the IMU's heading is referred to the beacon's axis through it";
        return Err(ctx.err(t.span(), "ros2.imu_topic", msg));
    };
    let max_age = match &r.imu_max_age_s {
        Some(a) => super::locate::positive_to(ctx, a, "ros2.imu_max_age_s", 10.0, " s")?,
        None => 0.5,
    };
    Ok(Some(ImuInput {
        topic: name,
        max_age: std::time::Duration::from_secs_f64(max_age),
        beacon_axis_heading_deg: heading,
    }))
}

fn check(ctx: &Ctx, r: &RawRos2, heading: Option<f64>) -> Result<Ros2, ConfigError> {
    let domain_id = match &r.domain_id {
        Some(d) if (0..=MAX_DOMAIN).contains(d.get_ref()) => *d.get_ref() as u16,
        Some(d) => {
            let msg = format!("{} is not in 0..={MAX_DOMAIN}", d.get_ref());
            return Err(ctx.err(d.span(), "ros2.domain_id", msg));
        }
        None => 0,
    };
    let namespace = match &r.namespace {
        Some(n) => namespace(ctx, n)?,
        None => "/lightpose".to_string(),
    };
    let node_name = match &r.node_name {
        Some(n) => {
            name_token(ctx, n, "ros2.node_name")?;
            n.get_ref().clone()
        }
        None => "lightposed".to_string(),
    };
    let mut networks = Vec::new();
    for n in r.networks.iter().flatten() {
        let ip = n.get_ref().parse::<IpAddr>().map_err(|_| {
            let msg = format!(
                "\"{}\" is not an IP address (an interface's address, e.g. \"127.0.0.1\")",
                lightpose_core::textfile::excerpt(n.get_ref(), 60)
            );
            ctx.err(n.span(), "ros2.networks", msg)
        })?;
        networks.push(ip);
    }
    Ok(Ros2 {
        domain_id,
        namespace,
        node_name,
        frames: frames(ctx, r.frames.as_ref())?,
        qos: qos(ctx, r.qos.as_ref())?,
        networks,
        imu: imu(ctx, r, heading)?,
        depth: super::ros2in::depth(ctx, r, heading.is_some())?,
        dvl: super::ros2in::dvl(ctx, r)?,
    })
}

/// A ROS 2 name token: letters, digits and `_`, not starting with a digit
/// (rcl's rule).
pub(super) use lightpose_logs::ros2msg::names::is_token;

fn name_token(ctx: &Ctx, v: &Spanned<String>, key: &str) -> Result<(), ConfigError> {
    if is_token(v.get_ref()) {
        return Ok(());
    }
    let msg = format!(
        "\"{}\" is no ROS 2 name (letters, digits and single _, not starting with a digit)",
        lightpose_core::textfile::excerpt(v.get_ref(), 60)
    );
    Err(ctx.err(v.span(), key, msg))
}

/// `/a/b`: absolute, tokens between slashes; `/` alone puts the topics
/// at the root.
fn namespace(ctx: &Ctx, v: &Spanned<String>) -> Result<String, ConfigError> {
    let s = v.get_ref();
    if lightpose_logs::ros2msg::names::is_namespace(s) {
        return Ok(s.clone());
    }
    let msg = format!(
        "\"{}\" is no absolute ROS 2 namespace (e.g. \"/lightpose\" or \"/auv1/lightpose\")",
        lightpose_core::textfile::excerpt(s, 60)
    );
    Err(ctx.err(v.span(), "ros2.namespace", msg))
}

/// A tf frame id: tf2 refuses a leading `/` and whitespace.
fn frame(
    ctx: &Ctx,
    v: Option<&Spanned<String>>,
    key: &str,
    default: &str,
) -> Result<String, ConfigError> {
    let Some(v) = v else {
        return Ok(default.to_string());
    };
    let s = v.get_ref();
    if lightpose_logs::ros2msg::names::is_frame_id(s) {
        return Ok(s.clone());
    }
    let msg = format!(
        "\"{}\" is no tf frame id (not empty, no leading /, no spaces)",
        lightpose_core::textfile::excerpt(s, 60)
    );
    Err(ctx.err(v.span(), key, msg))
}

fn frames(
    ctx: &Ctx,
    r: Option<&RawFrames>,
) -> Result<lightpose_logs::ros2msg::Frames, ConfigError> {
    let d = lightpose_logs::ros2msg::Frames::default();
    let Some(r) = r else { return Ok(d) };
    let f = lightpose_logs::ros2msg::Frames {
        beacon: frame(ctx, r.beacon.as_ref(), "ros2.frames.beacon", &d.beacon)?,
        base_link: frame(
            ctx,
            r.base_link.as_ref(),
            "ros2.frames.base_link",
            &d.base_link,
        )?,
        map: frame(ctx, r.map.as_ref(), "ros2.frames.map", &d.map)?,
    };
    if !f.distinct() {
        let at = r
            .beacon
            .as_ref()
            .or(r.base_link.as_ref())
            .or(r.map.as_ref());
        let msg = format!(
            "beacon, base_link and map must be three frames ({}, {}, {}): tf would loop",
            f.beacon, f.base_link, f.map
        );
        return Err(match at {
            Some(v) => ctx.err(v.span(), "ros2.frames", msg),
            None => ctx.whole(format!("ros2.frames: {msg}")),
        });
    }
    Ok(f)
}

fn kind(
    ctx: &Ctx,
    v: Option<&Spanned<String>>,
    key: &str,
    default: QosKind,
) -> Result<QosKind, ConfigError> {
    let Some(v) = v else { return Ok(default) };
    match v.get_ref().as_str() {
        "sensor_data" => Ok(QosKind::SensorData),
        "reliable" => Ok(QosKind::Reliable),
        "transient_local" => Ok(QosKind::TransientLocal),
        other => Err(ctx.err(
            v.span(),
            key,
            format!(
                "\"{}\" is not \"sensor_data\", \"reliable\" or \"transient_local\"",
                lightpose_core::textfile::excerpt(other, 40)
            ),
        )),
    }
}

fn qos(ctx: &Ctx, r: Option<&RawQos>) -> Result<TopicQos, ConfigError> {
    let none = RawQos {
        pose: None,
        odom: None,
        tf: None,
        diagnostics: None,
        depth: None,
    };
    let r = r.unwrap_or(&none);
    let depth = match &r.depth {
        Some(d) if (1..=1000).contains(d.get_ref()) => *d.get_ref() as usize,
        Some(d) => {
            let msg = format!("{} is not in 1..=1000", d.get_ref());
            return Err(ctx.err(d.span(), "ros2.qos.depth", msg));
        }
        None => 10,
    };
    Ok(TopicQos {
        pose: kind(ctx, r.pose.as_ref(), "ros2.qos.pose", QosKind::SensorData)?,
        odom: kind(ctx, r.odom.as_ref(), "ros2.qos.odom", QosKind::SensorData)?,
        // tf2's TransformListener subscribes reliable: a best-effort /tf
        // would match no listener.
        tf: kind(ctx, r.tf.as_ref(), "ros2.qos.tf", QosKind::Reliable)?,
        diagnostics: kind(
            ctx,
            r.diagnostics.as_ref(),
            "ros2.qos.diagnostics",
            QosKind::Reliable,
        )?,
        depth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    const BASE: &str = "calibration = \"c.toml\"\n[backend]\nkind = \"sim\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n";

    fn parse(extra: &str) -> Result<Config, String> {
        Config::parse(&format!("{BASE}{extra}"), "t.toml", None).map_err(|e| e.to_string())
    }

    #[test]
    fn absent_or_off_is_no_node() {
        assert_eq!(parse("").expect("valid").ros2, None);
        assert_eq!(
            parse("[ros2]\nenabled = false\n").expect("valid").ros2,
            None
        );
        // Off, but checked all the same.
        let e = parse("[ros2]\nenabled = false\ndomain_id = 300\n").expect_err("refused");
        assert_eq!(e, "t.toml:8: ros2.domain_id: 300 is not in 0..=232");
    }

    #[test]
    fn defaults_are_ros_2s() {
        let r = parse("[ros2]\n").expect("valid").ros2.expect("on");
        assert_eq!(r.domain_id, 0);
        assert_eq!(r.namespace, "/lightpose");
        assert_eq!(r.node_name, "lightposed");
        assert_eq!(r.frames.beacon, "lightpose_beacon");
        assert_eq!(r.qos.pose, QosKind::SensorData);
        assert_eq!(r.qos.tf, QosKind::Reliable);
        assert_eq!(r.qos.depth, 10);
        assert!(r.networks.is_empty());
    }

    #[test]
    fn every_key_is_read() {
        let r = parse(
            "[ros2]\ndomain_id = 42\nnamespace = \"/auv1/lp\"\nnode_name = \"lp_1\"\nnetworks = [\"127.0.0.1\"]\n[ros2.frames]\nbeacon = \"dock\"\nbase_link = \"auv1/base_link\"\nmap = \"odom\"\n[ros2.qos]\npose = \"transient_local\"\nodom = \"reliable\"\ndepth = 5\n",
        )
        .expect("valid")
        .ros2
        .expect("on");
        assert_eq!(
            (r.domain_id, r.namespace.as_str(), r.node_name.as_str()),
            (42, "/auv1/lp", "lp_1")
        );
        assert_eq!(r.networks, vec!["127.0.0.1".parse::<IpAddr>().unwrap()]);
        assert_eq!(
            (
                r.frames.beacon.as_str(),
                r.frames.base_link.as_str(),
                r.frames.map.as_str()
            ),
            ("dock", "auv1/base_link", "odom")
        );
        assert_eq!(
            (r.qos.pose, r.qos.odom, r.qos.depth),
            (QosKind::TransientLocal, QosKind::Reliable, 5)
        );
    }

    #[test]
    fn the_imu_input_takes_its_heading_from_site() {
        let site = "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n";
        let r = parse(&format!("{site}[ros2]\nimu_topic = \"/imu/data\"\n"))
            .expect("valid")
            .ros2
            .expect("on");
        let i = r.imu.expect("imu");
        assert_eq!(
            (i.topic.as_str(), i.beacon_axis_heading_deg),
            ("/imu/data", 30.0)
        );
        assert_eq!(i.max_age, std::time::Duration::from_millis(500));
        let e = parse(&format!("{site}[ros2]\nimu_topic = \"/imu/data\"\n[attitude]\nenabled = true\nlisten = \"127.0.0.1:17151\"\n")).expect_err("two inputs");
        assert!(e.contains("one attitude input at a time"), "{e}");
    }

    #[test]
    fn bad_values_name_their_line() {
        let cases = [
            (
                "[ros2]\nnamespace = \"lightpose\"\n",
                "t.toml:7: ros2.namespace: \"lightpose\" is no absolute ROS 2 namespace",
            ),
            (
                "[ros2]\nnamespace = \"/a//b\"\n",
                "t.toml:7: ros2.namespace:",
            ),
            (
                "[ros2]\nnode_name = \"9lives\"\n",
                "t.toml:7: ros2.node_name: \"9lives\" is no ROS 2 name",
            ),
            (
                "[ros2]\nnetworks = [\"eth0\"]\n",
                "t.toml:7: ros2.networks: \"eth0\" is not an IP address",
            ),
            (
                "[ros2]\n[ros2.frames]\nbeacon = \"/b\"\n",
                "t.toml:8: ros2.frames.beacon: \"/b\" is no tf frame id",
            ),
            (
                "[ros2]\n[ros2.frames]\nbeacon = \"base_link\"\n",
                "t.toml:8: ros2.frames: beacon, base_link and map must be three frames",
            ),
            (
                "[ros2]\n[ros2.qos]\npose = \"fast\"\n",
                "t.toml:8: ros2.qos.pose: \"fast\" is not \"sensor_data\"",
            ),
            (
                "[ros2]\n[ros2.qos]\ndepth = 0\n",
                "t.toml:8: ros2.qos.depth: 0 is not in 1..=1000",
            ),
            (
                "[ros2]\ntopic = \"x\"\n",
                "t.toml:7: ros2.topic: unknown field `topic`",
            ),
            (
                "[ros2]\nimu_topic = \"/imu/data\"\n",
                "t.toml:7: ros2.imu_topic: needs [site] beacon_heading_deg",
            ),
            (
                "[ros2]\nimu_topic = \"imu\"\n",
                "t.toml:7: ros2.imu_topic: \"imu\" is no absolute ROS 2 topic name",
            ),
            (
                "[ros2]\nimu_max_age_s = 1.0\n",
                "t.toml:7: ros2.imu_max_age_s: without ros2.imu_topic",
            ),
        ];
        for (text, want) in cases {
            let e = parse(text).expect_err(text);
            assert!(e.starts_with(want), "{text}: {e}");
        }
    }
}
