//! Diagnostic: per step of a paper case, the bias, RMS error, mean reported
//! σ and ±2σ coverage of an estimator, to see where and why coverage is
//! lost (docs/estimators.md, the tracker's section).
//!
//!   cargo run --release -p lightpose-analysis --example ridge_diag -- \
//!       SCENE TRAJECTORY CALIBRATION [RUNS] [ESTIMATOR] [AXES]
//!
//! AXES: comma-separated of x,y,z,pitch,yaw,surge (default z,pitch).
//! Environment: TRK = TOML of `[estimator.tracker]` settings to try,
//! SENSORS = the own sensors of the runs (none, attitude, depth,
//! attitude+depth, all; default: the scene's), QUIET = summary only,
//! OFF_AXIS = "LAT,ATT" (degrees): each run's truth moved off the
//! trajectory's knots by a constant y, z ~ N(0, (x₀·tan LAT)²) and pitch,
//! yaw ~ N(0, ATT²), to see whether the σ holds where the vehicle is not
//! on the runs' axis (the tracker's own start priors are 6° and 10°).
use lightpose_core::Angle;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Simulator, Trajectory};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        return Err(
            "usage: ridge_diag SCENE TRAJECTORY CALIBRATION [RUNS] [ESTIMATOR] [AXES]".into(),
        );
    }
    let (scene, traj, cal) = (&args[1], &args[2], &args[3]);
    let runs: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(200);
    let name = args.get(5).cloned().unwrap_or("tracker".into());
    let mut base = Scene::load(std::path::Path::new(scene))?;
    if let Ok(set) = std::env::var("SENSORS") {
        lightpose_analysis::sensors::SensorSet::parse(&set)
            .ok_or("SENSORS: none, attitude, depth, attitude+depth or all")?
            .apply(&mut base);
    }
    let traj = Trajectory::load(std::path::Path::new(traj))?;
    let mut cal = Calibration::load(std::path::Path::new(cal))?;
    if let Ok(t) = std::env::var("TRK") {
        let mut st = cal.estimator.clone().unwrap_or_default();
        st.tracker = toml::from_str(&t)?;
        cal.estimator = Some(st);
    }
    let off_axis: Option<(f64, f64)> = match std::env::var("OFF_AXIS") {
        Ok(v) => {
            let (a, b) = v.split_once(',').ok_or("OFF_AXIS: LAT,ATT in degrees")?;
            Some((a.trim().parse()?, b.trim().parse()?))
        }
        Err(_) => None,
    };
    let times: Vec<f64> = traj.frame_times(base.adc.rate_hz).collect();
    let n = times.len();
    // [step][axis] sums: err, err², σ, inside
    let mut acc = vec![[[0.0f64; 5]; 6]; n];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut status = std::collections::BTreeMap::new();
    // Each run's water is drawn about the calibration's: say so.
    let cal = cal.in_water_known_to(base.montecarlo.sigma_k_d, base.montecarlo.sigma_temp_c);
    let mut est = build_estimator(&name, &cal)?;
    for r in 0..runs {
        let mut s = base.clone();
        let n1: f64 = StandardNormal.sample(&mut rng);
        let n2: f64 = StandardNormal.sample(&mut rng);
        s.temp_c += s.montecarlo.sigma_temp_c * n1;
        s.light.k_d = (s.light.k_d + s.montecarlo.sigma_k_d * n2).max(0.0);
        let traj = match off_axis {
            Some(off) => moved_off_axis(&traj, off, &mut rng),
            None => traj.clone(),
        };
        let mut sim = Simulator::new(s, 1000 + r as u64);
        sim.set_reported_temp(Some(base.temp_c));
        est.reset();
        for (j, &t) in times.iter().enumerate() {
            let k = traj.kinematics(t);
            let (p, su) = (k.pose, k.surge());
            let f = sim.frame_moving(j as u64, t, &k);
            let e = est.estimate(&f);
            *status.entry(format!("{:?}", e.status)).or_insert(0usize) += 1;
            let tr = p.values_with_surge(su);
            let v = e.values();
            let sd = e.std.values();
            for a in 0..6 {
                if let (Some(v), Some(sd)) = (v[a], sd[a]) {
                    let err = v - tr[a];
                    acc[j][a][0] += err;
                    acc[j][a][1] += err * err;
                    acc[j][a][2] += sd;
                    acc[j][a][3] += (err.abs() <= 2.0 * sd) as u8 as f64;
                    acc[j][a][4] += 1.0;
                }
            }
        }
    }
    let axes = ["x", "y", "z", "pitch", "yaw", "surge"];
    let sel: Vec<usize> = args
        .get(6)
        .map(|s| {
            s.split(',')
                .filter_map(|a| axes.iter().position(|x| x == &a))
                .collect()
        })
        .unwrap_or(vec![2, 3]);
    print!("  t  ");
    for &a in &sel {
        print!("| {:>5} bias   rms  meanσ  cov ", axes[a]);
    }
    println!();
    let rn = runs as f64;
    let quiet = std::env::var("QUIET").is_ok();
    print!("ALL  ");
    for a in 0..6 {
        let inn: f64 = acc.iter().map(|r| r[a][3]).sum();
        let cnt: f64 = acc.iter().map(|r| r[a][4]).sum();
        let b = acc[n - 1][a][0] / rn;
        let rms = (acc[n - 1][a][1] / rn).sqrt();
        print!(
            "| {} cov {:4.1}% end bias {:6.3} rms {:6.3} ",
            axes[a],
            100.0 * inn / cnt,
            b,
            rms
        );
    }
    println!(" {status:?}");
    if quiet {
        return Ok(());
    }
    for j in 0..n {
        print!("{:5.1}", times[j]);
        for &a in &sel {
            let [s, s2, sd, inn, _] = acc[j][a];
            print!(
                "| {:8.3} {:6.3} {:6.3} {:4.0}% ",
                s / rn,
                (s2 / rn).sqrt(),
                sd / rn,
                100.0 * inn / rn
            );
        }
        println!();
    }
    Ok(())
}

/// `traj` moved by one draw of `OFF_AXIS`'s constant offsets.
fn moved_off_axis(
    traj: &Trajectory,
    (lat, att): (f64, f64),
    rng: &mut impl rand::Rng,
) -> Trajectory {
    let mut n = || -> f64 { StandardNormal.sample(&mut *rng) };
    let lateral = traj.knots()[0].pose.x * lat.to_radians().tan();
    let (dy, dz) = (lateral * n(), lateral * n());
    let (dp, dw) = (Angle::from_deg(att * n()), Angle::from_deg(att * n()));
    traj.moved(dy, dz, dp, dw)
}
