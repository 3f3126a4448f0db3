//! What a stand-in Water Linked DVL says: the vendor's JSON velocity
//! report, one a line (as the A50 sends it over TCP).

/// A bottom-track velocity report of `v` (m/s, the DVL's frame),
/// `velocity_valid: valid`, sent `latency_us` after its time of validity.
pub fn report(v: [f64; 3], valid: bool, latency_us: u64) -> String {
    let validity: u64 = 1638191471563017;
    format!(
        concat!(
            r#"{{"time": 99.8, "vx": {}, "vy": {}, "vz": {}, "fom": 0.002, "#,
            r#""covariance": [[1e-4, 0.0, 0.0], [0.0, 4e-4, 0.0], [0.0, 0.0, 9e-4]], "#,
            r#""altitude": 1.8, "transducers": [{{"id": 0, "velocity": 0.1, "distance": 2.0, "rssi": -30.0, "nsd": -90.0, "beam_valid": true}}], "#,
            r#""velocity_valid": {}, "status": 0, "tracking_mode": "bottom", "format": "json_v3.2", "type": "velocity", "#,
            r#""time_of_validity": {}, "time_of_transmission": {}}}"#,
            "\n"
        ),
        v[0],
        v[1],
        v[2],
        valid,
        validity,
        validity + latency_us
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn one_line_with_its_values_and_times() {
        let r = super::report([0.3, 0.05, -0.02], false, 50_000);
        assert_eq!(r.lines().count(), 1, "{r}");
        assert!(r.ends_with('\n'), "{r}");
        for part in [
            r#""vx": 0.3, "vy": 0.05, "vz": -0.02,"#,
            r#""velocity_valid": false,"#,
            r#""time_of_validity": 1638191471563017, "time_of_transmission": 1638191471613017}"#,
        ] {
            assert!(r.contains(part), "{part} in {r}");
        }
    }
}
