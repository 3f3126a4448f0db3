//! `lightpose convert`: an intensity log from one container to the other
//! (JSON Lines ↔ MCAP, by extension), with the POSE lines of the JSONL side
//! as a file of their own; with `--ros2`, a ROS 2 bag of the poses.
//! Thin: the work is `lightpose_logs::convert` and `convert_ros2`.

use lightpose_logs::McapOptions;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ConvertArgs {
    /// Log to read (.jsonl or .mcap; an MCAP cut short is read up to its
    /// last complete chunk: `lightpose recover` keeps every whole record).
    #[arg(long = "in")]
    input: PathBuf,
    /// Log to write (.jsonl or .mcap).
    #[arg(long)]
    out: PathBuf,
    /// POSE lines of the JSONL side (`lightpose replay --out`): read into
    /// the MCAP's /lightpose/pose when writing MCAP, written from it when
    /// reading MCAP.
    #[arg(long)]
    poses: Option<PathBuf>,
    /// MCAP chunk size, KiB: the unit that survives a power loss.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u64).range(1..=65536))]
    chunk_kib: u64,
    /// Leave out the Foxglove channels (image, vehicle pose, transform).
    #[arg(long)]
    no_foxglove: bool,
    /// Write a ROS 2 bag (MCAP, `ros2msg` schemas, CDR) of the `ok` poses
    /// of --poses (or of an MCAP recording's own) as lightposed's ROS 2
    /// node publishes them: pose, odometry, /tf; `ros2 bag play` and
    /// rosbags read it (docs/ros2.md).
    #[arg(long, conflicts_with = "no_foxglove")]
    ros2: bool,
    /// --ros2: the node's namespace (`[ros2] namespace`): topics
    /// NS/pose and NS/odom.
    #[arg(long, requires = "ros2", default_value = "/lightpose", value_parser = namespace)]
    namespace: String,
    /// --ros2: the frames BEACON,BASE_LINK,MAP (`[ros2.frames]`).
    #[arg(long, requires = "ros2", value_parser = frames)]
    frames: Option<Frames>,
    /// --ros2: `[site]` beacon_heading_deg, the compass heading of the
    /// beacon's axis: with it the bag holds /tf_static (MAP → BEACON).
    #[arg(long, requires = "ros2", allow_hyphen_values = true)]
    site_heading_deg: Option<f64>,
    /// --ros2: `[site]` beacon_depth_m (with --site-heading-deg).
    #[arg(long, requires = "site_heading_deg")]
    site_depth_m: Option<f64>,
    /// --ros2: `[site]` beacon_ned_m as N,E,D (with --site-heading-deg).
    #[arg(long, requires = "site_heading_deg", allow_hyphen_values = true, value_parser = ned)]
    site_ned_m: Option<[f64; 3]>,
}

use lightpose_logs::ros2msg::{names, Frames, SiteTf};

fn namespace(s: &str) -> Result<String, String> {
    if names::is_namespace(s) {
        Ok(s.to_string())
    } else {
        Err("no absolute ROS 2 namespace (e.g. /lightpose or /auv1/lightpose)".into())
    }
}

fn frames(s: &str) -> Result<Frames, String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [beacon, base_link, map] = parts[..] else {
        return Err("three frames, BEACON,BASE_LINK,MAP".into());
    };
    if let Some(bad) = parts.iter().find(|p| !names::is_frame_id(p)) {
        return Err(format!(
            "\"{bad}\" is no tf frame id (not empty, no leading /, no spaces)"
        ));
    }
    let f = Frames {
        beacon: beacon.into(),
        base_link: base_link.into(),
        map: map.into(),
    };
    f.distinct()
        .then_some(f)
        .ok_or_else(|| "beacon, base_link and map must be three frames: tf would loop".into())
}

fn ned(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("{p}: {e}")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [n, e, d] if v.iter().all(|x| x.is_finite()) => Ok([n, e, d]),
        _ => Err("three finite numbers, N,E,D in metres".into()),
    }
}

/// `[site]` from the flags, checked as the daemon checks it.
fn site(a: &ConvertArgs) -> anyhow::Result<Option<SiteTf>> {
    let Some(h) = a.site_heading_deg else {
        return Ok(None);
    };
    if !(h.is_finite() && (-360.0..=360.0).contains(&h)) {
        anyhow::bail!("--site-heading-deg {h}: a heading in -360..=360 degrees");
    }
    let ned = match (a.site_ned_m, a.site_depth_m) {
        (Some(n), _) => n,
        (None, Some(d)) if d.is_finite() && (0.0..=11000.0).contains(&d) => [0.0, 0.0, d],
        (None, Some(d)) => anyhow::bail!("--site-depth-m {d}: a depth in 0..=11000 m"),
        (None, None) => {
            anyhow::bail!(
                "--site-heading-deg needs --site-depth-m or --site-ned-m: where the beacon is"
            )
        }
    };
    Ok(Some(SiteTf {
        axis_heading: lightpose_core::Angle::from_deg(h),
        ned,
    }))
}

fn run_ros2(a: &ConvertArgs) -> anyhow::Result<()> {
    let opts = lightpose_logs::Ros2BagOptions {
        chunk_bytes: a.chunk_kib << 10,
        namespace: a.namespace.clone(),
        frames: a.frames.clone().unwrap_or_default(),
        site: site(a)?,
        ..Default::default()
    };
    let mut shown = 0u32;
    let s = lightpose_logs::convert_ros2(&a.input, &a.out, a.poses.as_deref(), &opts, |e| {
        shown += 1;
        if shown <= 20 {
            eprintln!("lightpose: skipped {e}");
        }
    })?;
    eprintln!(
        "{} frames, {} poses: {} ok written as pose, odom and /tf, {} not ok left out; {} STATUS as /diagnostics; {} skipped: {} -> {}",
        s.frames,
        s.poses,
        s.written,
        s.not_ok,
        s.diagnostics,
        s.skipped,
        a.input.display(),
        a.out.display()
    );
    Ok(())
}

pub fn run(a: ConvertArgs) -> anyhow::Result<()> {
    if a.ros2 {
        return run_ros2(&a);
    }
    let opts = McapOptions {
        chunk_bytes: a.chunk_kib << 10,
        foxglove: !a.no_foxglove,
    };
    let mut shown = 0u32;
    let s = lightpose_logs::convert(&a.input, &a.out, a.poses.as_deref(), &opts, |e| {
        shown += 1;
        if shown <= 20 {
            eprintln!("lightpose: skipped {e}");
        }
    })?;
    eprintln!(
        "{} frames, {} poses: {} -> {}; {} skipped, {} other messages and {} metadata records carried, {} other records passed over",
        s.frames,
        s.poses,
        a.input.display(),
        a.out.display(),
        s.skipped,
        s.carried,
        s.metadata,
        s.other
    );
    if let Some(cut) = s.cut {
        eprintln!("lightpose: {}: {cut}", a.input.display());
    }
    if s.seq_gaps.0 > 0 {
        eprintln!(
            "lightpose: {}: {} gaps in seq, {} frames lost",
            a.input.display(),
            s.seq_gaps.0,
            s.seq_gaps.1
        );
    }
    Ok(())
}
