//! What each estimate says about its frame's inputs, into STATUS and the
//! log: the own-sensor readings' verdicts, the channels left out as stuck,
//! and the reading check (a reading that disagrees with the light). Lines
//! are written when a set changes, not per frame: a stuck channel stays
//! stuck, a biased sensor stays biased.

use crate::stats::Stats;
use lightpose_core::{Frame, PoseEstimate, ReadingUse, CHECKED, COLS, NDET};
use std::sync::atomic::Ordering::Relaxed;

/// Count `est`'s verdicts on `frame` into `stats`, and log a change of
/// the stuck channels or of the disagreeing readings.
pub(super) fn count(stats: &Stats, est: &PoseEstimate, frame: &Frame) {
    for (counts, u) in stats.readings.iter().zip(est.readings.settled(frame).all()) {
        if u != ReadingUse::Absent {
            counts[u.index()].fetch_add(1, Relaxed);
        }
    }
    channels(stats, est.excluded_channels, frame.seq);
    agreement(stats, est, frame.seq);
    dvl(stats, est, frame.seq);
    station(stats, est, frame.seq);
}

/// A docking station's beacons: which the estimate saw, into STATUS, and
/// a line when a beacon is lost or seen again (the mode it leaves).
fn station(stats: &Stats, est: &PoseEstimate, seq: u64) {
    use lightpose_core::StationMode;
    let st = &est.station;
    if st.station == 0 {
        return;
    }
    let s = &stats.station;
    s.size.store(st.station, Relaxed);
    for (bits, v) in s.snr2_bits.iter().zip(st.snr2) {
        bits.store(f64::from(v).to_bits(), Relaxed);
    }
    let mode = match st.mode() {
        StationMode::SixDof => 0,
        StationMode::RollObservable => 1,
        StationMode::OneBeacon => 2,
        StationMode::Dark | StationMode::NotAStation => 3,
    };
    s.by_mode[mode].fetch_add(1, Relaxed);
    let seen = u64::from(st.seen);
    let before = s.seen_now.swap(seen, Relaxed);
    if before == seen
        && s.names
            .lock()
            .is_ok_and(|n| n.is_some() || st.names.is_none())
    {
        return;
    }
    if let Ok(mut n) = s.names.lock() {
        *n = st.names;
    }
    let id = |b: usize| {
        st.names
            .and_then(|n| n.beacons.get(b).cloned())
            .unwrap_or_else(|| format!("#{b}"))
    };
    let list = |mask: u64| -> Vec<String> {
        (0..usize::from(st.station).min(32))
            .filter(|b| mask & (1 << b) != 0)
            .map(id)
            .collect()
    };
    let (lost, back) = (list(before & !seen), list(seen & !before));
    let what = match st.mode() {
        StationMode::SixDof => "the whole pose from the light",
        StationMode::RollObservable => "roll observable, the pose from two beacons",
        StationMode::OneBeacon => "one beacon: roll from the attitude reading or its prior",
        _ => "no beacon: the track predicted only",
    };
    if lost.is_empty() && back.is_empty() {
        return;
    }
    tracing::info!(
        seq,
        "station: {} of {} beacons seen (lost {lost:?}, seen again {back:?}): {what}",
        st.count(),
        st.station
    );
}

/// The DVL checks: what they last judged into STATUS, and a line when the
/// DVL is refused for contradicting the light or taken again.
fn dvl(stats: &Stats, est: &PoseEstimate, seq: u64) {
    let a = &est.agreement;
    if let Some(c) = a.dvl_range_change_m {
        for (bits, v) in stats.dvl_change_bits.iter().zip(c) {
            bits.store(v.to_bits(), Relaxed);
        }
        stats.dvl_change_known.store(true, Relaxed);
    }
    if let Some(d) = a.dvl_turned_deg {
        stats.dvl_turned_bits.store(d.to_bits(), Relaxed);
        stats.dvl_turned_known.store(true, Relaxed);
    }
    let before = stats.dvl_refused_now.swap(a.dvl_refused, Relaxed);
    if before == a.dvl_refused {
        return;
    }
    let said = a.dvl_said();
    if a.dvl_refused {
        tracing::warn!(
            seq,
            "the DVL contradicts the light ({said}): refused until they agree; check its mounting rotation, axes and units (STATUS readings.check.dvl, readings.velocity.refused.light)"
        );
    } else {
        tracing::info!(
            seq,
            "the DVL agrees with the light again ({said}): taken again"
        );
    }
}

fn channels(stats: &Stats, mask: u32, seq: u64) {
    for (k, n) in stats.excluded.iter().enumerate() {
        if mask & (1 << k) != 0 {
            n.fetch_add(1, Relaxed);
        }
    }
    let before = stats.excluded_now.swap(u64::from(mask), Relaxed);
    if before == u64::from(mask) {
        return;
    }
    let rc = |m: u64| {
        (0..NDET)
            .filter(|k| m & (1 << k) != 0)
            .map(|k| format!("({},{})", k / COLS, k % COLS))
            .collect::<Vec<_>>()
            .join(" ")
    };
    if mask != 0 {
        tracing::warn!(
            seq,
            "channel(s) {} left out as stuck: a bound no light gives beside its neighbours, or a count frozen past its noise (STATUS channels)",
            rc(u64::from(mask))
        );
    } else {
        tracing::info!(seq, "channel(s) {} read again", rc(before));
    }
}

fn agreement(stats: &Stats, est: &PoseEstimate, seq: u64) {
    let a = &est.agreement;
    let mut known = 0u64;
    for i in 0..CHECKED.len() {
        if let Some(m) = a.mean[i] {
            stats.agreement_bits[i].store(m.to_bits(), Relaxed);
            known |= 1 << i;
        }
        if a.suspect & (1 << i) != 0 {
            stats.disagreed[i].fetch_add(1, Relaxed);
        }
    }
    stats.agreement_known.store(known, Relaxed);
    let now = u64::from(a.suspect);
    let before = stats.disagreeing_now.swap(now, Relaxed);
    if before == now {
        return;
    }
    let names = |m: u64| {
        (0..CHECKED.len())
            .filter(|i| m & (1 << i) != 0)
            .map(|i| match a.mean[i] {
                Some(v) => format!("{} ({v:+.2})", CHECKED[i]),
                None => CHECKED[i].to_string(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    if now & !before != 0 {
        tracing::warn!(
            seq,
            "own-sensor reading(s) {} disagree with the light: their innovations keep one sign (window mean of ν/√S); a bias, not noise: with depth and attitude both read, the tracker learns the offset of the one the light finds off (STATUS estimator.depth_offset, pitch_offset); check the sensor's zero and mounting, and beacon_depth_m (docs/estimators.md \"Sensor offsets\") (STATUS readings.check)",
            names(now & !before)
        );
    }
    if before & !now != 0 {
        tracing::info!(
            seq,
            "own-sensor reading(s) {} agree with the light again",
            names(before & !now)
        );
    }
}
