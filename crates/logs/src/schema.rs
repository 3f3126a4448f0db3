//! The channels of a lightpose MCAP recording and their schemas: the
//! project's own objects (FORMATS.md) as JSON, and Foxglove's well-known
//! types so that its panels show a recording without any set-up. Every
//! channel has `json` message encoding and a `jsonschema` schema.
//!
//! The Foxglove schemas describe the fields of Foxglove's published types
//! (`foxglove.RawImage`, `foxglove.PoseInFrame`, `foxglove.FrameTransform`)
//! that lightpose fills; Foxglove picks a panel by the schema's name.

/// Message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// Metadata record that holds the log's HEADER line (key [`HEADER_KEY`]),
/// exactly as the JSONL log's first line.
pub const HEADER_METADATA: &str = "lightpose-header";
pub const HEADER_KEY: &str = "json";

/// Metadata record that maps the log time to the wall clock (a daemon's
/// recording: at its start, and again when the wall clock steps). Every
/// value a string; keys in [`clock_key`].
pub const CLOCK_METADATA: &str = "lightpose-clock";

/// Keys of the [`CLOCK_METADATA`] record.
pub mod clock_key {
    /// The frames' time base: `monotonic` (a board: seconds since the
    /// computer booted) or `source` (the simulator's or a replayed log's
    /// own time).
    pub const EPOCH: &str = "epoch";
    /// The pair, read together: `t` in the log's epoch (seconds), the same
    /// instant as an MCAP log time (integer nanoseconds), and Unix time
    /// (seconds) on the computer's wall clock.
    pub const T: &str = "t";
    pub const LOG_TIME: &str = "log_time";
    pub const UNIX: &str = "unix";
    /// `unix − t`: add it to a log time (in seconds) to get Unix time.
    pub const OFFSET: &str = "offset";
    /// Whether the kernel said the wall clock was synchronized (NTP, GPS):
    /// `true`, `false` or `unknown`.
    pub const SYNCED: &str = "synced";
    /// Why this record was written: `open`, `step` (the wall clock stepped
    /// against the monotonic clock) or `sync` (`synced` changed).
    pub const REASON: &str = "reason";
}

/// Topics. The first three carry the JSON objects of FORMATS.md; the rest
/// carry the same data in Foxglove's types.
pub mod topic {
    /// The FRAME object, exactly as the JSONL line.
    pub const FRAME: &str = "/lightpose/frame";
    /// The POSE object of each estimate.
    pub const POSE: &str = "/lightpose/pose";
    /// The daemon's STATUS object.
    pub const STATUS: &str = "/lightpose/status";
    /// The 5 × 5 counts as a `foxglove.RawImage` (mono16).
    pub const IMAGE: &str = "/lightpose/image";
    /// The estimated pose as a `foxglove.PoseInFrame` in frame `beacon`.
    pub const VEHICLE_POSE: &str = "/lightpose/vehicle_pose";
    /// The frame's truth (simulator, tank carriage) as a `foxglove.PoseInFrame`.
    pub const TRUTH_POSE: &str = "/lightpose/truth_pose";
    /// `beacon` → `vehicle` as a `foxglove.FrameTransform`.
    pub const TF: &str = "/lightpose/tf";
    /// Spec v3: each BURST (the raw samples of a frame), binary
    /// ([`BURST_LAYOUT`]).
    pub const BURST: &str = "/lightpose/burst";
    /// Spec v3: each demodulated frame, exactly its JSONL line.
    pub const DEMODULATED: &str = "/lightpose/demodulated";
}

/// Schema names.
pub mod name {
    pub const FRAME: &str = "lightpose.Frame";
    pub const POSE: &str = "lightpose.Pose";
    pub const STATUS: &str = "lightpose.Status";
    pub const RAW_IMAGE: &str = "foxglove.RawImage";
    pub const POSE_IN_FRAME: &str = "foxglove.PoseInFrame";
    pub const FRAME_TRANSFORM: &str = "foxglove.FrameTransform";
    pub const BURST: &str = "lightpose.Burst";
    pub const DEMODULATED: &str = "lightpose.DemodulatedFrame";
}

/// Foxglove reference frames: B of MODEL.md, V (FRD) of MODEL.md, and the
/// array seen as a camera (x right, y down, z forward: the 5 × 5 image as
/// seen from behind the array looking forward).
pub const BEACON_FRAME: &str = "beacon";
pub const VEHICLE_FRAME: &str = "vehicle";
pub const DOME_FRAME: &str = "dome";

pub const FRAME: &str = r#"{"title":"lightpose.Frame","description":"One capture of the 5 x 5 photodiode array (FORMATS.md, intensity log FRAME line)","type":"object","properties":{"class":{"const":"FRAME"},"seq":{"type":"integer","minimum":0,"description":"frame counter; a gap means frames were lost"},"t":{"type":"number","description":"seconds in the log's own epoch"},"counts":{"type":"array","items":{"type":"integer","minimum":0,"maximum":65535},"minItems":25,"maxItems":25,"description":"ADC counts, row-major, index 5*r + c"},"temp_c":{"type":["number","null"],"description":"water temperature, degrees C"},"truth":{"type":"object","description":"reference pose (simulator, tank carriage)","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"pitch":{"type":"number"},"yaw":{"type":"number"},"roll":{"type":"number","description":"degrees, starboard side down; absent: 0 (spec v3)"},"surge":{"type":"number"}},"required":["x","y","z","pitch","yaw"]},"attitude":{"type":"object","description":"attitude sensor, degrees, beam frame","properties":{"pitch":{"type":"number"},"yaw":{"type":"number"},"roll":{"type":"number","description":"absent: not measured (spec v3)"},"std":{"type":"object","properties":{"pitch":{"type":"number"},"yaw":{"type":"number"}}}},"required":["pitch","yaw"]},"depth":{"type":"object","description":"depth sensor: the vehicle's z in B, m","properties":{"z":{"type":"number"},"std":{"type":"object","properties":{"z":{"type":"number"}}}},"required":["z"]},"velocity":{"type":"object","description":"DVL velocity over ground in V (FRD), m/s","properties":{"fwd":{"type":"number"},"right":{"type":"number"},"down":{"type":"number"},"std":{"type":"object","properties":{"fwd":{"type":"number"},"right":{"type":"number"},"down":{"type":"number"}}}},"required":["fwd","right","down"]}},"required":["class","seq","t","counts"]}"#;

pub const POSE: &str = r#"{"title":"lightpose.Pose","description":"One estimate (FORMATS.md POSE message); fields not known are null","type":"object","properties":{"class":{"const":"POSE"},"seq":{"type":"integer","minimum":0},"t":{"type":["number","null"],"description":"t of the frame the estimate comes from"},"time":{"type":"number","description":"wall-clock capture time, Unix seconds"},"status":{"type":"string","description":"ok when every field is trustworthy, else why not"},"x":{"type":["number","null"]},"y":{"type":["number","null"]},"z":{"type":["number","null"]},"pitch":{"type":["number","null"],"description":"degrees"},"yaw":{"type":["number","null"],"description":"degrees"},"surge":{"type":["number","null"],"description":"m/s"},"roll":{"type":["number","null"],"description":"degrees, starboard side down; absent when nothing in the frame says roll (spec v3)"},"frame":{"type":"string","description":"the station's name (spec v3); absent for one beacon: B"},"beacons_seen":{"type":"array","items":{"type":["string","integer"]},"description":"the station's beacons whose images this estimate fused (spec v3; absent for one beacon)"},"std":{"type":"object","description":"1-sigma of each field where known","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"pitch":{"type":"number"},"yaw":{"type":"number"},"roll":{"type":"number"},"surge":{"type":"number"}}},"estimator":{"type":"string"}},"required":["class","seq","status"]}"#;

/// Spec v3: a demodulated frame (FORMATS.md: a FRAME whose counts are
/// replaced by each beacon's amplitudes, the ambient and the clipped counts).
pub const DEMODULATED: &str = r#"{"title":"lightpose.DemodulatedFrame","description":"One demodulated frame (FORMATS.md, spec v3: a FRAME line with beacons, ambient and clipped in place of counts)","type":"object","properties":{"class":{"const":"FRAME"},"seq":{"type":"integer","minimum":0},"t":{"type":"number","description":"the middle of the frame's samples, seconds"},"beacons":{"type":"array","items":{"type":"object","properties":{"id":{"type":"string"},"amplitude":{"type":"array","items":{"type":["number","null"]},"minItems":25,"maxItems":25,"description":"on level minus off level, counts, index 5*r + c"},"std":{"type":"array","items":{"type":["number","null"]},"minItems":25,"maxItems":25}},"required":["id","amplitude","std"]}},"ambient":{"type":"array","items":{"type":["number","null"]},"minItems":25,"maxItems":25,"description":"mean counts of what does not blink"},"clipped":{"type":"array","items":{"type":"integer","minimum":0},"minItems":25,"maxItems":25,"description":"samples at 0 or full scale"},"temp_c":{"type":["number","null"]},"truth":{"type":"object"},"attitude":{"type":"object"},"depth":{"type":"object"},"velocity":{"type":"object"}},"required":["class","seq","t","beacons","ambient","clipped"]}"#;

/// Message encoding of `/lightpose/burst` (binary, [`BURST_LAYOUT`]).
pub const BURST_MESSAGE_ENCODING: &str = "lightpose-burst-v1";
/// Schema encoding of `lightpose.Burst`: its data is [`BURST_LAYOUT`], the
/// layout in words (no schema language describes a packed sample block
/// that Foxglove would decode; a program reads it with a few lines of
/// `struct`, as tests/python's mcap check does).
pub const BURST_SCHEMA_ENCODING: &str = "lightpose-layout";

/// The layout of a `/lightpose/burst` message, every number little-endian.
pub const BURST_LAYOUT: &str = "lightpose.Burst v1: one BURST (FORMATS.md, spec v3) in little-endian binary.
offset size field
0      4    magic \"LPB1\"
4      8    seq (u64)
12     8    t (f64): time of the frame's first sample, s
20     2    channels (u16): 25, index 5*r + c
22     2    n (u16): samples per channel
24     1    adc_bits (u8)
25     1    cut (u8): how `side` and the samples make the BURST line: 0 = the line is side[..at] + '\"samples\":' + S + ',' + side[at..]; 1 = side[..at] + ',\"samples\":' + S + side[at..]; 2 = side is the line whole
26     4    at (u32): byte offset into side
30     4    side_len (u32)
34     side_len  side: UTF-8 JSON, the BURST object without its samples (cut 0, 1; its seq, t, temp_c, truth, attitude, depth, velocity), or the line whole (cut 2)
34+side_len  2*channels*n  samples: u16, channel-major (sample i of channel k at k*n + i)
S is the samples as JSON: [[..n integers..], ..25 arrays..], no spaces. Log time: t in ns.";

pub const STATUS: &str = r#"{"title":"lightpose.Status","description":"The daemon's STATUS report (once a second); its fields grow with the daemon, readers ignore what they do not know","type":"object","properties":{"class":{"const":"STATUS"},"seq":{"type":"integer"},"t":{"type":"number","description":"wall clock, Unix seconds"}},"required":["class"]}"#;

// Pieces the Foxglove schemas share, as literals so that the schemas can
// be constants (`concat!` takes literals only).
macro_rules! time {
    () => {
        r#"{"type":"object","title":"time","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#
    };
}
macro_rules! vector3 {
    () => {
        r#"{"title":"foxglove.Vector3","type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}},"required":["x","y","z"]}"#
    };
}
macro_rules! quaternion {
    () => {
        r#"{"title":"foxglove.Quaternion","type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}},"required":["x","y","z","w"]}"#
    };
}

/// `foxglove.RawImage`: the fields lightpose fills.
pub const RAW_IMAGE: &str = concat!(
    r#"{"title":"foxglove.RawImage","description":"A raw image","type":"object","properties":{"timestamp":"#,
    time!(),
    r#","frame_id":{"type":"string"},"width":{"type":"integer","minimum":0},"height":{"type":"integer","minimum":0},"encoding":{"type":"string"},"step":{"type":"integer","minimum":0},"data":{"type":"string","contentEncoding":"base64"}}}"#
);

/// `foxglove.PoseInFrame`.
pub const POSE_IN_FRAME: &str = concat!(
    r#"{"title":"foxglove.PoseInFrame","description":"A timestamped pose in a named frame","type":"object","properties":{"timestamp":"#,
    time!(),
    r#","frame_id":{"type":"string"},"pose":{"title":"foxglove.Pose","type":"object","properties":{"position":"#,
    vector3!(),
    r#","orientation":"#,
    quaternion!(),
    r#"},"required":["position","orientation"]}},"required":["timestamp","frame_id","pose"]}"#
);

/// `foxglove.FrameTransform`.
pub const FRAME_TRANSFORM: &str = concat!(
    r#"{"title":"foxglove.FrameTransform","description":"The position and orientation of a child frame in its parent","type":"object","properties":{"timestamp":"#,
    time!(),
    r#","parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},"translation":"#,
    vector3!(),
    r#","rotation":"#,
    quaternion!(),
    r#"},"required":["timestamp","parent_frame_id","child_frame_id","translation","rotation"]}"#
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_is_json_with_its_title() {
        for (text, title) in [
            (FRAME, name::FRAME),
            (POSE, name::POSE),
            (STATUS, name::STATUS),
            (RAW_IMAGE, name::RAW_IMAGE),
            (POSE_IN_FRAME, name::POSE_IN_FRAME),
            (FRAME_TRANSFORM, name::FRAME_TRANSFORM),
            (DEMODULATED, name::DEMODULATED),
        ] {
            let v: serde_json::Value = serde_json::from_str(text).expect(title);
            assert_eq!(v["title"], title);
            assert_eq!(v["type"], "object");
        }
    }
}
