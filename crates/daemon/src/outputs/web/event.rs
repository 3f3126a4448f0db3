//! The page's live event: one JSON object the feed thread formats at most
//! `updates_hz` times a second (docs/blueos.md lists its fields). The pose
//! is the POSE datagram's own text, so that the page shows exactly what
//! subscribers get; the image is the frame's counts and, for a frame
//! demodulated from its samples (spec v3), each beacon's amplitudes, so
//! that several beacons are several heatmaps.

use lightpose_core::{Frame, NDET};
use serde_json::{json, Value};

/// Values for the page, rounded: 0.01 count is below any noise, and the
/// event stays a few kB at 10 a second over a tether.
fn round2(v: f64) -> Value {
    lightpose_core::finite(v).map_or(Value::Null, |v| ((v * 100.0).round() / 100.0).into())
}

/// The event of `frame`, whose POSE text is `pose` (taken at `wall_unix`).
pub fn live_event(frame: &Frame, pose: &[u8], wall_unix: f64) -> Vec<u8> {
    let beacons: Vec<Value> = frame
        .amplitudes
        .as_ref()
        .map(|a| {
            a.beacons()
                .iter()
                .map(|b| {
                    json!({
                        "beacon": b.beacon,
                        "amplitude": b.amplitude.iter().map(|v| round2(*v)).collect::<Vec<_>>(),
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    let image = json!({
        "seq": frame.seq,
        "t": round2(frame.t),
        "wall": wall_unix,
        "adc_bits": frame.adc_bits,
        "full_scale": frame.full_scale(),
        "counts": &frame.counts[..NDET],
        "beacons": beacons,
        "temp_c": frame.temp_c.and_then(lightpose_core::finite),
        // Which of the vehicle's readings rode on this frame (fresh
        // enough to be attached): the page's freshness row.
        "with": {
            "attitude": frame.attitude.is_some(),
            "depth": frame.depth.is_some(),
            "velocity": frame.velocity.is_some(),
        },
    });
    let mut out = Vec::with_capacity(2048);
    out.extend_from_slice(b"{\"pose\":");
    if pose.is_empty() {
        out.extend_from_slice(b"null");
    } else {
        out.extend_from_slice(pose);
    }
    out.extend_from_slice(b",\"frame\":");
    // Writing a Value into a Vec cannot fail.
    let _ = serde_json::to_writer(&mut out, &image);
    out.push(b'}');
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::samples::{Amplitudes, BeaconAmplitude};

    #[test]
    fn an_event_holds_the_pose_text_the_counts_and_each_beacon() {
        let mut f = Frame::new(7, 1.25, 12, [100; NDET]);
        let mut a = Amplitudes {
            n_beacons: 2,
            ..Amplitudes::default()
        };
        a.beacons[0] = BeaconAmplitude {
            beacon: 0,
            amplitude: [10.004; NDET],
            std: [1.0; NDET],
        };
        a.beacons[1] = BeaconAmplitude {
            beacon: 1,
            amplitude: [f64::NAN; NDET],
            std: [1.0; NDET],
        };
        f.amplitudes = Some(a);
        let pose = br#"{"class":"POSE","seq":7,"status":"ok"}"#;
        let v: Value = serde_json::from_slice(&live_event(&f, pose, 2.5)).unwrap();
        assert_eq!(v["pose"]["status"], "ok");
        assert_eq!(v["frame"]["seq"], 7);
        assert_eq!(v["frame"]["full_scale"], 4095);
        assert_eq!(v["frame"]["counts"].as_array().unwrap().len(), 25);
        let b = v["frame"]["beacons"].as_array().unwrap();
        assert_eq!(b.len(), 2);
        assert_eq!(b[0]["amplitude"][3], 10.0);
        assert_eq!(
            b[1]["amplitude"][0],
            Value::Null,
            "NaN is null, not bad JSON"
        );
        assert_eq!(v["frame"]["with"]["depth"], false);
        let none: Value = serde_json::from_slice(&live_event(&f, b"", 2.5)).unwrap();
        assert_eq!(none["pose"], Value::Null);
    }
}
