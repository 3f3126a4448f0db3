//! What an estimator says about one frame, and its POSE message
//! (FORMATS.md): fields that are not known are `null`, never NaN.

use serde::ser::{Serialize, SerializeMap, Serializer};

/// Why a pose is or is not trustworthy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// Every field is trustworthy.
    Ok,
    /// Too little light on the array to tell anything.
    NoLight,
    /// Pixels at full scale distort the image.
    Saturated,
    /// Outside the range of poses the calibration covered.
    OutOfRange,
    /// The estimator needs more frames before it can say everything.
    Initialising,
    /// The frame itself is unusable (wrong resolution, garbage).
    BadFrame,
    /// The solver did not converge.
    Diverged,
    /// The fields are given, but some lie along a direction the frames do
    /// not determine (without an attitude reading: y/yaw and z/pitch), so
    /// their std is not a guarantee.
    Unobservable,
    /// Daylight on the array is more than the estimator can tell from a
    /// steady beacon's light (spec v3): the ambient's level, fitted with
    /// the pose, leaves the pose too uncertain to give, or the array is
    /// lit beyond what the model of the ambient explains. A blinking
    /// beacon (demodulated) does not meet it.
    Daylight,
}

impl Status {
    pub const ALL: [Status; 9] = [
        Status::Ok,
        Status::NoLight,
        Status::Saturated,
        Status::OutOfRange,
        Status::Initialising,
        Status::BadFrame,
        Status::Diverged,
        Status::Unobservable,
        Status::Daylight,
    ];

    /// The word of FORMATS.md's `status` field.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::NoLight => "no_light",
            Status::Saturated => "saturated",
            Status::OutOfRange => "out_of_range",
            Status::Initialising => "initialising",
            Status::BadFrame => "bad_frame",
            Status::Diverged => "diverged",
            Status::Unobservable => "unobservable",
            Status::Daylight => "daylight",
        }
    }

    pub fn parse(s: &str) -> Option<Status> {
        Status::ALL.into_iter().find(|st| st.as_str() == s)
    }

    /// Position in [`Status::ALL`]: for tables of counts per status, sized
    /// `Status::ALL.len()` so that a new word cannot overrun them.
    pub fn index(self) -> usize {
        self as usize
    }
}

/// 1σ uncertainty of each field where the estimator knows it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StdDev {
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub z: Option<f64>,
    /// degrees
    pub pitch: Option<f64>,
    /// degrees
    pub yaw: Option<f64>,
    pub surge: Option<f64>,
    /// degrees (spec v3; not among [`StdDev::values`]' six)
    pub roll: Option<f64>,
}

impl StdDev {
    /// The six std's in message order (see [`PoseEstimate::values`]).
    pub fn values(&self) -> [Option<f64>; 6] {
        [self.x, self.y, self.z, self.pitch, self.yaw, self.surge]
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_none()
            && self.y.is_none()
            && self.z.is_none()
            && self.pitch.is_none()
            && self.yaw.is_none()
            && self.surge.is_none()
            && self.roll.is_none()
    }
}

/// Why an estimator refused one of a frame's own-sensor readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Refusal {
    /// A value is NaN or infinite.
    NotFinite,
    /// The reading's own `std` is not a positive finite number.
    BadStd,
    /// A value no vehicle that sees the beacon can have (e.g. 50 m/s).
    Implausible,
    /// Too far from what the estimator expects (innovation gate).
    Gate,
    /// At odds with the light over a window (a DVL whose range change the
    /// light's contradicts: mounted backwards, across the bow, in other
    /// units).
    Light,
}

impl Refusal {
    pub const ALL: [Refusal; 5] = [
        Refusal::NotFinite,
        Refusal::BadStd,
        Refusal::Implausible,
        Refusal::Gate,
        Refusal::Light,
    ];

    /// Short word for summaries and STATUS counters.
    pub fn as_str(self) -> &'static str {
        match self {
            Refusal::NotFinite => "not_finite",
            Refusal::BadStd => "bad_std",
            Refusal::Implausible => "implausible",
            Refusal::Gate => "gate",
            Refusal::Light => "light",
        }
    }

    /// Position in [`Refusal::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// What an estimator did with one of a frame's own-sensor readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ReadingUse {
    /// The frame carried no such reading (or the estimator did not say).
    #[default]
    Absent,
    /// The reading went into the estimate.
    Used,
    /// The frame carried it, but this estimator does not use it (by
    /// design or by its settings).
    Ignored,
    /// Refused, and why; the rest of the frame was still used.
    Refused(Refusal),
}

impl ReadingUse {
    /// Number of distinct outcomes: absent, used, ignored, then one per
    /// [`Refusal`], for tables of counts.
    pub const COUNT: usize = 3 + Refusal::ALL.len();

    /// Position among [`ReadingUse::COUNT`] outcomes.
    pub fn index(self) -> usize {
        match self {
            ReadingUse::Absent => 0,
            ReadingUse::Used => 1,
            ReadingUse::Ignored => 2,
            ReadingUse::Refused(r) => 3 + r.index(),
        }
    }

    /// The outcome at `index` (inverse of [`ReadingUse::index`]).
    pub fn from_index(index: usize) -> Option<ReadingUse> {
        match index {
            0 => Some(ReadingUse::Absent),
            1 => Some(ReadingUse::Used),
            2 => Some(ReadingUse::Ignored),
            i => Refusal::ALL.get(i - 3).map(|r| ReadingUse::Refused(*r)),
        }
    }

    /// `absent`, `used`, `ignored` or `refused_<reason>`.
    pub fn as_str(self) -> &'static str {
        match self {
            ReadingUse::Absent => "absent",
            ReadingUse::Used => "used",
            ReadingUse::Ignored => "ignored",
            ReadingUse::Refused(Refusal::NotFinite) => "refused_not_finite",
            ReadingUse::Refused(Refusal::BadStd) => "refused_bad_std",
            ReadingUse::Refused(Refusal::Implausible) => "refused_implausible",
            ReadingUse::Refused(Refusal::Gate) => "refused_gate",
            ReadingUse::Refused(Refusal::Light) => "refused_light",
        }
    }
}

/// Per-frame verdicts on the vehicle's own sensors (spec v2): what became
/// of the attitude, depth and velocity readings. Copy and fixed-size, so
/// that a caller counts them without allocating.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ReadingUses {
    pub attitude: ReadingUse,
    pub depth: ReadingUse,
    pub velocity: ReadingUse,
}

/// A docking station's name and its beacons' ids in the order of the
/// images (spec v3): what a POSE message names (`frame`, `beacons_seen`).
/// Interned ([`StationNames::interned`]): an estimate refers to it by a
/// `&'static`, so that it stays Copy and the frame thread allocates nothing.
#[derive(Debug, PartialEq, Eq)]
pub struct StationNames {
    pub name: String,
    pub beacons: Vec<String>,
}

impl StationNames {
    /// The one `&'static` copy of these names: made (and kept for the
    /// process's life) the first time they are asked for, the same one
    /// after. A daemon reloading its calibration keeps one per distinct
    /// station, not one per reload.
    pub fn interned(name: &str, beacons: &[String]) -> &'static StationNames {
        use std::sync::Mutex;
        static ALL: Mutex<Vec<&'static StationNames>> = Mutex::new(Vec::new());
        let want = StationNames {
            name: name.to_string(),
            beacons: beacons.to_vec(),
        };
        let mut all = ALL.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = all.iter().find(|n| ***n == want) {
            return n;
        }
        let n: &'static StationNames = Box::leak(Box::new(want));
        all.push(n);
        n
    }
}

/// Spec v3: which beacons of a docking station a frame saw, and how well.
/// On the wire as POSE's `frame` and `beacons_seen` (with the station's
/// [`StationNames`]); the SNRs are for STATUS and the tests. Copy and
/// fixed-size, so that the frame thread fills it without allocating. The
/// default, `station` 0, is "not a station": every single-beacon estimate.
///
/// How the mode is read (the status words stay those of one beacon):
/// [`StationSeen::mode`], from how many beacons were seen this frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StationSeen {
    /// How many beacons the station has (0: not a station).
    pub station: u8,
    /// The station's names, when the estimator was told them.
    pub names: Option<&'static StationNames>,
    /// Bit b: the station's beacon b was seen this frame (its image above
    /// the estimator's signal-to-noise threshold) and fused.
    pub seen: u32,
    /// Per beacon, Σ a²/σ² over its image's usable channels (0 for a
    /// beacon without an image this frame).
    pub snr2: [f32; crate::MAX_BEACONS],
}

/// What a station's light gave a frame's pose, from how many of its
/// beacons were seen ([`StationSeen::mode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StationMode {
    /// One beacon, no station: the single-beacon estimators.
    NotAStation,
    /// Three or more seen: the whole pose from the light.
    SixDof,
    /// Two seen: roll observable, the ridges broken.
    RollObservable,
    /// One seen: roll from the attitude reading or the roll prior.
    OneBeacon,
    /// None seen: the track predicted only (status `no_light`).
    Dark,
}

impl StationSeen {
    /// How many of the station's beacons were seen.
    pub fn count(&self) -> u32 {
        self.seen.count_ones()
    }

    pub fn mode(&self) -> StationMode {
        match (self.station, self.count()) {
            (0, _) => StationMode::NotAStation,
            (_, 0) => StationMode::Dark,
            (_, 1) => StationMode::OneBeacon,
            (_, 2) => StationMode::RollObservable,
            _ => StationMode::SixDof,
        }
    }
}

/// Names of the three readings, in [`ReadingUses::all`] order.
pub const READINGS: [&str; 3] = ["attitude", "depth", "velocity"];

impl ReadingUses {
    /// The three verdicts in [`READINGS`] order.
    pub fn all(&self) -> [ReadingUse; 3] {
        [self.attitude, self.depth, self.velocity]
    }

    /// These verdicts as seen against the frame they came from: a reading
    /// the frame carried but the estimator left `Absent` (one that says
    /// nothing about readings, like the paper's method) was `Ignored`.
    pub fn settled(&self, frame: &crate::Frame) -> ReadingUses {
        let settle = |u: ReadingUse, present: bool| match u {
            ReadingUse::Absent if present => ReadingUse::Ignored,
            u => u,
        };
        ReadingUses {
            attitude: settle(self.attitude, frame.attitude.is_some()),
            depth: settle(self.depth, frame.depth.is_some()),
            velocity: settle(self.velocity, frame.velocity.is_some()),
        }
    }
}

/// The own-sensor reading components whose agreement with the light the
/// tracker watches ([`Agreement`]), in order.
pub const CHECKED: [&str; 6] = ["pitch", "yaw", "depth", "fwd", "right", "down"];

/// How each own-sensor reading component has agreed with the light lately
/// (not on the wire: for STATUS, the replay summary and the log). A
/// reading that is biased rather than noisy (a depth sensor zeroed on
/// another day, a mis-surveyed beacon depth, an AHRS mounted askew) is
/// taken whole by a filter that believes its σ; what shows it is that its
/// innovations ν/√S, zero-mean for a reading as good as its σ, keep one
/// sign while the light pulls the other way.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Agreement {
    /// The mean of each [`CHECKED`] component's normalized innovation over
    /// the estimator's window; `None` until the window is full.
    pub mean: [Option<f64>; 6],
    /// Bit i: component i's window mean is past the limit: the reading and
    /// the light disagree by more than noise (kept through frames without
    /// the reading).
    pub suspect: u8,
    /// The DVL judged by the light's own range (the tracker's DVL check):
    /// the changes of range over the last window judged, m, the light's
    /// and the DVL's (alike for a good DVL; opposite for one mounted
    /// backwards).
    pub dvl_range_change_m: Option<[f64; 2]>,
    /// How far the DVL's track is turned from the light's, ° to
    /// starboard (the tracker's mounting check, with an attitude reading):
    /// about 0 for a good DVL, its mounting error for one turned.
    pub dvl_turned_deg: Option<f64>,
    /// The DVL stands refused for contradicting the light (its range or
    /// its track).
    pub dvl_refused: bool,
}

impl Agreement {
    /// What the DVL checks last judged, in words: "range over 5 s: light
    /// -1.20 m, DVL +1.05 m; its track turned +179° to starboard of the
    /// light's" (empty before either judged).
    pub fn dvl_said(&self) -> String {
        let range = self
            .dvl_range_change_m
            .map(|[l, d]| format!("range over 5 s: light {l:+.2} m, DVL {d:+.2} m"));
        let turned = self
            .dvl_turned_deg
            .map(|t| format!("its track turned {t:+.0}° to starboard of the light's"));
        let parts: Vec<String> = range.into_iter().chain(turned).collect();
        parts.join("; ")
    }
}

/// One estimate. Angles in degrees, as they go on the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseEstimate {
    pub seq: u64,
    pub t: f64,
    pub status: Status,
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub z: Option<f64>,
    pub pitch_deg: Option<f64>,
    pub yaw_deg: Option<f64>,
    pub surge: Option<f64>,
    /// Spec v3: the vehicle's roll, degrees, with its 1σ in `std.roll`.
    /// None when nothing in the frame says roll (every v1/v2 log, whose
    /// POSE lines stay as they were); not among [`PoseEstimate::values`]'
    /// six, which the v2 tables and coverage count.
    pub roll_deg: Option<f64>,
    pub std: StdDev,
    /// Name of the estimator that produced it.
    pub estimator: &'static str,
    /// What became of the frame's own-sensor readings (not on the wire:
    /// for counters such as STATUS and the replay summary).
    pub readings: ReadingUses,
    /// The channels the estimator left out of this frame as stuck, bit k
    /// for detector k = 5·row + col (not on the wire: for STATUS and the
    /// replay summary).
    pub excluded_channels: u32,
    /// How the own-sensor readings have agreed with the light lately (not
    /// on the wire; the tracker's, default elsewhere).
    pub agreement: Agreement,
    /// Spec v3: the station's beacons seen this frame (not on the wire;
    /// the default, "not a station", for one beacon).
    pub station: StationSeen,
}

/// Names of the six estimated fields, in message order.
pub const FIELDS: [&str; 6] = ["x", "y", "z", "pitch", "yaw", "surge"];

impl PoseEstimate {
    /// x, y, z (m), pitch, yaw (degrees), surge (m/s), in [`FIELDS`] order:
    /// for code that treats every axis alike (errors, coverage).
    pub fn values(&self) -> [Option<f64>; 6] {
        [
            self.x,
            self.y,
            self.z,
            self.pitch_deg,
            self.yaw_deg,
            self.surge,
        ]
    }

    /// An estimate that knows nothing but why.
    pub fn empty(seq: u64, t: f64, status: Status, estimator: &'static str) -> Self {
        PoseEstimate {
            seq,
            t,
            status,
            x: None,
            y: None,
            z: None,
            pitch_deg: None,
            yaw_deg: None,
            surge: None,
            std: StdDev::default(),
            estimator,
            readings: ReadingUses::default(),
            excluded_channels: 0,
            agreement: Agreement::default(),
            roll_deg: None,
            station: StationSeen::default(),
        }
    }

    /// Serialize as a POSE message, optionally with the wall-clock capture
    /// time (Unix seconds), into `out` (cleared first; reused by callers
    /// so that the hot path does not allocate once warm).
    pub fn write_json(&self, capture_unix: Option<f64>, out: &mut Vec<u8>) {
        out.clear();
        let msg = PoseMessage {
            est: self,
            capture_unix,
        };
        // Writing into a Vec cannot fail and every value is finite or null.
        if serde_json::to_writer(&mut *out, &msg).is_err() {
            out.clear();
        }
    }
}

struct PoseMessage<'a> {
    est: &'a PoseEstimate,
    capture_unix: Option<f64>,
}

struct StdMessage<'a>(&'a StdDev);

fn fin(v: Option<f64>) -> Option<f64> {
    v.and_then(crate::finite)
}

impl Serialize for StdMessage<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let d = self.0;
        let mut m = s.serialize_map(None)?;
        for (k, v) in [
            ("x", d.x),
            ("y", d.y),
            ("z", d.z),
            ("pitch", d.pitch),
            ("yaw", d.yaw),
            ("surge", d.surge),
            ("roll", d.roll),
        ] {
            if let Some(v) = fin(v) {
                m.serialize_entry(k, &v)?;
            }
        }
        m.end()
    }
}

/// The ids of the beacons seen (their indices where the names are not
/// known).
struct SeenList<'a>(&'a StationSeen);

impl Serialize for SeenList<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let st = self.0;
        let mut seq = s.serialize_seq(Some(st.count() as usize))?;
        for b in 0..usize::from(st.station).min(32) {
            if st.seen & (1 << b) == 0 {
                continue;
            }
            match st.names.and_then(|n| n.beacons.get(b)) {
                Some(id) => seq.serialize_element(id.as_str())?,
                None => seq.serialize_element(&b)?,
            }
        }
        seq.end()
    }
}

impl Serialize for PoseMessage<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let e = self.est;
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("class", "POSE")?;
        m.serialize_entry("seq", &e.seq)?;
        m.serialize_entry("t", &crate::finite(e.t))?;
        if let Some(w) = self.capture_unix.and_then(crate::finite) {
            m.serialize_entry("time", &w)?;
        }
        m.serialize_entry("status", e.status.as_str())?;
        m.serialize_entry("x", &fin(e.x))?;
        m.serialize_entry("y", &fin(e.y))?;
        m.serialize_entry("z", &fin(e.z))?;
        m.serialize_entry("pitch", &fin(e.pitch_deg))?;
        m.serialize_entry("yaw", &fin(e.yaw_deg))?;
        m.serialize_entry("surge", &fin(e.surge))?;
        // Spec v3's roll only where the estimate has one: a v2 log's POSE
        // lines are byte for byte what they were.
        if let Some(r) = fin(e.roll_deg) {
            m.serialize_entry("roll", &r)?;
        }
        if !e.std.is_empty() {
            m.serialize_entry("std", &StdMessage(&e.std))?;
        }
        m.serialize_entry("estimator", e.estimator)?;
        // Spec v3: a station's pose is in its frame D, named; a single
        // beacon's (B) says nothing, so v1/v2 POSE lines stay as they were.
        if e.station.station > 0 {
            let name = e.station.names.map_or("D", |n| n.name.as_str());
            m.serialize_entry("frame", name)?;
            m.serialize_entry("beacons_seen", &SeenList(&e.station))?;
        }
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_becomes_null_and_std_only_when_known() {
        let mut e = PoseEstimate::empty(3, 0.6, Status::NoLight, "moments");
        e.x = Some(f64::NAN);
        e.y = Some(0.25);
        let mut buf = Vec::new();
        e.write_json(None, &mut buf);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["class"], "POSE");
        assert_eq!(v["status"], "no_light");
        assert!(v["x"].is_null());
        assert_eq!(v["y"], 0.25);
        assert!(v.get("std").is_none());
        e.std.x = Some(0.2);
        e.std.y = Some(f64::INFINITY);
        e.write_json(Some(1.7e9), &mut buf);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["std"]["x"], 0.2);
        assert!(v["std"].get("y").is_none());
        assert_eq!(v["time"], 1.7e9);
    }

    #[test]
    fn a_station_pose_names_its_frame_and_the_beacons_seen() {
        let mut e = PoseEstimate::empty(3, 0.6, Status::Ok, "tracker");
        let mut plain = Vec::new();
        e.write_json(None, &mut plain);
        let v: serde_json::Value = serde_json::from_slice(&plain).unwrap();
        assert!(v.get("frame").is_none() && v.get("beacons_seen").is_none());

        let ids = ["top", "starboard", "bottom", "port"].map(String::from);
        let names = StationNames::interned("dock", &ids);
        assert!(std::ptr::eq(names, StationNames::interned("dock", &ids)));
        assert!(!std::ptr::eq(names, StationNames::interned("dock2", &ids)));
        e.station = StationSeen {
            station: 4,
            names: Some(names),
            seen: 0b1011,
            snr2: [0.0; crate::MAX_BEACONS],
        };
        let mut buf = Vec::new();
        e.write_json(None, &mut buf);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["frame"], "dock");
        assert_eq!(
            v["beacons_seen"],
            serde_json::json!(["top", "starboard", "port"])
        );
        // Names not told: D and the images' indices.
        e.station.names = None;
        e.write_json(None, &mut buf);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["frame"], "D");
        assert_eq!(v["beacons_seen"], serde_json::json!([0, 1, 3]));
    }

    #[test]
    fn values_follow_the_message_order() {
        let mut e = PoseEstimate::empty(0, 0.0, Status::Ok, "t");
        (e.x, e.pitch_deg, e.surge) = (Some(1.0), Some(2.0), Some(3.0));
        e.std.yaw = Some(4.0);
        assert_eq!(
            e.values(),
            [Some(1.0), None, None, Some(2.0), None, Some(3.0)]
        );
        assert_eq!(
            e.std.values()[FIELDS.iter().position(|f| *f == "yaw").unwrap()],
            Some(4.0)
        );
    }

    #[test]
    fn reading_outcomes_index_round_trip_and_settle() {
        for i in 0..ReadingUse::COUNT {
            let u = ReadingUse::from_index(i).unwrap();
            assert_eq!(u.index(), i);
        }
        assert_eq!(ReadingUse::from_index(ReadingUse::COUNT), None);
        assert_eq!(ReadingUse::Refused(Refusal::Gate).as_str(), "refused_gate");
        let mut f = crate::Frame::new(0, 0.0, 10, [0; crate::NDET]);
        f.depth = Some(crate::DepthReading::new(0.1));
        let v = ReadingUses::default().settled(&f);
        assert_eq!(v.depth, ReadingUse::Ignored);
        assert_eq!(v.attitude, ReadingUse::Absent);
        let used = ReadingUses {
            depth: ReadingUse::Used,
            ..ReadingUses::default()
        };
        assert_eq!(used.settled(&f).depth, ReadingUse::Used);
    }

    #[test]
    fn status_words_round_trip() {
        for (i, s) in Status::ALL.into_iter().enumerate() {
            assert_eq!(s.index(), i);
            assert_eq!(Status::parse(s.as_str()), Some(s));
        }
        assert_eq!(Status::parse("unobservable"), Some(Status::Unobservable));
        assert_eq!(Status::parse("bogus"), None);
    }

    /// The mode is read from the beacons seen; one beacon's estimate is
    /// "not a station" and its POSE line is what it was.
    #[test]
    fn a_station_s_mode_follows_the_beacons_seen() {
        let e = PoseEstimate::empty(1, 0.1, Status::Ok, "tracker");
        assert_eq!(e.station.mode(), StationMode::NotAStation);
        let mut plain = Vec::new();
        e.write_json(None, &mut plain);
        let mut st = e;
        st.station.station = 4;
        let mut with = Vec::new();
        st.write_json(None, &mut with);
        // A station's POSE is one beacon's with its frame and beacons
        // after (a_station_pose_names_its_frame_and_the_beacons_seen).
        assert!(with.starts_with(&plain[..plain.len() - 1]), "a prefix");
        assert!(!plain.windows(7).any(|w| w == b"\"frame\""));
        for (seen, mode) in [
            (0b0000, StationMode::Dark),
            (0b0100, StationMode::OneBeacon),
            (0b1001, StationMode::RollObservable),
            (0b1011, StationMode::SixDof),
            (0b1111, StationMode::SixDof),
        ] {
            st.station.seen = seen;
            assert_eq!(st.station.mode(), mode, "{seen:b}");
            assert_eq!(st.station.count(), seen.count_ones());
        }
    }
}
