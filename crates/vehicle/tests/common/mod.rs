//! What the integration tests share: the vehicle's tasks running on a
//! runtime of their own (so that a test body can play the frame thread),
//! `udpout` settings and an `ok` estimate.
#![allow(dead_code)]

use lightpose_core::{Angle, PoseEstimate, Status, StdDev};
use lightpose_vehicle::{DvlSettings, Hub, MavlinkSettings, Site};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A task running on its own runtime thread until dropped.
pub struct Running {
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            t.join().expect("task thread ends without panic");
        }
    }
}

fn spawn<F, Fut>(f: F) -> Running
where
    F: FnOnce(tokio::sync::oneshot::Receiver<()>) -> Fut + Send + 'static,
    Fut: std::future::Future<Output = ()>,
{
    let (tx, rx) = tokio::sync::oneshot::channel();
    let thread = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        rt.block_on(f(rx));
    });
    Running {
        stop: Some(tx),
        thread: Some(thread),
    }
}

pub fn spawn_mavlink(s: MavlinkSettings, hub: Arc<Hub>) -> Running {
    spawn(move |stop| async move {
        lightpose_vehicle::mav::task::run(s, hub, async {
            let _ = stop.await;
        })
        .await
    })
}

pub fn spawn_dvl(s: DvlSettings, hub: Arc<Hub>) -> Running {
    spawn(move |stop| async move {
        lightpose_vehicle::dvl::client::run(s, hub, async {
            let _ = stop.await;
        })
        .await
    })
}

/// MAVLink settings that send (`udpout`) to 127.0.0.1:`port`, on a site
/// whose axis heads 30° with the beacon 3 m deep.
pub fn udpout(port: u16) -> MavlinkSettings {
    MavlinkSettings::new(
        format!("udpout:127.0.0.1:{port}").parse().unwrap(),
        Site::new(Angle::from_deg(30.0), 3.0),
    )
}

/// Poll `cond` every 5 ms until it holds or `timeout` passes.
pub fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let end = Instant::now() + timeout;
    while Instant::now() < end {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    cond()
}

/// An `ok` estimate of the test pose: x 5, y 1, z 0.5 m, pitch 10°, yaw
/// −20°, surge 0.4 m/s, with std 0.2, 0.05, 0.03 m, 1°, 2°, 0.05 m/s.
pub fn estimate(seq: u64, t: f64) -> PoseEstimate {
    let mut e = PoseEstimate::empty(seq, t, Status::Ok, "test");
    (e.x, e.y, e.z) = (Some(5.0), Some(1.0), Some(0.5));
    (e.pitch_deg, e.yaw_deg, e.surge) = (Some(10.0), Some(-20.0), Some(0.4));
    e.std = StdDev {
        x: Some(0.2),
        y: Some(0.05),
        z: Some(0.03),
        pitch: Some(1.0),
        yaw: Some(2.0),
        surge: Some(0.05),
        roll: None,
    };
    e
}

/// The pymavlink stand-in (`tests/python/mav_peer.py` with `args`, env
/// `envs`) running: its JSON lines as they come, and the UDP port it
/// printed first.
pub struct PyPeer {
    pub child: std::process::Child,
    pub lines: std::sync::mpsc::Receiver<serde_json::Value>,
    pub reader: std::thread::JoinHandle<()>,
    pub port: u16,
}

impl PyPeer {
    pub fn spawn(args: &[String], envs: &[(&str, &str)]) -> PyPeer {
        Self::spawn_script("mav_peer.py", args, envs)
    }

    /// As [`PyPeer::spawn`] with another script of `tests/python`.
    pub fn spawn_script(name: &str, args: &[String], envs: &[(&str, &str)]) -> PyPeer {
        use std::io::{BufRead, BufReader};
        let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/python")
            .join(name);
        let mut child = std::process::Command::new(lightpose_testkit::python::python())
            .arg(script)
            .args(args)
            .envs(envs.iter().copied())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("python starts");
        let (tx, rx) = std::sync::mpsc::channel::<serde_json::Value>();
        let out = child.stdout.take().expect("stdout");
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let v = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{line}: {e}"));
                if tx.send(v).is_err() {
                    break;
                }
            }
        });
        let first = rx
            .recv_timeout(Duration::from_secs(30))
            .expect("the peer's port");
        let port = first["port"].as_u64().expect("port") as u16;
        PyPeer {
            child,
            lines: rx,
            reader,
            port,
        }
    }
}
