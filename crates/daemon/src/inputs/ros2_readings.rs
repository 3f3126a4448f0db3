//! The vehicle's depth and DVL velocity from ROS 2 (`[ros2] depth_topic`,
//! `dvl_topic`), and the node's input thread that reads them and the IMU.
//! Each message is checked and turned into the reading the MAVLink and
//! Water Linked inputs give (`DepthReading`: z in B through `[site]`;
//! `VelocityReading`: V, FRD), stored in a [`Hub`]'s lock-free cells of
//! its own, and attached by a [`super::vehicle::VehicleReadings`] with
//! the `[ros2]` ages: freshness, carrying and STATUS counts as for those
//! inputs. Refusals are counted by reason (STATUS `ros2.inputs`).

use crate::config::ros2in::{DepthInput, DepthKind, DvlInput, G};
use crate::inputs::attitude::AttitudeCell;
use lightpose_core::{BodyVec, DepthReading, VelocityReading};
use lightpose_logs::ros2msg::{
    FluidPressure, Header, PoseWithCovarianceStamped, TwistWithCovarianceStamped,
};
use lightpose_vehicle::{Hub, Site};
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A frame id longer than this is no frame id: the sample is refused
/// (`malformed`) rather than believed.
pub const MAX_FRAME_ID: usize = 256;

/// Why a depth or DVL message was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// A NaN or infinite value.
    NotFinite = 0,
    /// A depth outside the range, a speed above the maximum, a pressure
    /// that is not positive.
    OutOfRange = 1,
    /// A negative or NaN variance, or variances given for some axes only.
    BadCovariance = 2,
    /// A sample DDS could not read, or one with an overlong frame id.
    Malformed = 3,
}

impl Refusal {
    pub const ALL: [Refusal; 4] = [
        Refusal::NotFinite,
        Refusal::OutOfRange,
        Refusal::BadCovariance,
        Refusal::Malformed,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Refusal::NotFinite => "not_finite",
            Refusal::OutOfRange => "out_of_range",
            Refusal::BadCovariance => "bad_covariance",
            Refusal::Malformed => "malformed",
        }
    }
}

/// One input's counters.
#[derive(Default)]
pub struct Counts {
    pub received: AtomicU64,
    pub rejected_by: [AtomicU64; Refusal::ALL.len()],
}

impl Counts {
    fn refuse(&self, r: Refusal, what: &str) {
        // The first refusal of each kind told, the others counted.
        if self.rejected_by[r as usize].fetch_add(1, Relaxed) == 0 {
            tracing::warn!(
                "ros2 {what}: a reading refused ({}), counted in STATUS ros2.inputs.{what}.rejected_by",
                r.as_str()
            );
        }
    }

    fn report(&self, topic: &str, use_: &lightpose_vehicle::readings::ReadingStatus) -> Value {
        let by: serde_json::Map<String, Value> = Refusal::ALL
            .iter()
            .map(|r| {
                (
                    r.as_str().to_string(),
                    self.rejected_by[*r as usize].load(Relaxed).into(),
                )
            })
            .collect();
        json!({
            "topic": topic,
            "received": self.received.load(Relaxed),
            "stored": use_.stored,
            "attached": use_.attached,
            "stale": use_.stale,
            "age_s": use_.age_s,
            "rejected_by": by,
        })
    }
}

/// The depth and DVL inputs' shared state: the hub the frame thread
/// attaches from, the counters STATUS reads.
pub struct Ros2Readings {
    pub hub: Arc<Hub>,
    pub depth: Counts,
    pub dvl: Counts,
    depth_cfg: Option<DepthInput>,
    dvl_cfg: Option<DvlInput>,
    site: Option<Site>,
}

impl Ros2Readings {
    /// `None` when neither input is configured.
    pub fn new(
        depth: Option<DepthInput>,
        dvl: Option<DvlInput>,
        site: Option<&Site>,
    ) -> Option<Self> {
        (depth.is_some() || dvl.is_some()).then(|| Ros2Readings {
            hub: Hub::new(),
            depth: Counts::default(),
            dvl: Counts::default(),
            depth_cfg: depth,
            dvl_cfg: dvl,
            site: site.copied(),
        })
    }

    /// The ages the frame thread's attach uses: only depth and velocity
    /// are ever stored here.
    pub fn max_age(&self) -> lightpose_vehicle::MaxAge {
        lightpose_vehicle::MaxAge {
            attitude: Duration::ZERO,
            temperature: Duration::ZERO,
            depth: self
                .depth_cfg
                .as_ref()
                .map_or(Duration::ZERO, |d| d.max_age),
            velocity: self.dvl_cfg.as_ref().map_or(Duration::ZERO, |d| d.max_age),
        }
    }

    /// STATUS `ros2.inputs`.
    pub fn report(&self) -> Value {
        let s = self.hub.readings.status(Instant::now());
        let mut v = serde_json::Map::new();
        if let Some(d) = &self.depth_cfg {
            v.insert("depth".into(), self.depth.report(&d.topic, &s.depth));
        }
        if let Some(d) = &self.dvl_cfg {
            v.insert("dvl".into(), self.dvl.report(&d.topic, &s.velocity));
        }
        Value::Object(v)
    }

    /// One depth message (or a sample DDS could not read).
    pub fn take_depth(&self, got: Result<(f64, Option<f64>), Refusal>) {
        let (Some(cfg), Some(site)) = (&self.depth_cfg, &self.site) else {
            return;
        };
        self.depth.received.fetch_add(1, Relaxed);
        match got.and_then(|(d, std)| depth_reading(d, std, cfg.range_m, site)) {
            Ok(r) => self.hub.readings.store_depth(Instant::now(), &r),
            Err(r) => self.depth.refuse(r, "depth"),
        }
    }

    /// One DVL message (or a sample DDS could not read).
    pub fn take_dvl(&self, got: Result<&TwistWithCovarianceStamped, Refusal>) {
        let Some(cfg) = &self.dvl_cfg else { return };
        self.dvl.received.fetch_add(1, Relaxed);
        match got.and_then(|m| velocity(m, cfg.max_speed_mps)) {
            Ok(v) => self.hub.readings.store_velocity(Instant::now(), &v),
            Err(r) => self.dvl.refuse(r, "dvl"),
        }
    }
}

fn header(h: &Header) -> Result<(), Refusal> {
    if h.frame_id.len() > MAX_FRAME_ID {
        return Err(Refusal::Malformed);
    }
    Ok(())
}

/// A variance as a σ: 0 is ROS's "unknown" (no σ), a negative or NaN
/// one is refused.
fn sigma(var: f64) -> Result<Option<f64>, Refusal> {
    if var == 0.0 {
        Ok(None)
    } else if var.is_finite() && var > 0.0 {
        Ok(Some(var.sqrt()))
    } else {
        Err(Refusal::BadCovariance)
    }
}

/// The depth (m, positive down) and its σ of a pressure.
pub fn depth_of_pressure(
    m: &FluidPressure,
    kind: DepthKind,
) -> Result<(f64, Option<f64>), Refusal> {
    header(&m.header)?;
    let DepthKind::FluidPressure {
        water_density_kg_m3: rho,
        surface_pressure_pa: p0,
    } = kind
    else {
        return Err(Refusal::Malformed);
    };
    if !m.fluid_pressure.is_finite() {
        return Err(Refusal::NotFinite);
    }
    if m.fluid_pressure <= 0.0 {
        return Err(Refusal::OutOfRange);
    }
    let std = sigma(m.variance)?.map(|s| s / (rho * G));
    Ok(((m.fluid_pressure - p0) / (rho * G), std))
}

/// The depth of a pose's z (ENU: up), and its σ.
pub fn depth_of_pose(m: &PoseWithCovarianceStamped) -> Result<(f64, Option<f64>), Refusal> {
    header(&m.header)?;
    let z = m.pose.pose.position.z;
    if !z.is_finite() {
        return Err(Refusal::NotFinite);
    }
    Ok((-z, sigma(m.pose.covariance.0[14])?))
}

/// z in B of a depth, checked against the range.
fn depth_reading(
    depth_m: f64,
    std: Option<f64>,
    [lo, hi]: [f64; 2],
    site: &Site,
) -> Result<DepthReading, Refusal> {
    if !(lo..=hi).contains(&depth_m) {
        return Err(Refusal::OutOfRange);
    }
    Ok(DepthReading {
        z: site.z_from_depth(depth_m),
        std,
    })
}

/// The DVL's velocity in V (FRD) from a twist in the body FLU (REP-103:
/// y and z negated), its σ from the linear part's diagonal when given.
pub fn velocity(
    m: &TwistWithCovarianceStamped,
    max_speed: f64,
) -> Result<VelocityReading, Refusal> {
    header(&m.header)?;
    let l = m.twist.twist.linear;
    let v = [l.x, -l.y, -l.z];
    if v.iter().any(|c| !c.is_finite()) {
        return Err(Refusal::NotFinite);
    }
    if v.iter().any(|c| c.abs() > max_speed) {
        return Err(Refusal::OutOfRange);
    }
    let c = &m.twist.covariance.0;
    let s = [sigma(c[0])?, sigma(c[7])?, sigma(c[14])?];
    let std = match s {
        [Some(a), Some(b), Some(c)] => Some(BodyVec([a, b, c])),
        [None, None, None] => None,
        // Some axes known, others not: no honest σ for the reading.
        _ => return Err(Refusal::BadCovariance),
    };
    Ok(VelocityReading { v: BodyVec(v), std })
}

type Sub<M> = ros2_client::dds::Subscription<M>;

/// The depth topic's subscription, by its type.
pub enum DepthSub {
    Pressure(Sub<FluidPressure>, DepthKind),
    Pose(Sub<PoseWithCovarianceStamped>),
}

/// What the node's input thread reads.
pub struct Subs {
    /// Writers of another type on these topics, looked for in discovery.
    pub watch: Option<OtherTypes>,
    /// The IMU, its attitude cell and the beacon axis' heading (degrees).
    pub imu: Option<(Sub<lightpose_logs::ros2msg::Imu>, Arc<AttitudeCell>, f64)>,
    pub depth: Option<DepthSub>,
    pub dvl: Option<Sub<TwistWithCovarianceStamped>>,
    pub readings: Option<Arc<Ros2Readings>>,
}

impl Subs {
    fn any(&self) -> bool {
        self.imu.is_some() || self.depth.is_some() || self.dvl.is_some()
    }
}

/// Samples taken from one topic per round at most, so that a flood on one
/// does not starve the others.
const PER_ROUND: usize = 32;

/// Take what one subscription holds: `each` gets every sample (or the
/// error of one DDS could not read). True if there was any.
fn drain<M: 'static + serde::de::DeserializeOwned>(
    sub: &Sub<M>,
    mut each: impl FnMut(Result<M, String>),
) -> bool {
    let mut any = false;
    for _ in 0..PER_ROUND {
        match sub.take() {
            Ok(Some((m, _))) => each(Ok(m)),
            Ok(None) => break,
            Err(e) => each(Err(format!("{e:?}"))),
        }
        any = true;
    }
    any
}

fn unreadable(why: String, what: &str) -> Refusal {
    tracing::debug!("ros2 {what}: unreadable sample: {why}");
    Refusal::Malformed
}

/// One round over every subscription; true if anything came.
fn round(s: &Subs) -> bool {
    let mut any = false;
    if let Some((sub, cell, heading)) = &s.imu {
        any |= drain(sub, |m| crate::inputs::ros2::take(cell, m, *heading));
    }
    if let (Some(d), Some(r)) = (&s.depth, &s.readings) {
        let what = "depth";
        any |= match d {
            DepthSub::Pressure(sub, kind) => drain(sub, |m| {
                r.take_depth(
                    m.map_err(|e| unreadable(e, what))
                        .and_then(|m| depth_of_pressure(&m, *kind)),
                )
            }),
            DepthSub::Pose(sub) => drain(sub, |m| {
                r.take_depth(
                    m.map_err(|e| unreadable(e, what))
                        .and_then(|m| depth_of_pose(&m)),
                )
            }),
        };
    }
    if let (Some(sub), Some(r)) = (&s.dvl, &s.readings) {
        any |= drain(sub, |m| match m {
            Ok(m) => r.take_dvl(Ok(&m)),
            Err(e) => r.take_dvl(Err(unreadable(e, "dvl"))),
        });
    }
    any
}

/// Writers on an input's topic whose type is not the input's. Cyclone,
/// Fast DDS and Connext match by type name and send such a reader
/// nothing, so no sample shows them; discovery (SEDP) does: each one is
/// logged once and named in STATUS `ros2.other_type_writers`.
pub struct OtherTypes {
    pub participant: ros2_client::dds::rustdds::DomainParticipant,
    /// (DDS topic name, the DDS type name the input reads).
    pub topics: Vec<(String, String)>,
    /// "rt/imu/data: std_msgs::msg::dds_::String_", each once.
    pub found: Arc<std::sync::Mutex<Vec<String>>>,
}

impl OtherTypes {
    /// The input topic `ros_name` (absolute) read as `t`.
    pub fn topic(ros_name: &str, t: lightpose_logs::ros2msg::TypeName) -> (String, String) {
        (format!("rt{ros_name}"), t.dds())
    }

    fn look(&self) {
        for w in self.participant.discovered_writers() {
            let d = &w.publication_topic_data;
            let Some((_, want)) = self.topics.iter().find(|(n, _)| *n == d.topic_name) else {
                continue;
            };
            if d.type_name == *want {
                continue;
            }
            let seen = format!("{}: {}", d.topic_name, d.type_name);
            let mut found = self.found.lock().unwrap_or_else(|p| p.into_inner());
            if !found.contains(&seen) {
                tracing::warn!(
                    "ros2: a writer of {} on {} (the input reads {want}): not matched, its samples never arrive",
                    d.type_name,
                    d.topic_name
                );
                found.push(seen);
            }
        }
    }
}

/// The input thread, when any input is configured: every topic polled
/// each 2 ms (an IMU at 100 Hz is read within 2 ms of its sample), and
/// discovery once a second for writers of another type, until `closed`.
pub fn spawn(subs: Subs, closed: Arc<AtomicBool>) -> std::io::Result<Option<JoinHandle<()>>> {
    if !subs.any() {
        return Ok(None);
    }
    std::thread::Builder::new()
        .name("lightposed-ros2-in".into())
        .spawn(move || {
            let mut looked: Option<Instant> = None;
            while !closed.load(Relaxed) {
                if let Some(w) = &subs.watch {
                    if looked.is_none_or(|t| t.elapsed() >= Duration::from_secs(1)) {
                        w.look();
                        looked = Some(Instant::now());
                    }
                }
                if !round(&subs) {
                    std::thread::sleep(Duration::from_millis(2));
                }
            }
        })
        .map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_logs::ros2msg::Cov6;

    fn site() -> Site {
        Site {
            axis_heading: lightpose_core::Angle::from_deg(30.0),
            beacon_depth_m: 3.0,
            beacon_ned: lightpose_vehicle::NedVec::default(),
        }
    }

    const SEA: DepthKind = DepthKind::FluidPressure {
        water_density_kg_m3: 1025.0,
        surface_pressure_pa: 101_325.0,
    };

    #[test]
    fn a_pressure_and_a_pose_become_a_depth() {
        let rho_g = 1025.0 * G;
        let m = FluidPressure {
            fluid_pressure: 101_325.0 + 2.0 * rho_g,
            variance: (0.01 * rho_g).powi(2),
            ..FluidPressure::default()
        };
        let (d, s) = depth_of_pressure(&m, SEA).expect("taken");
        assert!((d - 2.0).abs() < 1e-12, "{d}");
        assert!((s.expect("σ") - 0.01).abs() < 1e-12);
        // Unknown variance: no σ (the estimator's own is used).
        let m = FluidPressure { variance: 0.0, ..m };
        assert_eq!(depth_of_pressure(&m, SEA).map(|d| d.1), Ok(None));
        let mut p = PoseWithCovarianceStamped::default();
        p.pose.pose.position.z = -4.5;
        p.pose.covariance = Cov6([0.0; 36]);
        p.pose.covariance.0[14] = 0.04;
        assert_eq!(depth_of_pose(&p), Ok((4.5, Some(0.2))));
        // Through [site]: the beacon at 3 m, the vehicle at 2 m is z = 1.
        assert_eq!(
            depth_reading(2.0, None, [-10.0, 1000.0], &site()).map(|r| r.z),
            Ok(1.0)
        );
    }

    #[test]
    fn bad_depths_are_refused_by_reason() {
        let nan = FluidPressure {
            fluid_pressure: f64::NAN,
            ..FluidPressure::default()
        };
        assert_eq!(depth_of_pressure(&nan, SEA), Err(Refusal::NotFinite));
        let zero = FluidPressure::default();
        assert_eq!(depth_of_pressure(&zero, SEA), Err(Refusal::OutOfRange));
        let neg_var = FluidPressure {
            fluid_pressure: 2e5,
            variance: -1.0,
            ..FluidPressure::default()
        };
        assert_eq!(
            depth_of_pressure(&neg_var, SEA),
            Err(Refusal::BadCovariance)
        );
        let mut long = FluidPressure {
            fluid_pressure: 2e5,
            ..FluidPressure::default()
        };
        long.header.frame_id = "x".repeat(MAX_FRAME_ID + 1);
        assert_eq!(depth_of_pressure(&long, SEA), Err(Refusal::Malformed));
        assert_eq!(
            depth_reading(2000.0, None, [-10.0, 1000.0], &site()),
            Err(Refusal::OutOfRange)
        );
        let r = Ros2Readings::new(
            Some(DepthInput {
                topic: "/d".into(),
                kind: SEA,
                max_age: Duration::from_millis(500),
                range_m: [-10.0, 1000.0],
            }),
            None,
            Some(&site()),
        )
        .expect("an input");
        r.take_depth(Ok((2.0, None)));
        r.take_depth(Err(Refusal::Malformed));
        r.take_depth(Ok((5000.0, None)));
        let v = r.report();
        assert_eq!(v["depth"]["received"], 3, "{v}");
        assert_eq!(v["depth"]["stored"], 1, "{v}");
        assert_eq!(v["depth"]["rejected_by"]["malformed"], 1, "{v}");
        assert_eq!(v["depth"]["rejected_by"]["out_of_range"], 1, "{v}");
        assert!(v.get("dvl").is_none());
    }

    #[test]
    fn a_flu_twist_becomes_an_frd_velocity() {
        let mut m = TwistWithCovarianceStamped::default();
        (
            m.twist.twist.linear.x,
            m.twist.twist.linear.y,
            m.twist.twist.linear.z,
        ) = (0.5, 0.2, -0.1);
        let v = velocity(&m, 5.0).expect("taken");
        assert_eq!(v.v.0, [0.5, -0.2, 0.1]);
        assert_eq!(v.std, None);
        for (i, var) in [(0, 0.01), (7, 0.04), (14, 0.09)] {
            m.twist.covariance.0[i] = var;
        }
        let s = velocity(&m, 5.0).expect("taken").std.expect("σ").0;
        assert!(
            (s[0] - 0.1).abs() < 1e-12 && (s[1] - 0.2).abs() < 1e-12 && (s[2] - 0.3).abs() < 1e-12
        );
        m.twist.covariance.0[7] = 0.0;
        assert_eq!(velocity(&m, 5.0), Err(Refusal::BadCovariance));
        m.twist.covariance.0[7] = 0.04;
        m.twist.twist.linear.x = 9.0;
        assert_eq!(velocity(&m, 5.0), Err(Refusal::OutOfRange));
        m.twist.twist.linear.x = f64::INFINITY;
        assert_eq!(velocity(&m, 5.0), Err(Refusal::NotFinite));
    }
}
