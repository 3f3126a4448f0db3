//! `lightpose replay`: run an estimator over a recorded intensity log and
//! write one POSE line per frame; with `--report`, the error of each axis
//! against the log's truth. Thin: the loop is `lightpose_pipeline::replay`.

use crate::guard;
use crate::stdout::{out, outln};
use anyhow::Context;
use lightpose_core::FrameLog;
use lightpose_core::Status;
use lightpose_pipeline::{build_estimator, reads_frames_of, replay, Calibration, ReplaySummary};
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ReplayArgs {
    /// Calibration file written by `lightpose calibrate`.
    #[arg(long)]
    calibration: PathBuf,
    /// Intensity log to replay (.jsonl or .mcap).
    #[arg(long)]
    log: PathBuf,
    /// Where to write the POSE lines (JSON Lines).
    #[arg(long)]
    out: PathBuf,
    /// Estimator: auto (the tracker when the calibration has a light model,
    /// else moments), moments (the paper's), model (single frame) or tracker.
    #[arg(long, default_value = "auto", value_parser = ["auto", "moments", "model", "tracker"])]
    estimator: String,
    /// Print each axis's error against the log's truth.
    #[arg(long)]
    report: bool,
}

pub fn run(a: ReplayArgs) -> anyhow::Result<()> {
    guard::not_an_input(&a.out, &[("log", &a.log), ("calibration", &a.calibration)])?;
    let cal = Calibration::load(&a.calibration)?;
    let mut est = build_estimator(&a.estimator, &cal)?;
    // Say which one "auto" chose, before any output.
    eprintln!("lightpose: estimator {} ({})", est.name(), a.estimator);
    // Every kind of frame (FORMATS.md): BURSTs demodulated on the way.
    let mut log = lightpose_demod::LogFrames::new(lightpose_logs::LogFile::open(&a.log)?)
        .map_err(lightpose_core::LogError::from)?;
    if let Some(d) = log.demodulator() {
        let c = d.config();
        eprintln!(
            "lightpose: demodulating {} samples a frame at {} Hz ({} beacon(s))",
            c.n,
            c.sample_hz,
            c.beacons.len()
        );
    }
    reads_frames_of(est.as_ref(), &cal, log.header().adc_bits)
        .map_err(|m| anyhow::anyhow!("{}: {m}", a.log.display()))?;
    let file = File::create(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut out = BufWriter::new(file);
    let mut shown = 0u32;
    let mut first_bad = None;
    let s = replay(est.as_mut(), &mut log, &mut out, |e| {
        shown += 1;
        if shown <= 20 {
            eprintln!("lightpose: skipped {e}");
        }
        first_bad.get_or_insert_with(|| e.to_string());
    })
    .with_context(|| format!("replaying {} into {}", a.log.display(), a.out.display()))?;
    if s.frames == 0 {
        // Nothing replayed is a failure, not an empty success.
        let mut why = match (s.bad_lines, first_bad) {
            (0, _) => "the log has no frames".to_string(),
            (1, Some(m)) => format!("1 bad line ({m})"),
            (n, Some(m)) => format!("{n} bad lines (first: {m})"),
            (n, None) => format!("{n} bad lines"),
        };
        if let Some(cut) = s.cut {
            why.push_str(&format!("; {cut}"));
        }
        anyhow::bail!("{}: no frame could be replayed: {why}", a.log.display());
    }
    say_summary(&a, &s);
    say_log(&a, &log);
    if a.report {
        match &s.report {
            Some(r) => out!("{r}"),
            None if s.truth_frames > 0 => eprintln!(
                "lightpose: {}: {} frames carry truth but no estimate gave a value to \
                 compare, no error report",
                a.log.display(),
                s.truth_frames
            ),
            None => eprintln!(
                "lightpose: {}: no truth in the log, no error report",
                a.log.display()
            ),
        }
        if let Some(line) = s.readings_line() {
            outln!("readings: {line}");
        }
        if let Some(line) = s.agreement_line() {
            outln!("reading check, window mean of ν/√S farthest from 0: {line}");
        }
    }
    Ok(())
}

/// The summary of a replay on stderr: poses by status, readings, stuck
/// channels, the water learned, dropped readings, a cut.
fn say_summary(a: &ReplayArgs, s: &ReplaySummary) {
    let statuses: Vec<String> = Status::ALL
        .iter()
        .zip(s.status)
        .filter(|(_, n)| *n > 0)
        .map(|(st, n)| format!("{n} {}", st.as_str()))
        .collect();
    eprintln!(
        "{} poses -> {} ({}); {} bad lines skipped",
        s.frames,
        a.out.display(),
        statuses.join(", "),
        s.bad_lines
    );
    // Once: on stdout with the report it belongs to, else on stderr.
    if let (false, Some(line)) = (a.report, s.readings_line()) {
        eprintln!("readings: {line}");
    }
    if let Some(line) = s.excluded_line() {
        eprintln!(
            "lightpose: {}: channel(s) left out as stuck (a bound no light gives beside its neighbours, or a count frozen past its noise): {line}",
            a.log.display()
        );
    }
    if let Some(line) = s.disagreed_line() {
        eprintln!(
            "lightpose: {}: own-sensor reading(s) disagree with the light (a bias, not noise: check the sensor's zero and mounting, and beacon_depth_m, or tell the tracker depth_offset_sigma_m / pitch_offset_sigma_deg to estimate it): {line}",
            a.log.display()
        );
    }
    if let Some(line) = s.dvl_refused_line() {
        eprintln!(
            "lightpose: {}: the DVL contradicted the light (its change of range, or its track's direction: mounted turned, its axes or units wrong; check its mounting rotation, axes and units), so it was refused: {line}",
            a.log.display()
        );
    }
    if let Some(k) = s.water_k_d {
        eprintln!("water: K_D {k:.3} m⁻¹ as the estimator learned it by the end");
    }
    if let Some((m, sd)) = s.pitch_offset_deg {
        eprintln!(
            "attitude: the sensor's pitch offset {m:+.2} ± {sd:.2}° as the estimator learned it by the end (its pitch less it is the vehicle's)"
        );
    }
    if let Some((m, sd)) = s.depth_offset {
        eprintln!(
            "depth: the sensor's offset {m:+.3} ± {sd:.3} m as the estimator learned it by the end (readings less it are the vehicle's z)"
        );
    }
    if s.bad_readings > 0 {
        let first = s
            .first_bad_reading
            .as_deref()
            .map(|m| format!("; first: {m}"))
            .unwrap_or_default();
        eprintln!(
            "lightpose: {}: {} malformed sensor readings dropped (frames kept{first})",
            a.log.display(),
            s.bad_readings
        );
    }
    if let Some(cut) = s.cut {
        eprintln!("lightpose: {}: {cut}", a.log.display());
    }
}

/// What the log itself said on the way: other classes passed over, time
/// jumps, lone glitches, gaps in seq.
fn say_log(a: &ReplayArgs, log: &dyn FrameLog) {
    if let Some(first) = log.first_other() {
        let n = log.other_records();
        let what = if n == 1 {
            "line of another class"
        } else {
            "lines of other classes"
        };
        eprintln!(
            "lightpose: {}: {n} {what} passed over (first: {first})",
            a.log.display()
        );
    }
    let order = log.order();
    if order.jumps() > 0 {
        eprintln!(
            "lightpose: {}: t jumped forward by more than {} s {} time(s) (kept)",
            a.log.display(),
            order.max_gap_s(),
            order.jumps()
        );
    }
    if order.glitches() > 0 {
        eprintln!(
            "lightpose: {}: {} lone frame(s) out of line in seq or t gone over (the frames after them kept)",
            a.log.display(),
            order.glitches()
        );
    }
    let gaps = log.seq_gaps();
    if gaps.0 > 0 {
        eprintln!(
            "lightpose: {}: {} gaps in seq, {} frames lost",
            a.log.display(),
            gaps.0,
            gaps.1
        );
    }
}
