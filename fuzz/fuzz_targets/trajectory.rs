//! Any bytes as a trajectory CSV: a trajectory whose knots increase in t
//! (and whose frame count is known at once), or a refusal on one line that
//! names the file and line and quotes at most an excerpt.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match lightpose_sim::Trajectory::read(data, "fuzz.csv") {
        Ok(t) => {
            assert!(t.knots().windows(2).all(|w| w[1].t > w[0].t));
            let _ = t.frame_count(5.0);
            let _ = t.kinematics((t.t0() + t.t_end()) / 2.0);
        }
        Err(e) => {
            let s = e.to_string();
            assert!(s.starts_with("fuzz.csv:") && !s.contains('\n'), "{s}");
            assert!(s.chars().count() < 400, "{} chars", s.len());
        }
    }
});
