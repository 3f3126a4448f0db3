//! `lightpose calibrate`: fit the paper's pose equations from truth-labelled
//! sweep logs and write the calibration file. Thin: the fit is
//! `lightpose_pipeline::calibration`; this parses arguments, names bad lines
//! on stderr and prints what was chosen, and the light model's parameters
//! with their standard errors (or one line saying which one the sweeps could
//! not determine). With `--station` (spec v3) the light model is a docking
//! station's: each beacon's, with the check of its survey.

use crate::guard;
use anyhow::Context;
use lightpose_pipeline::calibration::{
    calibrate_full, fit_station_sweeps, CalibrateOptions, ParamEstimate, PhysicalCalibration,
    ScatterFit, Station, StationCalibration, StationFitOptions,
};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// A truth-labelled sweep log, .jsonl or .mcap (repeat for more; a
    /// dark sweep is used for the offsets).
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
    /// Light model's scattering term: auto (kept when the data demand it),
    /// on or off.
    #[arg(long, default_value = "auto", value_parser = ["auto", "on", "off"])]
    scattering: String,
    /// Skip the light model ([physical]): the paper's coefficients only.
    #[arg(long)]
    no_physical: bool,
    /// Spec v3: the docking station's survey (FORMATS.md "station file"):
    /// fit each beacon's V1 and sigma_b, the gains, K_D and sigma_R from
    /// the station's sweeps, check the survey, and carry the station in
    /// the calibration ([station]).
    #[arg(long, conflicts_with = "no_physical")]
    station: Option<PathBuf>,
}

pub fn run(a: CalibrateArgs) -> anyhow::Result<()> {
    let mut inputs: Vec<(&str, &std::path::Path)> =
        a.sweeps.iter().map(|p| ("sweep", p.as_path())).collect();
    inputs.extend(a.dark.as_deref().map(|p| ("dark", p)));
    inputs.extend(a.station.as_deref().map(|p| ("station", p)));
    guard::not_an_input(&a.out, &inputs)?;
    check_options(&a)?;
    // The survey is read before any sweep: a bad file is refused at once.
    let station = a.station.as_deref().map(read_station).transpose()?;
    let mut opts = CalibrateOptions::new(a.sweeps.clone());
    opts.dark = a.dark;
    opts.v_ref = a.v_ref;
    opts.default_temp_c = a.default_temp;
    opts.surge_window = a.surge_window;
    opts.created_by = format!("lightpose calibrate {}", env!("CARGO_PKG_VERSION"));
    let scattering = match a.scattering.as_str() {
        "on" => ScatterFit::On,
        "off" => ScatterFit::Off,
        _ => ScatterFit::Auto,
    };
    if a.no_physical || station.is_some() {
        // A station's light is fitted by its own fit, below.
        opts.physical = None;
    } else if let Some(p) = opts.physical.as_mut() {
        p.scattering = scattering;
    }
    let mut bad = 0u64;
    let out = calibrate_full(&opts, |e| {
        bad += 1;
        if bad <= 20 {
            eprintln!("lightpose: skipped {e}");
        }
    })?;
    let mut cal = out.cal;
    if bad > 20 {
        eprintln!("lightpose: skipped {} more bad lines", bad - 20);
    }
    if let Some((st, text, file)) = &station {
        let o = StationFitOptions {
            scattering,
            v_ref: cal.scene.v_ref,
            ..StationFitOptions::default()
        };
        let (fitted, _) = fit_station_sweeps(&a.sweeps, st, text, file, &o)
            .with_context(|| format!("calibrating station {} ({file})", st.name))?;
        let e = fitted.estimator_settings(cal.estimator.take().unwrap_or_default());
        cal.estimator = Some(e);
        cal.physical = Some(fitted.physical);
        cal.station = Some(fitted.station);
        eprintln!(
            "  x_range: [{:.2}, {:.2}] m (the sweeps' span, for the model and the tracker)",
            fitted.x_span[0], fitted.x_span[1]
        );
    }
    // The error names the file.
    cal.save(&a.out).context("writing the calibration")?;
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
    for n in &out.notes {
        eprintln!("lightpose: note: {n}");
    }
    if let Some(e) = &out.physical_skipped {
        eprintln!("lightpose: warning: no [physical] light model written: {e}");
    }
    if let Some(p) = &cal.physical {
        print_light_model(p);
    }
    if let Some(st) = cal.station() {
        print_station(st);
    }
    Ok(())
}

/// The station file, its text and its name (for errors at its lines).
fn read_station(path: &std::path::Path) -> anyhow::Result<(Station, String, String)> {
    let file = path.display().to_string();
    let text = lightpose_core::textfile::read_text(path)?;
    let st = Station::parse(&text, &file)?;
    Ok((st, text, file))
}

/// Each beacon's fitted light and the check of its survey: a suspect
/// survey as a warning.
fn print_station(st: &StationCalibration) {
    let pm = |v: &ParamEstimate| format!("{:.4} ± {:.4}", v.value, v.std);
    eprintln!(
        "  station {} ({} beacons, {} poses, {} frames, chi2/dof {:.2}):",
        st.name,
        st.beacons.len(),
        st.poses,
        st.frames,
        st.chi2_per_dof
    );
    for b in &st.beacons {
        eprintln!(
            "    {:<10} V1 = {} V·m²  sigma_b = {} deg  model error {:.2} %",
            b.id,
            pm(&b.v1),
            pm(&b.sigma_b_deg),
            100.0 * b.model_rel
        );
    }
    for b in &st.beacons {
        let c = &b.survey_check;
        if c.suspect {
            eprintln!("lightpose: warning: {}", c.note);
        } else {
            eprintln!("    {}", c.note);
        }
    }
}

/// The fitted light model, each parameter with its standard error.
fn print_light_model(p: &PhysicalCalibration) {
    let pm = |v: &ParamEstimate| format!("{:.5} ± {:.5}", v.value, v.std);
    eprintln!(
        "  light model ({} poses, {} frames, chi2/dof {:.2}):",
        p.poses, p.frames, p.chi2_per_dof
    );
    eprintln!("    V1      = {} V", pm(&p.v1));
    eprintln!("    sigma_b = {} deg", pm(&p.sigma_b_deg));
    eprintln!("    sigma_R = {} deg", pm(&p.sigma_r_deg));
    eprintln!("    K_D     = {} 1/m", pm(&p.k_d));
    match (&p.omega, &p.sigma_h_deg) {
        (Some(o), Some(h)) => {
            eprintln!("    omega   = {}", pm(o));
            eprintln!("    sigma_h = {} deg", pm(h));
        }
        _ => eprintln!("    scattering: not modelled"),
    }
    let worst = |v: &[ParamEstimate]| v.iter().map(|g| g.std).fold(0.0, f64::max);
    let spread = |v: &[ParamEstimate]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), g| {
                (l.min(g.value), h.max(g.value))
            });
        format!("{lo:.4}..{hi:.4}")
    };
    eprintln!(
        "    gains   {} (worst ± {:.5}); offsets {} V (worst ± {:.5})",
        spread(&p.gain),
        worst(&p.gain),
        spread(&p.offset_v),
        worst(&p.offset_v)
    );
    eprintln!(
        "    noise: sigma_e {:.4} V, kappa {:.5} V",
        p.sigma_e_v, p.kappa_v
    );
}

/// The options are the user's: name them, rather than let the fit say it
/// found no light (a v_ref of 0) or gave a NaN temperature.
fn check_options(a: &CalibrateArgs) -> anyhow::Result<()> {
    if !(a.v_ref.is_finite() && a.v_ref > 0.0 && a.v_ref <= 100.0) {
        anyhow::bail!(
            "--v-ref {:?}: an ADC's reference is more than 0 and at most 100 V",
            a.v_ref
        );
    }
    let water = lightpose_core::light::WATER_TEMP_C;
    if !water.contains(&a.default_temp) {
        anyhow::bail!(
            "--default-temp {}: not a water temperature ({}..{} °C)",
            a.default_temp,
            water.start(),
            water.end()
        );
    }
    Ok(())
}
