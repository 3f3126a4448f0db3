//! `lightpose fake-autopilot`: stands in for the vehicle's autopilot on a
//! desk. From a scene and a trajectory it sends what ArduSub would
//! (ATTITUDE, GLOBAL_POSITION_INT or VFR_HUD, SCALED_PRESSURE2 at the frame
//! rate, HEARTBEAT every second) to the daemon's MAVLink endpoint, and
//! prints what comes back (VISION_POSITION_ESTIMATE / SPEED_ESTIMATE)
//! against the truth at each estimate's capture time, with running p95
//! errors. The messages and the comparison are `lightpose_vehicle::standin`;
//! this file is the loop.

use crate::stdout::outln;
use anyhow::{anyhow, Context};
use lightpose_core::Angle;
use lightpose_sim::{Scene, Trajectory};
use lightpose_vehicle::mav::inbound::DepthSource;
use lightpose_vehicle::mav::link::Sent;
use lightpose_vehicle::mav::outbound::Encoder;
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::mav::signing::{KeyForm, SigningConfig, SigningKey};
use lightpose_vehicle::standin::{
    autopilot_heartbeat, autopilot_messages, decode, ErrorStats, Received, SensorState, ERROR_AXES,
};
use lightpose_vehicle::{Endpoint, Link, NedPose, Site, SiteTable};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct FakeAutopilotArgs {
    /// Scene file (its frame rate, water temperature and sensor noise).
    #[arg(long)]
    scene: PathBuf,
    /// Trajectory knots (CSV: t,x,y,z,pitch,yaw), the truth.
    #[arg(long)]
    trajectory: PathBuf,
    /// Where to talk: udpin:ADDR:PORT (the default is where the daemon's
    /// default `udpout:127.0.0.1:14550` sends), udpout:HOST:PORT or
    /// serial:PATH:BAUD.
    #[arg(long, default_value = "udpin:127.0.0.1:14550")]
    connect: String,
    /// Heading of the beacon's axis, as the daemon's [site].
    #[arg(long, default_value_t = 30.0)]
    beacon_heading_deg: f64,
    /// Depth of the beacon, as the daemon's [site].
    #[arg(long, default_value_t = 3.0)]
    beacon_depth_m: f64,
    /// Sets of messages per second, 0.01 to 1000 (default 10: the
    /// ATTITUDE stream the README asks of an autopilot; an autopilot's
    /// streams do not follow the array's frame rate).
    #[arg(long, default_value_t = DEFAULT_RATE_HZ)]
    rate: f64,
    /// The depth message, as the daemon's `[mavlink] depth` (default
    /// global_position_int: relative_alt, mm, below the surface negative).
    #[arg(long, default_value = "global_position_int", value_parser = ["global_position_int", "vfr_hud"])]
    depth_source: String,
    /// 1σ noise of the pitch, degrees, 0 to 180 (default: the scene's
    /// attitude sensor's pitch, else none).
    #[arg(long)]
    pitch_noise_deg: Option<f64>,
    /// 1σ noise of the heading, degrees, 0 to 180 (default: the scene's
    /// attitude sensor's yaw, else none).
    #[arg(long)]
    yaw_noise_deg: Option<f64>,
    /// 1σ noise of the depth, m, 0 to 1000 (default: the scene's depth
    /// sensor, else none).
    #[arg(long)]
    depth_noise_m: Option<f64>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Stop after this many seconds (at most a year; default: until
    /// Ctrl-C).
    #[arg(long)]
    duration: Option<f64>,
    /// Run the trajectory over and over (else the vehicle stays at its end).
    #[arg(long = "loop")]
    repeat: bool,
    /// Whose clock places us on the trajectory: the daemon's (its estimates'
    /// capture times, once they come) or our own.
    #[arg(long, default_value = "daemon", value_parser = ["daemon", "own"])]
    clock: String,
    /// Sign what is sent and take only frames signed with the key, as an
    /// autopilot with MAVLink 2 signing set up: the key is SHA-256 of the
    /// passphrase in this file (MAVProxy's and QGroundControl's), as the
    /// daemon's `[mavlink.signing] passphrase_file`.
    #[arg(long, conflicts_with = "signing_key_file")]
    signing_passphrase_file: Option<PathBuf>,
    /// The same with the key as 64 hex digits (`key_file`).
    #[arg(long)]
    signing_key_file: Option<PathBuf>,
    /// Print every estimate received.
    #[arg(long)]
    verbose: bool,
}

/// The signing asked for, if any (link id 0, unsigned frames refused).
fn signing(a: &FakeAutopilotArgs) -> anyhow::Result<Option<SigningConfig>> {
    let (path, form, flag) = match (&a.signing_passphrase_file, &a.signing_key_file) {
        (Some(p), _) => (p, KeyForm::Passphrase, "--signing-passphrase-file"),
        (None, Some(p)) => (p, KeyForm::Hex, "--signing-key-file"),
        (None, None) => return Ok(None),
    };
    let key = SigningKey::load(path, form).map_err(|e| anyhow!("{flag}: {e}"))?;
    Ok(Some(SigningConfig {
        key,
        link_id: 0,
        allow_unsigned: false,
    }))
}

/// Everything the loop keeps.
struct Session {
    site: Site,
    traj: Trajectory,
    repeat: bool,
    temp_c: f64,
    depth: DepthSource,
    noise: [f64; 3],
    rng: ChaCha8Rng,
    follow_daemon: bool,
    /// Daemon time − our elapsed time, from the least-delayed estimate.
    offset: Option<f64>,
    start: Instant,
    enc: Encoder,
    /// Signing is on, and the frames it dropped (unsigned, another key,
    /// replayed).
    signed: bool,
    unsigned_or_bad: u64,
    stats: ErrorStats,
    sent_sets: u64,
    speeds: u64,
    /// Estimates whose capture time lies off the trajectory (no truth).
    no_truth: u64,
    components: Vec<u8>,
    latest: Option<[f64; 5]>,
    verbose: bool,
}

/// Longest `--duration`, s (a year): more is a typo, and leaving it out
/// runs until Ctrl-C.
const MAX_DURATION_S: f64 = 365.0 * 86_400.0;

/// Largest noise options: a 1σ beyond these is no sensor.
const MAX_ANGLE_NOISE_DEG: f64 = 180.0;
const MAX_DEPTH_NOISE_M: f64 = 1000.0;

/// The range of `--rate`, Hz: below, a set every 100 s is no autopilot
/// (and 1e-20 Hz made a period no `Duration` holds: a panic); above, the
/// tick is under a millisecond.
const MIN_RATE_HZ: f64 = 0.01;
/// `--rate`'s default: README, "Streams": ATTITUDE at 10 Hz or more.
const DEFAULT_RATE_HZ: f64 = 10.0;
const MAX_RATE_HZ: f64 = 1000.0;

/// The rate, if within [`MIN_RATE_HZ`]..=[`MAX_RATE_HZ`].
fn rate_ok(r: f64) -> bool {
    r.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&r)
}

/// Refuse what would panic (a `Duration` of −1 s, NaN or 1e20 s) or send
/// nonsense (a negative or NaN 1σ, a beacon 20 km deep), before any file
/// is read or socket opened.
fn check_numbers(a: &FakeAutopilotArgs) -> anyhow::Result<Site> {
    let r = a.rate;
    if !rate_ok(r) {
        return Err(anyhow!(
            "--rate {r}: must be {MIN_RATE_HZ} to {MAX_RATE_HZ} Hz (default {DEFAULT_RATE_HZ})"
        ));
    }
    if let Some(d) = a.duration {
        if !(d.is_finite() && d > 0.0 && d <= MAX_DURATION_S) {
            return Err(anyhow!(
                "--duration {d}: must be more than 0 and at most {MAX_DURATION_S} s (leave it out to run until Ctrl-C)"
            ));
        }
    }
    for (flag, v, max, unit) in [
        (
            "pitch-noise-deg",
            a.pitch_noise_deg,
            MAX_ANGLE_NOISE_DEG,
            "°",
        ),
        ("yaw-noise-deg", a.yaw_noise_deg, MAX_ANGLE_NOISE_DEG, "°"),
        ("depth-noise-m", a.depth_noise_m, MAX_DEPTH_NOISE_M, " m"),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && (0.0..=max).contains(&v)) {
                return Err(anyhow!("--{flag} {v}: a 1σ must be 0 to {max}{unit}"));
            }
        }
    }
    // The beacon, as the daemon's [site] checks it, named as the option.
    SiteTable {
        beacon_heading_deg: a.beacon_heading_deg,
        beacon_depth_m: a.beacon_depth_m,
        beacon_ned_m: None,
    }
    .validate()
    .map_err(|e| anyhow!("--{}: {}", e.key.replace('_', "-"), e.msg))
}

pub fn run(a: FakeAutopilotArgs) -> anyhow::Result<()> {
    let site = check_numbers(&a)?;
    let scene = Scene::load(&a.scene)?;
    let traj = Trajectory::load(&a.trajectory)?;
    let signing = signing(&a)?;
    let endpoint: Endpoint = a.connect.parse().map_err(|e| anyhow!("--connect: {e}"))?;
    let rate = a.rate;
    let att = scene
        .attitude
        .unwrap_or(lightpose_sim::scene::AttitudeNoise {
            sigma_pitch: Angle::ZERO,
            sigma_yaw: Angle::ZERO,
            sigma_roll: None,
        });
    let noise = [
        a.pitch_noise_deg.unwrap_or(att.sigma_pitch.deg()),
        a.yaw_noise_deg.unwrap_or(att.sigma_yaw.deg()),
        a.depth_noise_m
            .unwrap_or(scene.depth.map_or(0.0, |d| d.sigma_m)),
    ];
    let mut s = Session {
        site,
        traj,
        repeat: a.repeat,
        temp_c: scene.temp_c,
        depth: match a.depth_source.as_str() {
            "vfr_hud" => DepthSource::VfrHud,
            _ => DepthSource::GlobalPositionInt,
        },
        noise,
        rng: ChaCha8Rng::seed_from_u64(a.seed),
        follow_daemon: a.clock == "daemon",
        offset: None,
        start: Instant::now(),
        signed: signing.is_some(),
        enc: Encoder::new(1, 1).signed(signing),
        unsigned_or_bad: 0,
        stats: ErrorStats::default(),
        sent_sets: 0,
        speeds: 0,
        no_truth: 0,
        components: Vec::new(),
        latest: None,
        verbose: a.verbose,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("tokio runtime")?;
    rt.block_on(s.serve(endpoint, rate, a.duration))?;
    outln!("{}", s.summary());
    Ok(())
}

impl Session {
    async fn serve(
        &mut self,
        endpoint: Endpoint,
        rate: f64,
        duration: Option<f64>,
    ) -> anyhow::Result<()> {
        let mut link = Link::open(&endpoint).await?;
        eprintln!(
            "fake-autopilot: on {endpoint}{}, trajectory {:.1}..{:.1} s, {rate} Hz, noise pitch {}° heading {}° depth {} m",
            link.local_addr().map(|a| format!(" ({a})")).unwrap_or_default(),
            self.traj.t0(),
            self.traj.t_end(),
            self.noise[0],
            self.noise[1],
            self.noise[2]
        );
        let mut scanner = Scanner::new(link.framing());
        let period = Duration::try_from_secs_f64(1.0 / rate)
            .map_err(|e| anyhow!("--rate {rate}: no period of 1/{rate} s: {e}"))?;
        let mut tick = tokio::time::interval(period);
        let mut beat = tokio::time::interval(Duration::from_secs(1));
        let mut report = tokio::time::interval(Duration::from_secs(1));
        let end = match duration {
            None => Duration::from_secs(u32::MAX as u64),
            Some(d) => Duration::try_from_secs_f64(d)
                .map_err(|e| anyhow!("--duration {d}: not a duration: {e}"))?,
        };
        let stop = tokio::time::sleep(end);
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => return Ok(()),
                _ = tokio::signal::ctrl_c() => return Ok(()),
                _ = tick.tick() => self.send_sensors(&mut link).await,
                _ = beat.tick() => {
                    let _ = link.send(self.enc.encode(&autopilot_heartbeat())).await;
                }
                _ = report.tick() => {
                    if let Some(line) = self.progress() {
                        outln!("{line}");
                    }
                }
                r = link.recv(scanner.spare()) => match r {
                    Ok(n) => {
                        scanner.commit(n);
                        // udpin: answer whoever sent a valid frame, not
                        // whoever sent a datagram.
                        // A new peer gets our HEARTBEAT at once: a
                        // daemon takes nothing from us before it.
                        if self.take(&mut scanner)
                            && link.accept_sender(std::time::Instant::now()).is_some()
                        {
                            let _ = link.send(self.enc.encode(&autopilot_heartbeat())).await;
                        }
                    }
                    Err(e) if link.framing() == Framing::Stream => return Err(e).context("serial link"),
                    Err(_) => {} // nobody listening yet
                },
            }
        }
    }

    /// Trajectory time for a time on the daemon's (or our) clock.
    fn traj_time(&self, t: f64) -> f64 {
        let (t0, t1) = (self.traj.t0(), self.traj.t_end());
        if self.repeat && t1 > t0 {
            t0 + (t - t0).rem_euclid(t1 - t0)
        } else {
            t.clamp(t0, t1)
        }
    }

    /// Where the vehicle is now, on the clock in use.
    fn now(&self) -> f64 {
        let el = self.start.elapsed().as_secs_f64();
        el + self.offset.unwrap_or(self.traj.t0())
    }

    fn gauss(&mut self, sigma: f64) -> f64 {
        let z: f64 = StandardNormal.sample(&mut self.rng);
        sigma * z
    }

    async fn send_sensors(&mut self, link: &mut Link) {
        let pose = self.traj.kinematics(self.traj_time(self.now())).pose;
        let mut s = SensorState::of(&self.site, &pose, Some(self.temp_c));
        s.pitch = s.pitch + Angle::from_deg(self.gauss(self.noise[0]));
        s.heading = s.heading + Angle::from_deg(self.gauss(self.noise[1]));
        s.depth_m += self.gauss(self.noise[2]);
        let ms = (self.start.elapsed().as_millis() & 0xFFFF_FFFF) as u32;
        let mut sent = false;
        for m in autopilot_messages(&s, self.depth, ms) {
            // udpin before the daemon spoke: nowhere to send yet, and the
            // set is not counted as sent.
            sent |= matches!(link.send(self.enc.encode(&m)).await, Ok(Sent::Yes));
        }
        self.sent_sets += u64::from(sent);
    }

    /// Judge what came; true if it held a valid frame.
    fn take(&mut self, sc: &mut Scanner) -> bool {
        let mut valid = false;
        while let Some(ev) = sc.next_frame() {
            let Scanned::Frame(f) = ev else { continue };
            if let Some(sg) = self.enc.signer_mut() {
                if sg.check(f.bytes).is_err() {
                    self.unsigned_or_bad += 1;
                    continue;
                }
            }
            valid = true;
            match decode(&f) {
                Some(Received::Position(p)) => {
                    let t = p.usec as f64 * 1e-6;
                    if self.follow_daemon {
                        let off = t - self.start.elapsed().as_secs_f64();
                        self.offset = Some(self.offset.map_or(off, |o| o.max(off)));
                    }
                    let (t0, t1) = (self.traj.t0(), self.traj.t_end());
                    if !self.repeat && !(t0 - 0.5..=t1 + 0.5).contains(&t) {
                        self.no_truth += 1;
                        continue;
                    }
                    let truth = self
                        .site
                        .pose_ned(&self.traj.kinematics(self.traj_time(t)).pose);
                    let est = NedPose {
                        position: p.position,
                        roll: p.roll,
                        pitch: p.pitch,
                        heading: p.heading,
                    };
                    let e = self.stats.push(&est, &truth);
                    self.latest = Some(e);
                    if self.verbose {
                        outln!("VISION_POSITION_ESTIMATE t {t:.3} s  NED {:+.3} {:+.3} {:+.3} m  pitch {:+.2}° heading {:+.2}°  reset {}  error {}", p.position.0[0], p.position.0[1], p.position.0[2], p.pitch.deg(), p.heading.deg(), p.reset_counter, errors(&e));
                    }
                }
                Some(Received::Speed(v)) => {
                    self.speeds += 1;
                    if self.verbose {
                        let [n, e, d] = v.velocity.0;
                        outln!(
                            "VISION_SPEED_ESTIMATE t {:.3} s  NED {n:+.3} {e:+.3} {d:+.3} m/s",
                            v.usec as f64 * 1e-6
                        );
                    }
                }
                Some(Received::Heartbeat { component, .. })
                    if !self.components.contains(&component) =>
                {
                    eprintln!(
                        "fake-autopilot: HEARTBEAT from component {component} of system {}",
                        f.system
                    );
                    self.components.push(component);
                }
                _ => {}
            }
        }
        if sc.framing() == Framing::Datagram {
            sc.end_of_datagram();
        }
        valid
    }

    fn p95_line(&self) -> String {
        if self.stats.is_empty() {
            return "no estimate received to compare with the truth".into();
        }
        let p = self.stats.p95();
        format!(
            "p95 over {}: {} {:.3} m, {} {:.3} m, {} {:.3} m, {} {:.2}°, {} {:.2}°",
            self.stats.len(),
            ERROR_AXES[0],
            p[0],
            ERROR_AXES[1],
            p[1],
            ERROR_AXES[2],
            p[2],
            ERROR_AXES[3],
            p[3],
            ERROR_AXES[4],
            p[4]
        )
    }

    fn progress(&self) -> Option<String> {
        let e = self.latest?;
        Some(format!(
            "t {:.1} s  latest {}  {}",
            self.now(),
            errors(&e),
            self.p95_line()
        ))
    }

    fn summary(&self) -> String {
        let refused = if self.signed {
            format!(
                "; {} frames refused for their signature",
                self.unsigned_or_bad
            )
        } else {
            String::new()
        };
        format!(
            "fake-autopilot: sent {} sets of sensor messages; received {} VISION_POSITION_ESTIMATE ({} off the trajectory's times), {} VISION_SPEED_ESTIMATE, heartbeats from components {:?}{refused}; {}",
            self.sent_sets,
            self.stats.len() as u64 + self.no_truth,
            self.no_truth,
            self.speeds,
            self.components,
            self.p95_line()
        )
    }
}

fn errors(e: &[f64; 5]) -> String {
    format!(
        "N {:+.3} E {:+.3} D {:+.3} m, pitch {:+.2}°, heading {:+.2}°",
        e[0], e[1], e[2], e[3], e[4]
    )
}
