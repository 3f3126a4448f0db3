//! Steps 5–7 of a frame (docs/demodulator.md): with every beacon's phase
//! found, each channel's least-squares fit of the slow polynomials and the
//! beacons' square waves, which gives the amplitudes, their σ and the
//! level with every beacon off; a channel the common phase fits badly
//! refitted on its own. Apart from the search (`demod.rs`) because it
//! only reads the phases the search chose.

// Channels, beacons and matrix rows are indices into several arrays at once.
#![allow(clippy::needless_range_loop)]

use super::{Demodulator, QUANT_VAR};
use crate::config::MAX_BEACONS;
use crate::runs::{on_runs, overlap, turns};
use crate::scan::{Signal, Window};
use lightpose_core::samples::Demodulated;
use lightpose_core::NDET;

impl Demodulator {
    /// Steps 5–7: per channel the least-squares fit of the slow polynomials
    /// and every beacon's square wave at the phase found (the amplitudes,
    /// their σ from what the fit leaves, and the level with every beacon
    /// off), a channel the common phase fits badly refitted on its own, and
    /// each channel's noise kept for the next frame.
    pub(super) fn fit(&mut self, out: &mut Demodulated, full: u16) {
        let dof = (self.cfg.n - self.basis.len() - self.cfg.beacons.len()) as f64;
        let (phases, freqs) = (self.frame_phase, self.frame_freq);
        let mut first = [0.0; NDET];
        for (k, v) in first.iter_mut().enumerate() {
            *v = self.fit_channel(k, &phases, &freqs, out, full);
        }
        // Without a last frame, the channels' median: one board's noise.
        let mut sorted = first;
        sorted.sort_unstable_by(f64::total_cmp);
        let median = sorted[NDET / 2];
        for k in 0..NDET {
            let mut noise = first[k];
            // Six σ of the residual variance's own spread over the last
            // frame's.
            let prev = self.noise[k].unwrap_or(median);
            if out.light.clipped[k] == 0
                && noise > prev * (1.0 + 6.0 * (2.0 / dof).sqrt()) + QUANT_VAR
            {
                noise = self.refit(k, noise, &phases, &freqs, out, full);
            }
            self.noise[k] = Some(noise);
        }
    }

    /// Step 6. The common phase leaves far more than channel k's noise: an
    /// edge crossed one of its sample instants within the frame where the
    /// common phase and frequency do not put it (the channels' skew spreads
    /// the crossings over frames, and their places depend on a drift not
    /// learnt yet). The channel's own best phase within a sample of the
    /// common one (each beacon on what the others' fit leaves), kept only
    /// when it fits better; its noise.
    fn refit(
        &mut self,
        k: usize,
        noise: f64,
        phases: &[f64; MAX_BEACONS],
        freqs: &[f64; MAX_BEACONS],
        out: &mut Demodulated,
        full: u16,
    ) -> f64 {
        let nb = self.cfg.beacons.len();
        let (mut ph, mut fr) = (*phases, *freqs);
        let mut w = [0.0; NDET];
        w[k] = 1.0;
        for b in 0..nb {
            if nb > 1 {
                self.residual(k, b, phases, freqs, out);
            }
            let m = self.cfg.beacons[b].half_period;
            let wide = self.cfg.max_drift * self.cfg.beacons[b].mod_hz;
            let sf = self.tracks[b].freq_std().max(1e-12);
            let sig = if nb > 1 {
                Signal {
                    x: &self.ys,
                    sums: &self.ys_sum,
                    corr: Some(&self.corr),
                }
            } else {
                Signal {
                    x: &self.xs,
                    sums: &self.xs_sum,
                    corr: None,
                }
            };
            let mut best = (f64::NEG_INFINITY, phases[b], freqs[b]);
            for f in [0.0, -1.5 * sf, 1.5 * sf, -wide, wide] {
                let win = Window {
                    freq: freqs[b] + f,
                    center: phases[b],
                    half: 1.0 / (2 * m) as f64,
                    var: f64::INFINITY,
                    sample_hz: self.cfg.sample_hz,
                    skew_s: self.cfg.channel_skew_s,
                };
                let cell = self.scan.search(&sig, &w, &win);
                if cell.ll > best.0 {
                    best = (cell.ll, phases[b] + 0.5 * (cell.lo + cell.hi), win.freq);
                }
            }
            ph[b] = best.1.rem_euclid(1.0);
            fr[b] = best.2;
        }
        let mut kept = ([0.0; MAX_BEACONS], [0.0; MAX_BEACONS], out.light.ambient[k]);
        for (b, bo) in out.light.beacons[..nb].iter().enumerate() {
            kept.0[b] = bo.amplitude[k];
            kept.1[b] = bo.std[k];
        }
        let again = self.fit_channel(k, &ph, &fr, out, full);
        if again < noise {
            return again;
        }
        for (b, bo) in out.light.beacons[..nb].iter_mut().enumerate() {
            bo.amplitude[k] = kept.0[b];
            bo.std[k] = kept.1[b];
        }
        out.light.ambient[k] = kept.2;
        // The common phases' Lᵀu again, for a later residual.
        self.fit_channel(k, phases, freqs, out, full);
        noise
    }

    /// Channel k's fit at the beacons' phases and frequencies given; its
    /// noise variance. Every sum over a template is taken over its runs
    /// (prefix sums of the samples and of the polynomials).
    pub(super) fn fit_channel(
        &mut self,
        k: usize,
        phases: &[f64; MAX_BEACONS],
        freqs: &[f64; MAX_BEACONS],
        out: &mut Demodulated,
        full: u16,
    ) -> f64 {
        let n = self.cfg.n;
        let nb = self.cfg.beacons.len();
        let d = self.basis.len();
        let dof = (n - d - nb) as f64;
        let mut rhs = [0.0; MAX_BEACONS];
        let mut mean_u = [0.0; MAX_BEACONS];
        let mut on = [0usize; MAX_BEACONS];
        let mut first_on = [false; MAX_BEACONS];
        let mut g = [[0.0; MAX_BEACONS]; MAX_BEACONS];
        let sums = &self.xs_sum[k * (n + 1)..(k + 1) * (n + 1)];
        for b in 0..nb {
            let p0 = phases[b] + freqs[b] * k as f64 * self.cfg.channel_skew_s;
            let tb = &mut self.turns[b];
            first_on[b] = turns(p0, freqs[b] / self.cfg.sample_hz, n, tb);
            let lu = &mut self.fit_lu[(k * MAX_BEACONS + b) * d..(k * MAX_BEACONS + b + 1) * d];
            lu.iter_mut()
                .zip(self.scan.cum(n))
                .for_each(|(l, t)| *l = -0.5 * t);
            let mut raw = 0.0;
            for (s, e) in on_runs(first_on[b], tb, n) {
                raw += sums[e] - sums[s];
                on[b] += e - s;
                let (cs, ce) = (self.scan.cum(s), self.scan.cum(e));
                for j in 0..d {
                    lu[j] += ce[j] - cs[j];
                }
            }
            rhs[b] = raw - 0.5 * sums[n];
            mean_u[b] = (on[b] as f64 - 0.5 * n as f64) / n as f64;
        }
        // G = UᵀU − (LᵀU)ᵀ(LᵀU): the templates' Gram matrix once the slow
        // part is out; uᵀu = N/4, and for two beacons (on − ½)ᵀ(on − ½).
        let quarter = n as f64 / 4.0;
        for b in 0..nb {
            let lb = &self.fit_lu[(k * MAX_BEACONS + b) * d..(k * MAX_BEACONS + b + 1) * d];
            for c in 0..=b {
                let uu = if b == c {
                    quarter
                } else {
                    let both = overlap(first_on[b], &self.turns[b], first_on[c], &self.turns[c], n);
                    both as f64 - 0.5 * (on[b] + on[c]) as f64 + quarter
                };
                let lc = &self.fit_lu[(k * MAX_BEACONS + c) * d..(k * MAX_BEACONS + c + 1) * d];
                g[b][c] = uu - lb.iter().zip(lc).map(|(x, y)| x * y).sum::<f64>();
            }
        }
        match Cholesky::new(&g, nb) {
            Some(ch) => {
                let a = ch.solve(&rhs, nb);
                let fitted: f64 = (0..nb).map(|b| a[b] * rhs[b]).sum();
                let noise = ((self.energy[k] - fitted) / dof).max(QUANT_VAR);
                let mut off = self.mean[k];
                for b in 0..nb {
                    let mut std = (noise * ch.inverse_diag(b, nb)).sqrt();
                    if out.light.clipped[k] > 0 {
                        std = std.max(f64::from(full));
                    }
                    out.light.beacons[b].amplitude[k] = a[b];
                    out.light.beacons[b].std[k] = std;
                    off -= a[b] * (mean_u[b] + 0.5);
                }
                out.light.ambient[k] = off;
                noise
            }
            None => {
                // Not reached with whole periods (G ≈ N/4 · I); kept so
                // that no frame can panic here.
                let nb = out.light.n_beacons;
                for bo in out.light.beacons[..nb].iter_mut() {
                    bo.amplitude[k] = 0.0;
                    bo.std[k] = f64::from(full);
                }
                out.light.ambient[k] = self.mean[k];
                (self.energy[k] / dof).max(QUANT_VAR)
            }
        }
    }
}

/// Cholesky factor of a small symmetric positive definite matrix (the
/// lower triangle of `g` is read).
struct Cholesky {
    l: [[f64; MAX_BEACONS]; MAX_BEACONS],
}

impl Cholesky {
    fn new(g: &[[f64; MAX_BEACONS]; MAX_BEACONS], nb: usize) -> Option<Self> {
        let mut l = [[0.0; MAX_BEACONS]; MAX_BEACONS];
        for i in 0..nb {
            for j in 0..=i {
                let mut s = g[i][j];
                for q in 0..j {
                    s -= l[i][q] * l[j][q];
                }
                if i == j {
                    if !s.is_finite() || s <= 0.0 {
                        return None;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        Some(Cholesky { l })
    }

    fn solve(&self, b: &[f64; MAX_BEACONS], nb: usize) -> [f64; MAX_BEACONS] {
        let l = &self.l;
        let mut y = [0.0; MAX_BEACONS];
        for i in 0..nb {
            let mut s = b[i];
            for q in 0..i {
                s -= l[i][q] * y[q];
            }
            y[i] = s / l[i][i];
        }
        let mut x = [0.0; MAX_BEACONS];
        for i in (0..nb).rev() {
            let mut s = y[i];
            for q in i + 1..nb {
                s -= l[q][i] * x[q];
            }
            x[i] = s / l[i][i];
        }
        x
    }

    /// (G⁻¹)_bb.
    fn inverse_diag(&self, b: usize, nb: usize) -> f64 {
        let mut e = [0.0; MAX_BEACONS];
        e[b] = 1.0;
        self.solve(&e, nb)[b]
    }
}
