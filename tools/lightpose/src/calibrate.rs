//! `lightpose calibrate`: fit the paper's pose equations from truth-labelled
//! sweep logs and write the calibration file. Thin: the fit is
//! `lightpose_pipeline::calibrate`; this parses arguments, names bad lines
//! on stderr and prints what was chosen.

use anyhow::Context;
use lightpose_pipeline::calibrate::{calibrate, CalibrateOptions};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// A truth-labelled sweep log (repeat for more; a dark sweep is used
    /// for the offsets).
    #[arg(long = "sweep", required = true)]
    sweeps: Vec<PathBuf>,
    /// A log of beacon-off frames: each channel's dark offset.
    #[arg(long)]
    dark: Option<PathBuf>,
    /// Where to write the calibration (TOML).
    #[arg(long)]
    out: PathBuf,
    /// ADC reference in volts, if the logs' headers do not say.
    #[arg(long, default_value_t = 5.0)]
    v_ref: f64,
    /// Water temperature assumed for frames that report none, °C.
    #[arg(long, default_value_t = 20.0)]
    default_temp: f64,
    /// Samples the surge estimate is smoothed over (the paper used 10).
    #[arg(long, default_value_t = 10)]
    surge_window: usize,
}

pub fn run(a: CalibrateArgs) -> anyhow::Result<()> {
    let mut opts = CalibrateOptions::new(a.sweeps);
    opts.dark = a.dark;
    opts.v_ref = a.v_ref;
    opts.default_temp_c = a.default_temp;
    opts.surge_window = a.surge_window;
    opts.created_by = format!("lightpose calibrate {}", env!("CARGO_PKG_VERSION"));
    let mut bad = 0u64;
    let cal = calibrate(&opts, |e| {
        bad += 1;
        if bad <= 20 {
            eprintln!("lightpose: skipped {e}");
        }
    })?;
    if bad > 20 {
        eprintln!("lightpose: skipped {} more bad lines", bad - 20);
    }
    cal.save(&a.out)
        .with_context(|| format!("writing {}", a.out.display()))?;
    let f = &cal.fits;
    eprintln!(
        "calibrated from {} frames (dark offsets: {}) -> {}",
        cal.meta.frames,
        cal.meta.dark_source,
        a.out.display()
    );
    eprintln!(
        "  x     : PD = {:.4} exp(-{:.5} x)  R2 {:.4}  sigma {:.3} m",
        f.x.a1, f.x.b1, f.x.r2, f.x.sigma_m
    );
    for (name, fit, unit) in [
        ("pitch", &f.pitch, "deg"),
        ("yaw", &f.yaw, "deg"),
        ("y", &f.y, "m"),
        ("z", &f.z, "m"),
    ] {
        eprintln!(
            "  {name:<6}: {:.5} * {} + {:.5}  R2 {:.4}  sigma {:.4} {unit}",
            fit.a, fit.feature, fit.b, fit.r2, fit.sigma
        );
    }
    Ok(())
}
