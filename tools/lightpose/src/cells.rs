//! Number cells of the Markdown tables `bench` and `crb` print, so both
//! write a bound the same way.

/// z of a 95 % two-sided interval: σ → half-width.
pub const Z95: f64 = 1.959964;

/// Three significant-ish digits, `1.2e3` from 1000 up, ∞ for a bound with
/// no information, — for nothing.
pub fn num(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() && v >= 1e3 => format!("{v:.1e}"),
        Some(v) if v.is_finite() && v >= 10.0 => format!("{v:.1}"),
        Some(v) if v.is_finite() => format!("{v:.3}"),
        Some(v) if v.is_infinite() => "∞".into(),
        _ => "—".into(),
    }
}
