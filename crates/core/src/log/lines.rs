//! Each line of a log into what it carries: a FRAME's counts and
//! fields, a BURST's samples, a demodulated frame's images, and the
//! readings and truth beside them, each refused or counted with its line.

use super::rawline::{self, RawLine, Reading, Std};
use super::readings::{parse_attitude, parse_depth, parse_velocity};
use super::{LogError, LogReader, Meta};
use crate::frame::full_scale;
use crate::samples::{MAX_BEACONS, MAX_SAMPLES_PER_FRAME};
use crate::textfile::excerpt;
use crate::{Angle, Frame, Pose, Truth, NDET};
use std::io::BufRead;

impl<R: BufRead> LogReader<R> {
    /// A reading of the frame, or none when it is absent or malformed (then
    /// counted and named: the frame keeps its light).
    fn reading<T>(
        &mut self,
        v: Option<&Reading>,
        fs: Option<&Std>,
        parse: fn(&Reading, Option<&Std>) -> Result<T, String>,
    ) -> Option<T> {
        // A null reading is `None` here (serde's `Option`).
        match v {
            None => None,
            Some(v) => match parse(v, fs) {
                Ok(r) => Some(r),
                Err(msg) => {
                    self.bad_readings += 1;
                    self.last_bad_reading = Some(format!("{}:{}: {msg}", self.name, self.line_no));
                    None
                }
            },
        }
    }

    /// A frame line's seq and t; `what` names its class in errors.
    fn seq_t(&self, raw: &RawLine<'_>, what: &str) -> Result<(u64, f64), LogError> {
        let seq = raw
            .seq
            .as_ref()
            .and_then(|v| v.as_u64())
            .ok_or_else(|| self.line_err(format!("{what} needs a non-negative integer seq")))?;
        let t = raw
            .t
            .filter(|t| t.is_finite())
            .ok_or_else(|| self.line_err(format!("{what} needs a finite number t")))?;
        Ok((seq, t))
    }

    /// What a frame line of any kind carries beside its light: the reported
    /// temperature, the truth and the vehicle's readings.
    fn meta_from(&mut self, raw: &RawLine<'_>) -> Result<Meta, LogError> {
        if let Some(tc) = raw.temp_c {
            if !tc.is_finite() {
                return Err(self.line_err("temp_c is not finite"));
            }
        }
        let truth = match &raw.truth {
            None => None,
            Some(tr) => {
                let vals = [tr.x, tr.y, tr.z, tr.pitch, tr.yaw];
                let opt_bad = |v: Option<f64>| v.is_some_and(|s| !s.is_finite());
                if vals.iter().any(|v| !v.is_finite()) || opt_bad(tr.surge) || opt_bad(tr.roll) {
                    return Err(self.line_err("truth has a value that is not finite"));
                }
                let mut pose = Pose::new(
                    tr.x,
                    tr.y,
                    tr.z,
                    Angle::from_deg(tr.pitch),
                    Angle::from_deg(tr.yaw),
                );
                if let Some(r) = tr.roll {
                    pose.roll = Angle::from_deg(r);
                }
                Some(Truth {
                    pose,
                    surge: tr.surge,
                })
            }
        };
        let fs = raw.std.as_ref();
        let attitude = self.reading(raw.attitude.as_ref(), fs, parse_attitude);
        let depth = self.reading(raw.depth.as_ref(), fs, parse_depth);
        let velocity = self.reading(raw.velocity.as_ref(), fs, parse_velocity);
        Ok(Meta {
            temp_c: raw.temp_c,
            truth,
            attitude,
            depth,
            velocity,
        })
    }

    pub(super) fn frame_from(&mut self, raw: RawLine<'_>) -> Result<Frame, LogError> {
        let (seq, t) = self.seq_t(&raw, "FRAME")?;
        let values = raw
            .counts
            .as_ref()
            .ok_or_else(|| self.line_err("FRAME has no counts"))?;
        if values.len != NDET {
            return Err(self.line_err(format!("counts has {} values, expected {NDET}", values.len)));
        }
        let fs = full_scale(self.header.adc_bits) as u64;
        let mut counts = [0u16; NDET];
        for (k, (v, c)) in values.values.iter().zip(counts.iter_mut()).enumerate() {
            match *v {
                Some(n) if n <= fs => *c = n as u16,
                _ => {
                    // The first value that is no integer is the one kept.
                    let v = match (v, &values.first_other) {
                        (Some(n), _) => n.to_string(),
                        (None, Some(other)) => other.to_string(),
                        (None, None) => String::new(),
                    };
                    let v = excerpt(&v, 40);
                    return Err(
                        self.line_err(format!("counts[{k}] = {v} is not an integer in 0..{fs}"))
                    );
                }
            }
        }
        let m = self.meta_from(&raw)?;
        Ok(Frame {
            seq,
            t,
            adc_bits: self.header.adc_bits,
            counts,
            temp_c: m.temp_c,
            truth: m.truth,
            attitude: m.attitude,
            depth: m.depth,
            velocity: m.velocity,
            amplitudes: None,
        })
    }

    /// A BURST line into `self.burst`: 25 arrays of exactly N (the header's
    /// sample_hz / rate_hz) counts, each in 0..full scale.
    pub(super) fn burst_from(&mut self, mut raw: RawLine<'_>) -> Result<(), LogError> {
        let (seq, t) = self.seq_t(&raw, "BURST")?;
        let n = self.header.samples_per_frame();
        let Some(mut s) = raw.samples.take() else {
            return Err(self.line_err("BURST has no samples"));
        };
        let checked = (|| {
            if s.too_many {
                return Err(format!(
                    "samples has more than {NDET} × {MAX_SAMPLES_PER_FRAME} values"
                ));
            }
            if s.channels != NDET {
                return Err(format!(
                    "samples has {} arrays, expected {NDET}",
                    s.channels
                ));
            }
            if let Some(k) = s.lens.iter().position(|&l| l != n) {
                return Err(format!(
                    "samples[{k}] has {} values, expected N = {n} (the header's sample_hz / rate_hz)",
                    s.lens[k]
                ));
            }
            let fs = full_scale(self.header.adc_bits);
            if let Some((k, i, v)) = &s.first_bad {
                let v = excerpt(&v.to_string(), 40);
                return Err(format!(
                    "samples[{k}][{i}] = {v} is not an integer in 0..{fs}"
                ));
            }
            if let Some(j) = s.flat.iter().position(|&c| c > fs) {
                return Err(format!(
                    "samples[{}][{}] = {} is not an integer in 0..{fs}",
                    j / n,
                    j % n,
                    s.flat[j]
                ));
            }
            Ok(())
        })();
        if let Err(msg) = checked {
            rawline::give_back(std::mem::take(&mut s.flat));
            return Err(self.line_err(msg));
        }
        let m = self.meta_from(&raw)?;
        let b = &mut self.burst;
        b.swap_samples(n, &mut s.flat);
        rawline::give_back(std::mem::take(&mut s.flat));
        b.seq = seq;
        b.t = t;
        b.adc_bits = self.header.adc_bits;
        b.temp_c = m.temp_c;
        b.truth = m.truth;
        b.attitude = m.attitude;
        b.depth = m.depth;
        b.velocity = m.velocity;
        Ok(())
    }

    /// A demodulated FRAME line into `self.demod`: beacons named in the
    /// header, once each, with 25 finite amplitudes and 25 finite std ≥ 0;
    /// 25 finite ambient levels; 25 clipped counts in 0..=N.
    pub(super) fn demod_from(&mut self, raw: RawLine<'_>) -> Result<(), LogError> {
        let (seq, t) = self.seq_t(&raw, "FRAME")?;
        let n = self.header.samples_per_frame() as u64;
        let checked = (|| -> Result<(), String> {
            let d = &mut *self.demod;
            let Some(bs) = raw.beacons.as_ref() else {
                return Err("FRAME has no counts".into());
            };
            if bs.len > MAX_BEACONS {
                return Err(format!(
                    "beacons has {} entries, at most {MAX_BEACONS}",
                    bs.len
                ));
            }
            if bs.len == 0 {
                return Err("beacons is empty".into());
            }
            let nums = |v: &Option<rawline::Nums>,
                        what: String,
                        min: f64|
             -> Result<[f64; NDET], String> {
                let v = v.as_ref().ok_or_else(|| format!("{what} is missing"))?;
                if v.len != NDET {
                    return Err(format!("{what} has {} values, expected {NDET}", v.len));
                }
                if let Some(k) = v.first_bad {
                    return Err(format!("{what}[{k}] is not a finite number"));
                }
                if let Some(k) = v.values.iter().position(|x| *x < min) {
                    return Err(format!("{what}[{k}] = {} is below {min}", v.values[k]));
                }
                Ok(v.values)
            };
            for (i, b) in bs.items[..bs.len].iter().enumerate() {
                let id =
                    b.id.as_ref()
                        .ok_or_else(|| format!("beacons[{i}] has no id"))?;
                let idx = self.header.beacon_index(&id.0).ok_or_else(|| {
                    format!(
                        "beacons[{i}]: id \"{}\" is not among the header's beacons",
                        excerpt(&id.0, 40)
                    )
                })?;
                if d.light.beacons[..i]
                    .iter()
                    .any(|o| o.beacon as usize == idx)
                {
                    return Err(format!(
                        "beacons[{i}]: id \"{}\" repeats",
                        excerpt(&id.0, 40)
                    ));
                }
                d.light.beacons[i].beacon = idx as u8;
                d.light.beacons[i].amplitude = nums(
                    &b.amplitude,
                    format!("beacons[{i}].amplitude"),
                    f64::NEG_INFINITY,
                )?;
                d.light.beacons[i].std = nums(&b.std, format!("beacons[{i}].std"), 0.0)?;
            }
            d.light.n_beacons = bs.len;
            d.light.ambient = nums(&raw.ambient, "ambient".into(), f64::NEG_INFINITY)?;
            let c = raw.clipped.as_ref().ok_or("clipped is missing")?;
            if c.len != NDET {
                return Err(format!("clipped has {} values, expected {NDET}", c.len));
            }
            for (k, (v, out)) in c.values.iter().zip(d.light.clipped.iter_mut()).enumerate() {
                match *v {
                    Some(x) if x <= n => *out = x as u32,
                    _ => {
                        return Err(format!(
                            "clipped[{k}] is not an integer in 0..={n} (samples per frame)"
                        ))
                    }
                }
            }
            Ok(())
        })();
        checked.map_err(|msg| self.line_err(msg))?;
        let m = self.meta_from(&raw)?;
        let d = &mut *self.demod;
        d.seq = seq;
        d.t = t;
        d.adc_bits = self.header.adc_bits;
        d.temp_c = m.temp_c;
        d.truth = m.truth;
        d.attitude = m.attitude;
        d.depth = m.depth;
        d.velocity = m.velocity;
        Ok(())
    }
}
