//! A beacon's clock as the vehicle sees it: phase and frequency, followed
//! from frame to frame (a Kalman filter on the two), so that a weak frame
//! leans on the ones before it and the drift of the beacon's crystal
//! (±100 ppm) is learnt rather than assumed away.

/// Random walk of the beacon clock's frequency, relative, per √s: a
/// crystal warming by a few degrees over minutes moves by well under this.
const FREQ_WALK: f64 = 1e-7;
/// Random walk of its phase, cycles per √s: jitter and the light's path
/// changing with the vehicle's motion (nanoseconds), far below a sample.
const PHASE_WALK: f64 = 1e-5;
/// A gap in time longer than this starts the track over: the phase it
/// would predict is spread over the whole cycle anyway.
const MAX_GAP_S: f64 = 3600.0;

#[derive(Debug, Clone)]
pub struct Track {
    nominal_hz: f64,
    max_drift: f64,
    locked: bool,
    t: f64,
    /// Phase at `t`, cycles in [0, 1): the wave is on where
    /// frac(phase + freq·(τ − t)) < 1/2.
    phase: f64,
    freq: f64,
    /// Covariance of (phase, freq).
    p: [[f64; 2]; 2],
}

/// A prediction of the phase at a frame.
#[derive(Debug, Clone, Copy)]
pub struct Prediction {
    pub phase: f64,
    pub var: f64,
    pub freq: f64,
}

impl Track {
    pub fn new(nominal_hz: f64, max_drift: f64) -> Self {
        let mut t = Track {
            nominal_hz,
            max_drift,
            locked: false,
            t: 0.0,
            phase: 0.0,
            freq: nominal_hz,
            p: [[0.0; 2]; 2],
        };
        t.reset();
        t
    }

    /// Forget the beacon's phase (its frequency goes back to nominal).
    pub fn reset(&mut self) {
        self.locked = false;
        self.freq = self.nominal_hz;
        let sf = (self.max_drift * self.nominal_hz).max(1e-9 * self.nominal_hz);
        self.p = [[f64::INFINITY, 0.0], [0.0, sf * sf]];
    }

    pub fn locked(&self) -> bool {
        self.locked
    }

    pub fn freq(&self) -> f64 {
        self.freq
    }

    pub fn phase(&self) -> f64 {
        self.phase
    }

    pub fn phase_std(&self) -> f64 {
        self.p[0][0].sqrt()
    }

    pub fn freq_std(&self) -> f64 {
        self.p[1][1].sqrt()
    }

    /// The phase at time `t` (a frame's first sample) and its variance;
    /// infinite when there is no lock. Moves the track to `t`.
    pub fn predict(&mut self, t: f64) -> Prediction {
        let dt = t - self.t;
        if self.locked && !(0.0..=MAX_GAP_S).contains(&dt) {
            // Time went back (a log looped) or a long gap: start over.
            self.reset();
        }
        if self.locked {
            let [[a, b], [_, d]] = self.p;
            let qf = (FREQ_WALK * self.nominal_hz).powi(2);
            let qp = PHASE_WALK * PHASE_WALK;
            let p00 = a + 2.0 * dt * b + dt * dt * d + qp * dt + qf * dt * dt * dt / 3.0;
            let p01 = b + dt * d + qf * dt * dt / 2.0;
            let p11 = d + qf * dt;
            self.p = [[p00, p01], [p01, p11]];
            self.phase = (self.phase + self.freq * dt).rem_euclid(1.0);
        }
        self.t = t;
        Prediction {
            phase: self.phase,
            var: self.p[0][0],
            freq: self.freq,
        }
    }

    /// A measured phase at the time of the last prediction, with its
    /// variance (cycles²).
    pub fn update(&mut self, phase: f64, var: f64) {
        if !self.locked {
            self.locked = true;
            self.phase = phase.rem_euclid(1.0);
            self.p[0][0] = var;
            self.p[0][1] = 0.0;
            self.p[1][0] = 0.0;
            return;
        }
        let nu = wrap(phase - self.phase);
        let [[a, b], [_, d]] = self.p;
        let s = a + var;
        let (k0, k1) = (a / s, b / s);
        self.phase = (self.phase + k0 * nu).rem_euclid(1.0);
        let lim = self.max_drift * self.nominal_hz * 2.0;
        self.freq = (self.freq + k1 * nu).clamp(self.nominal_hz - lim, self.nominal_hz + lim);
        let p00 = (1.0 - k0) * a;
        let p01 = (1.0 - k0) * b;
        let p11 = d - k1 * b;
        self.p = [[p00, p01], [p01, p11.max(0.0)]];
    }
}

/// A phase difference into [−1/2, 1/2).
pub fn wrap(x: f64) -> f64 {
    (x + 0.5).rem_euclid(1.0) - 0.5
}
