//! A STATUS as `/diagnostics` (`diagnostic_msgs/msg/DiagnosticArray`), one
//! conversion for the ROS 2 node and for the ROS 2 bags the recorder
//! writes, so that what a bag holds is what a live subscriber heard.

use super::{DiagnosticArray, DiagnosticStatus, Header, KeyValue, Time};
use super::{DIAG_ERROR, DIAG_OK, DIAG_WARN};
use lightpose_core::{PoseEstimate, Status};
use serde_json::Value;

/// The latest estimate's status, for the diagnostics' level.
#[derive(Debug, Default, Clone, Copy)]
pub struct LastEstimate {
    pub status: Option<Status>,
    pub seq: u64,
}

impl LastEstimate {
    pub fn observe(&mut self, est: &PoseEstimate) {
        self.status = Some(est.status);
        self.seq = est.seq;
    }
}

/// One DiagnosticStatus from a STATUS (`json`) stamped `stamp`: its
/// scalars flattened to `a.b` keys; OK while the latest estimate is `ok`,
/// WARN otherwise, ERROR before any frame. A STATUS that is not JSON gives
/// a diagnostic with no values, never none.
pub fn diagnostics(json: &[u8], last: &LastEstimate, stamp: Time) -> DiagnosticArray {
    let mut values = Vec::new();
    if let Ok(v) = serde_json::from_slice::<Value>(json) {
        flatten("", &v, &mut values, 0);
    }
    let (level, message) = match last.status {
        Some(Status::Ok) => (DIAG_OK, format!("ok (frame {})", last.seq)),
        Some(s) => (DIAG_WARN, format!("{} (frame {})", s.as_str(), last.seq)),
        None => (DIAG_ERROR, "no frame yet".to_string()),
    };
    DiagnosticArray {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        status: vec![DiagnosticStatus {
            level,
            name: "lightposed".into(),
            message,
            hardware_id: "lightpose".into(),
            values,
        }],
    }
}

fn flatten(prefix: &str, v: &Value, out: &mut Vec<KeyValue>, depth: usize) {
    let key = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        Value::Object(m) if depth < 3 => {
            for (k, x) in m {
                flatten(&key(k), x, out, depth + 1);
            }
        }
        Value::Object(_) | Value::Array(_) => {}
        Value::String(s) => out.push(KeyValue {
            key: prefix.to_string(),
            value: s.clone(),
        }),
        other => out.push(KeyValue {
            key: prefix.to_string(),
            value: other.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagnostics_flatten_status_and_say_the_last_status() {
        let status = br#"{"class":"STATUS","frames":12,"latency":{"p99_ms":0.2},"backend":{"kind":"sim"},"list":[1]}"#;
        let mut last = LastEstimate::default();
        let stamp = Time::from_unix(1.5e9);
        let d = diagnostics(status, &last, stamp);
        assert_eq!(d.status[0].level, DIAG_ERROR);
        assert_eq!(d.header.stamp, stamp);
        last.status = Some(Status::Ok);
        last.seq = 12;
        let d = diagnostics(status, &last, stamp);
        let s = &d.status[0];
        assert_eq!((s.level, s.message.as_str()), (DIAG_OK, "ok (frame 12)"));
        let kv: Vec<(&str, &str)> = s
            .values
            .iter()
            .map(|k| (k.key.as_str(), k.value.as_str()))
            .collect();
        assert!(kv.contains(&("frames", "12")), "{kv:?}");
        assert!(kv.contains(&("latency.p99_ms", "0.2")), "{kv:?}");
        assert!(kv.contains(&("backend.kind", "sim")), "{kv:?}");
        assert!(!kv.iter().any(|(k, _)| *k == "list"));
        // Not JSON: no values, still a diagnostic.
        assert!(diagnostics(b"garbage", &last, stamp).status[0]
            .values
            .is_empty());
    }
}
