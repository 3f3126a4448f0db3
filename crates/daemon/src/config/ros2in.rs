//! `[ros2]`'s depth and DVL inputs (`depth_topic`, `dvl_topic`,
//! docs/ros2.md): each optional, each checked here at its line, so that a
//! topic name the graph refuses or a density no water has fails the start
//! rather than silently giving frames no depth. Apart from config/ros2.rs
//! (the node and its outputs) to keep each file to one job.

use super::locate::{positive_to, within, Ctx};
use super::ros2::RawRos2;
use super::ConfigError;
use std::time::Duration;
use toml::Spanned;

/// How a depth message gives the depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthKind {
    /// `sensor_msgs/msg/FluidPressure` (Pa): depth = (p − surface) / (ρ g).
    FluidPressure {
        water_density_kg_m3: f64,
        surface_pressure_pa: f64,
    },
    /// `geometry_msgs/msg/PoseWithCovarianceStamped` in an ENU frame whose
    /// z is 0 at the surface: depth = −z.
    Pose,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DepthInput {
    pub topic: String,
    pub kind: DepthKind,
    /// A reading older than this is not attached to a frame.
    pub max_age: Duration,
    /// Depths (m, positive down) outside this range are refused, as
    /// `[mavlink]`'s are.
    pub range_m: [f64; 2],
}

#[derive(Debug, Clone, PartialEq)]
pub struct DvlInput {
    pub topic: String,
    pub max_age: Duration,
    /// A component faster than this (m/s) is refused, as `[dvl]`'s are.
    pub max_speed_mps: f64,
}

/// Standard gravity, m/s² (the depth of a pressure, as depth sensors'
/// drivers take it).
pub const G: f64 = 9.80665;

/// `[mavlink]`'s depth range, the same for ROS 2's.
const DEPTH_RANGE_M: [f64; 2] = [-10.0, 1000.0];

/// An absolute ROS 2 topic name (`/a/b`), refused at its line otherwise.
pub(super) fn topic(
    ctx: &Ctx,
    t: &Spanned<String>,
    key: &str,
    eg: &str,
) -> Result<String, ConfigError> {
    let name = t.get_ref();
    if name.starts_with('/') && name[1..].split('/').all(super::ros2::is_token) {
        return Ok(name.clone());
    }
    let msg = format!(
        "\"{}\" is no absolute ROS 2 topic name (e.g. \"{eg}\")",
        lightpose_core::textfile::excerpt(name, 60)
    );
    Err(ctx.err(t.span(), key, msg))
}

/// A key that only means something with its topic.
fn without<T>(
    ctx: &Ctx,
    v: Option<&Spanned<T>>,
    key: &str,
    topic: &str,
) -> Result<(), ConfigError> {
    match v {
        Some(v) => Err(ctx.err(v.span(), key, format!("without {topic}"))),
        None => Ok(()),
    }
}

fn age(
    ctx: &Ctx,
    v: Option<&Spanned<f64>>,
    key: &str,
    default: f64,
) -> Result<Duration, ConfigError> {
    let s = match v {
        Some(a) => positive_to(ctx, a, key, 10.0, " s")?,
        None => default,
    };
    Ok(Duration::from_secs_f64(s))
}

/// The keys only a fluid-pressure depth takes, refused without `needs`.
fn pressure_keys_without(ctx: &Ctx, r: &RawRos2, needs: &str) -> Result<(), ConfigError> {
    without(
        ctx,
        r.water_density_kg_m3.as_ref(),
        "ros2.water_density_kg_m3",
        needs,
    )?;
    without(
        ctx,
        r.surface_pressure_pa.as_ref(),
        "ros2.surface_pressure_pa",
        needs,
    )
}

pub(super) fn depth(ctx: &Ctx, r: &RawRos2, site: bool) -> Result<Option<DepthInput>, ConfigError> {
    let Some(t) = &r.depth_topic else {
        let t = "ros2.depth_topic";
        without(ctx, r.depth_type.as_ref(), "ros2.depth_type", t)?;
        pressure_keys_without(ctx, r, t)?;
        without(ctx, r.depth_max_age_s.as_ref(), "ros2.depth_max_age_s", t)?;
        return Ok(None);
    };
    let topic = topic(ctx, t, "ros2.depth_topic", "/depth/pressure")?;
    if !site {
        let msg = "needs [site] beacon_depth_m: a depth becomes z in B through it";
        return Err(ctx.err(t.span(), "ros2.depth_topic", msg));
    }
    let kind = match r.depth_type.as_ref().map(|k| (k, k.get_ref().as_str())) {
        None | Some((_, "fluid_pressure")) => DepthKind::FluidPressure {
            water_density_kg_m3: match &r.water_density_kg_m3 {
                // Fresh water to the densest brine.
                Some(d) => within(
                    ctx,
                    d,
                    "ros2.water_density_kg_m3",
                    (990.0, 1100.0),
                    " kg/m³",
                )?,
                None => 1025.0,
            },
            surface_pressure_pa: match &r.surface_pressure_pa {
                Some(p) => within(
                    ctx,
                    p,
                    "ros2.surface_pressure_pa",
                    (50_000.0, 120_000.0),
                    " Pa",
                )?,
                None => 101_325.0,
            },
        },
        Some((_, "pose")) => {
            let t = "ros2.depth_type = \"fluid_pressure\"";
            pressure_keys_without(ctx, r, t)?;
            DepthKind::Pose
        }
        Some((k, other)) => {
            let msg = format!(
                "\"{}\" is not \"fluid_pressure\" or \"pose\"",
                lightpose_core::textfile::excerpt(other, 40)
            );
            return Err(ctx.err(k.span(), "ros2.depth_type", msg));
        }
    };
    Ok(Some(DepthInput {
        topic,
        kind,
        max_age: age(ctx, r.depth_max_age_s.as_ref(), "ros2.depth_max_age_s", 0.5)?,
        range_m: DEPTH_RANGE_M,
    }))
}

pub(super) fn dvl(ctx: &Ctx, r: &RawRos2) -> Result<Option<DvlInput>, ConfigError> {
    let Some(t) = &r.dvl_topic else {
        let t = "ros2.dvl_topic";
        without(ctx, r.dvl_max_age_s.as_ref(), "ros2.dvl_max_age_s", t)?;
        without(
            ctx,
            r.dvl_max_speed_mps.as_ref(),
            "ros2.dvl_max_speed_mps",
            t,
        )?;
        return Ok(None);
    };
    Ok(Some(DvlInput {
        topic: topic(ctx, t, "ros2.dvl_topic", "/dvl/twist")?,
        max_age: age(ctx, r.dvl_max_age_s.as_ref(), "ros2.dvl_max_age_s", 1.0)?,
        max_speed_mps: match &r.dvl_max_speed_mps {
            Some(v) => positive_to(ctx, v, "ros2.dvl_max_speed_mps", 50.0, " m/s")?,
            None => 5.0,
        },
    }))
}

/// One depth and one DVL input at a time: two writers of one reading
/// would take turns on the frames. `[mavlink]` gives a depth unless its
/// `depth = "none"`.
pub(super) fn one_of_each(
    ctx: &Ctx,
    ros2: Option<&super::Ros2>,
    vehicle: Option<&super::VehicleConfig>,
) -> Result<(), ConfigError> {
    let (Some(r), Some(v)) = (ros2, vehicle) else {
        return Ok(());
    };
    let mav_depth = v.mavlink.as_ref().map(|m| m.input.depth);
    if let (Some(d), Some(src)) = (&r.depth, mav_depth) {
        if src != lightpose_vehicle::mav::inbound::DepthSource::Off {
            return Err(ctx.whole(format!(
                "ros2.depth_topic {} and [mavlink]'s depth: one depth input at a time ([mavlink] depth = \"none\")",
                d.topic
            )));
        }
    }
    if let (Some(d), Some(dvl)) = (&r.dvl, &v.dvl) {
        return Err(ctx.whole(format!(
            "ros2.dvl_topic {} and [dvl] address {}: one DVL input at a time",
            d.topic, dvl.address
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::config::Config;

    const BASE: &str = "calibration = \"c.toml\"\n[backend]\nkind = \"sim\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n";
    const SITE: &str = "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n";

    fn parse(extra: &str) -> Result<Config, String> {
        Config::parse(&format!("{BASE}{extra}"), "t.toml", None).map_err(|e| e.to_string())
    }

    #[test]
    fn depth_and_dvl_take_their_defaults() {
        let r = parse(&format!(
            "{SITE}[ros2]\ndepth_topic = \"/depth\"\ndvl_topic = \"/dvl/twist\"\n"
        ))
        .expect("valid")
        .ros2
        .expect("on");
        let d = r.depth.expect("depth");
        assert_eq!(d.topic, "/depth");
        assert_eq!(
            d.kind,
            super::DepthKind::FluidPressure {
                water_density_kg_m3: 1025.0,
                surface_pressure_pa: 101_325.0
            }
        );
        assert_eq!(d.max_age, std::time::Duration::from_millis(500));
        let v = r.dvl.expect("dvl");
        assert_eq!((v.topic.as_str(), v.max_speed_mps), ("/dvl/twist", 5.0));
        assert_eq!(v.max_age, std::time::Duration::from_secs(1));
        let r = parse(&format!(
            "{SITE}[ros2]\ndepth_topic = \"/odom/depth\"\ndepth_type = \"pose\"\ndepth_max_age_s = 0.2\ndvl_max_age_s = 0.3\ndvl_topic = \"/d\"\ndvl_max_speed_mps = 3.0\n"
        ))
        .expect("valid")
        .ros2
        .expect("on");
        assert_eq!(
            r.depth.as_ref().map(|d| d.kind),
            Some(super::DepthKind::Pose)
        );
        assert_eq!(r.dvl.map(|d| d.max_speed_mps), Some(3.0));
    }

    #[test]
    fn bad_depth_and_dvl_keys_name_their_line() {
        let cases = [
            (
                "[ros2]\ndepth_topic = \"/depth\"\n".to_string(),
                "t.toml:7: ros2.depth_topic: needs [site] beacon_depth_m",
            ),
            (
                format!("{SITE}[ros2]\ndepth_topic = \"depth\"\n"),
                "t.toml:10: ros2.depth_topic: \"depth\" is no absolute ROS 2 topic name",
            ),
            (
                format!("{SITE}[ros2]\ndepth_topic = \"/d\"\ndepth_type = \"baro\"\n"),
                "t.toml:11: ros2.depth_type: \"baro\" is not \"fluid_pressure\" or \"pose\"",
            ),
            (
                format!("{SITE}[ros2]\ndepth_topic = \"/d\"\nwater_density_kg_m3 = 10.0\n"),
                "t.toml:11: ros2.water_density_kg_m3: 10 is not in 990..=1100 kg/m³",
            ),
            (
                format!("{SITE}[ros2]\ndepth_topic = \"/d\"\ndepth_type = \"pose\"\nsurface_pressure_pa = 1e5\n"),
                "t.toml:12: ros2.surface_pressure_pa: without ros2.depth_type = \"fluid_pressure\"",
            ),
            (
                "[ros2]\ndepth_max_age_s = 1.0\n".to_string(),
                "t.toml:7: ros2.depth_max_age_s: without ros2.depth_topic",
            ),
            (
                "[ros2]\ndvl_topic = \"/dvl\"\ndvl_max_speed_mps = -1.0\n".to_string(),
                "t.toml:8: ros2.dvl_max_speed_mps: -1 is not in (0, 50] m/s",
            ),
            (
                "[ros2]\ndvl_max_age_s = 1.0\n".to_string(),
                "t.toml:7: ros2.dvl_max_age_s: without ros2.dvl_topic",
            ),
        ];
        for (text, want) in cases {
            let e = parse(&text).expect_err(&text);
            assert!(e.starts_with(want), "{text}: {e}");
        }
    }

    #[test]
    fn one_depth_and_one_dvl_input_at_a_time() {
        let two = format!(
            "{SITE}[ros2]\ndepth_topic = \"/d\"\n[mavlink]\nconnection = \"udpin:127.0.0.1:14550\"\n"
        );
        let e = parse(&two).expect_err("two depths");
        assert!(e.contains("one depth input at a time"), "{e}");
        let ok = format!(
            "{SITE}[ros2]\ndepth_topic = \"/d\"\n[mavlink]\nconnection = \"udpin:127.0.0.1:14550\"\ndepth = \"none\"\n"
        );
        parse(&ok).expect("mavlink without depth");
        let two =
            format!("{SITE}[ros2]\ndvl_topic = \"/v\"\n[dvl]\naddress = \"127.0.0.1:16171\"\n");
        let e = parse(&two).expect_err("two dvls");
        assert!(e.contains("one DVL input at a time"), "{e}");
    }
}
