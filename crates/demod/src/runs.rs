//! A sampled square wave as the samples where it turns. A beacon's
//! template over a frame is ±1/2 in runs of about m samples, so every sum
//! the demodulator takes over it (its product with the samples, with the
//! slow polynomials, with another beacon's wave) is a sum over runs of
//! prefix sums: O(turns) instead of O(N), and no per-sample `floor`.

/// The samples where the wave on iff ⌊2·(p0 + g·i)⌋ is even (sample i at
/// phase p0 + g·i cycles, g = mod_hz / sample_hz ≤ 1/2 · (1 + drift))
/// changes state, in order, into `out`; and whether it is on at sample 0.
/// Two edges between the same two samples (m = 1 with a fast clock) turn
/// it twice: no turn.
pub fn turns(p0: f64, g: f64, n: usize, out: &mut Vec<u32>) -> bool {
    out.clear();
    let b0 = (2.0 * p0).floor();
    if n > 1 {
        let top = (2.0 * (p0 + g * (n - 1) as f64)).floor();
        let mut b = b0 + 1.0;
        while b <= top {
            // The first sample at or past the edge b/2 (1..n-1 but for
            // rounding, which the clamp keeps in the frame).
            let i = ((0.5 * b - p0) / g).ceil().clamp(1.0, (n - 1) as f64) as u32;
            if out.last() == Some(&i) {
                out.pop();
            } else {
                out.push(i);
            }
            b += 1.0;
        }
    }
    (b0 as i64) & 1 == 0
}

/// The runs `[a, b)` where the wave is on, given its first state and turns.
pub fn on_runs(
    first_on: bool,
    turns: &[u32],
    n: usize,
) -> impl Iterator<Item = (usize, usize)> + '_ {
    let start = if first_on { 0 } else { 1 };
    (start..=turns.len()).step_by(2).map(move |r| {
        let a = if r == 0 { 0 } else { turns[r - 1] as usize };
        let b = if r == turns.len() {
            n
        } else {
            turns[r] as usize
        };
        (a, b)
    })
}

/// How many samples two waves are both on.
pub fn overlap(a_on: bool, a: &[u32], b_on: bool, b: &[u32], n: usize) -> usize {
    let (mut ia, mut ib, mut pos, mut sa, mut sb, mut count) = (0, 0, 0, a_on, b_on, 0);
    loop {
        let na = a.get(ia).map_or(n, |&v| v as usize);
        let nb = b.get(ib).map_or(n, |&v| v as usize);
        let next = na.min(nb);
        if sa && sb {
            count += next - pos;
        }
        if next >= n {
            return count;
        }
        pos = next;
        if na == next {
            sa = !sa;
            ia += 1;
        }
        if nb == next {
            sb = !sb;
            ib += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn direct(p0: f64, g: f64, n: usize) -> Vec<bool> {
        (0..n)
            .map(|i| ((2.0 * (p0 + g * i as f64)).floor() as i64) & 1 == 0)
            .collect()
    }

    fn expand(first: bool, t: &[u32], n: usize) -> Vec<bool> {
        let mut v = vec![false; n];
        for (a, b) in on_runs(first, t, n) {
            v[a..b].iter_mut().for_each(|x| *x = true);
        }
        v
    }

    #[test]
    fn runs_equal_the_samples() {
        let mut t = Vec::new();
        for &(p0, g, n) in &[
            (0.123, 1.0 / 16.0, 400),
            (0.9, 0.5 * (1.0 + 1e-2), 400),
            (0.31, 0.5 * (1.0 - 1e-4), 160),
            (3.77, 1.0 / 40.0 * (1.0 + 9e-5), 800),
            (0.0001, 0.25, 1),
        ] {
            let first = turns(p0, g, n, &mut t);
            assert_eq!(expand(first, &t, n), direct(p0, g, n), "p0 {p0} g {g}");
        }
    }

    #[test]
    fn overlap_counts_both_on() {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let n = 480;
        let fa = turns(0.2, 1.0 / 12.0, n, &mut a);
        let fb = turns(0.7, 1.0 / 48.0, n, &mut b);
        let (da, db) = (direct(0.2, 1.0 / 12.0, n), direct(0.7, 1.0 / 48.0, n));
        let want = da.iter().zip(&db).filter(|(x, y)| **x && **y).count();
        assert_eq!(overlap(fa, &a, fb, &b, n), want);
    }
}
