//! The systemd unit against what the daemon and the kernel do: a device
//! name systemd cannot match, a group that does not exist or an exit code
//! the daemon does not use for a refused config each fail at sea, not here
//! (`char-spidev` in DeviceAllow let no MCP3008 open under the unit: the
//! kernel's spidev driver registers as `spi`).

use std::path::{Path, PathBuf};
use std::process::Command;

fn systemd_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../systemd")
}

/// The values of `key=` lines of a unit or config file, comments skipped.
fn values(text: &str, key: &str) -> Vec<String> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.strip_prefix(key)?.strip_prefix('='))
        .map(|v| v.trim().to_string())
        .collect()
}

fn unit() -> String {
    std::fs::read_to_string(systemd_dir().join("lightposed.service")).expect("the unit file")
}

/// `char-NAME` is matched against /proc/devices: the names the drivers the
/// boards use register (spidev.c: "spi", i2c-dev.c: "i2c", the serial
/// drivers: ttyS 8250, ttyUSB usb-serial, ttyACM cdc-acm, ttyAMA pl011).
#[test]
fn device_allow_names_are_kernel_driver_names() {
    let known = ["spi", "i2c", "ttyS", "ttyUSB", "ttyACM", "ttyAMA"];
    let allowed = values(&unit(), "DeviceAllow");
    assert!(allowed.len() >= known.len(), "{allowed:?}");
    for a in &allowed {
        let name = a
            .strip_prefix("char-")
            .and_then(|r| r.split_whitespace().next())
            .unwrap_or_else(|| panic!("DeviceAllow={a}: not a char-NAME rule"));
        assert!(
            known.contains(&name),
            "DeviceAllow={a}: no driver registers as {name}"
        );
    }
    for k in known {
        assert!(
            allowed.iter().any(|a| a.starts_with(&format!("char-{k} "))),
            "the {k} boards are not allowed: {allowed:?}"
        );
    }
}

/// Every supplementary group exists on Debian (dialout) or is created by
/// the shipped sysusers file, and the udev rules give the devices to them.
#[test]
fn supplementary_groups_are_created_and_own_the_devices() {
    let sysusers = std::fs::read_to_string(systemd_dir().join("lightposed.sysusers")).unwrap();
    let rules = std::fs::read_to_string(systemd_dir().join("60-lightpose-devices.rules")).unwrap();
    let created: Vec<&str> = sysusers
        .lines()
        .filter_map(|l| l.strip_prefix("g "))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    let groups = values(&unit(), "SupplementaryGroups").join(" ");
    assert!(!groups.is_empty());
    for g in groups.split_whitespace() {
        if g == "dialout" {
            continue;
        }
        assert!(
            created.contains(&g),
            "group {g} is not created: {created:?}"
        );
        assert!(
            rules.contains(&format!("GROUP=\"{g}\"")),
            "no udev rule gives a device to {g}"
        );
    }
}

/// RestartPreventExitStatus is the code the daemon exits with on a refused
/// config, so systemd does not restart into the same refusal every 2 s.
#[test]
fn restart_prevent_exit_status_is_the_refused_config_code() {
    let codes = values(&unit(), "RestartPreventExitStatus");
    assert_eq!(codes.len(), 1, "{codes:?}");
    let dir = std::env::temp_dir().join(format!("lp-unit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("bad.toml");
    std::fs::write(&cfg, "[backend]\nkind = \"no-such-backend\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .arg("--check-config")
        .arg(&cfg)
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(
        out.status.code().map(|c| c.to_string()),
        Some(codes[0].clone()),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Seconds of a systemd time span as this unit writes them: `60`, `60s`,
/// `1min`.
fn seconds(v: &str) -> f64 {
    let (n, unit) = v
        .find(|c: char| c.is_ascii_alphabetic())
        .map_or((v, ""), |i| v.split_at(i));
    let n: f64 = n
        .trim()
        .parse()
        .unwrap_or_else(|_| panic!("a time span: {v}"));
    match unit {
        "" | "s" | "sec" => n,
        "min" | "m" => n * 60.0,
        _ => panic!("a time span in seconds or minutes: {v}"),
    }
}

/// The one value of `key`, which the unit must set.
fn one(text: &str, key: &str) -> String {
    let v = values(text, key);
    assert_eq!(v.len(), 1, "{key}: {v:?}");
    v[0].clone()
}

/// The delay before the `k`-th automatic restart (from 1), as systemd
/// (>= 254, service_restart_usec_next) computes it from RestartSec,
/// RestartSteps and RestartMaxDelaySec.
fn delay(k: u32, sec: f64, steps: u32, max: f64) -> f64 {
    match k {
        _ if k <= 1 => sec,
        _ if k > steps => max,
        _ => sec * (max / sec).powf(f64::from(k - 1) / f64::from(steps)),
    }
}

/// Soak audit: a start that fails at once (a MAVLink udpin port taken,
/// exit 1) restarted every 2 s, ~43 000 times a day, never reaching the
/// start limit. The delay now grows to a cap, while the first restarts
/// stay as quick as before.
#[test]
fn restarts_back_off_from_restart_sec_to_a_cap() {
    let u = unit();
    assert_eq!(one(&u, "Restart"), "on-failure");
    let sec = seconds(&one(&u, "RestartSec"));
    let steps: u32 = one(&u, "RestartSteps").parse().expect("RestartSteps");
    let max = seconds(&one(&u, "RestartMaxDelaySec"));
    assert_eq!(sec, 2.0, "the first restart comes as soon as before");
    assert!(steps >= 1, "RestartSteps=0 turns the back-off off");
    // Capped low: systemd never resets the count during a run, so after a
    // few rare failures every restart waits the cap without a pose.
    assert!((10.0..=30.0).contains(&max), "RestartMaxDelaySec={max}");
    let first3: f64 = (1..=3).map(|k| delay(k, sec, steps, max)).sum();
    assert!(
        first3 <= 15.0,
        "a passing fault waits {first3} s for 3 tries"
    );
    // A start that fails at once, for a day.
    let (mut t, mut k) = (0.0, 0);
    while t < 86_400.0 {
        k += 1;
        t += delay(k, sec, steps, max);
    }
    assert!(k <= 5_000, "{k} restarts a day (43 200 every 2 s)");
    assert!(
        u.contains("systemd >= 254") && u.contains("Unknown key"),
        "the unit says which systemd reads the back-off keys"
    );
}

/// `systemd-analyze verify` (where installed; it needs no running
/// systemd) with ExecStart the binary just built: the unit loads, and the
/// only keys it does not know are the back-off ones (systemd < 254).
#[test]
fn systemd_analyze_verify_knows_every_key() {
    let probe = Command::new("systemd-analyze").arg("--version").output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!("no systemd-analyze here: not verified");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let exec = format!("ExecStart={}", env!("CARGO_BIN_EXE_lightposed"));
    let text: Vec<String> = unit()
        .lines()
        .map(|l| match l.starts_with("ExecStart=") {
            true => exec.clone(),
            false => l.to_string(),
        })
        .collect();
    let path = dir.path().join("lightposed.service");
    std::fs::write(&path, text.join("\n") + "\n").expect("unit copy");
    let out = Command::new("systemd-analyze")
        .arg("verify")
        .arg(&path)
        .output()
        .expect("systemd-analyze");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    for l in err.lines().filter(|l| l.contains("Unknown key")) {
        assert!(
            l.contains("'RestartSteps'") || l.contains("'RestartMaxDelaySec'"),
            "{l}"
        );
    }
}

/// Network audit: with no LimitNOFILE the daemon had 1024 descriptors, and
/// a flood of connections to the live view took them all (the DVL's
/// reconnect failed). The unit sets one limit, a number (not `infinity`)
/// well above what the daemon needs and above the 1024 that ran out.
#[test]
fn limit_nofile_is_set_and_sane() {
    let v = one(&unit(), "LimitNOFILE");
    // `N` or `SOFT:HARD`: both numbers, soft no more than hard.
    let n: Vec<u64> = v
        .split(':')
        .map(|x| {
            x.trim()
                .parse()
                .unwrap_or_else(|_| panic!("LimitNOFILE={v}: not a number"))
        })
        .collect();
    assert!(
        n.len() <= 2 && n[0] <= *n.last().unwrap(),
        "LimitNOFILE={v}"
    );
    assert!(
        (2048..=65536).contains(&n[0]),
        "LimitNOFILE={v}: the soft limit should be a few thousand"
    );
}

/// Every system call a full run of the daemon makes (the simulator,
/// recording JSONL and MCAP, multicast, the live view, the attitude input;
/// strace -f, x86_64, an audit of 2026-11-25).
const DAEMON_SYSCALLS: &[&str] = &[
    "accept4",
    "access",
    "arch_prctl",
    "bind",
    "brk",
    "clock_adjtime",
    "clock_nanosleep",
    "clone3",
    "close",
    "connect",
    "epoll_create1",
    "epoll_ctl",
    "epoll_wait",
    "eventfd2",
    "execve",
    "exit",
    "exit_group",
    "fcntl",
    "fdatasync",
    "fsync",
    "futex",
    "getdents64",
    "getrandom",
    "getsockname",
    "gettid",
    "ioctl",
    "listen",
    "madvise",
    "mkdir",
    "mmap",
    "mprotect",
    "munmap",
    "newfstatat",
    "openat",
    "poll",
    "prctl",
    "pread64",
    "prlimit64",
    "read",
    "recvfrom",
    "restart_syscall",
    "rseq",
    "rt_sigaction",
    "rt_sigprocmask",
    "rt_sigreturn",
    "sched_getaffinity",
    "sched_yield",
    "sendto",
    "set_robust_list",
    "set_tid_address",
    "setsockopt",
    "sigaltstack",
    "socket",
    "socketpair",
    "statfs",
    "statx",
    "write",
];

/// The calls of a `systemd-analyze syscall-filter` group, nested groups
/// expanded.
fn syscall_group(name: &str, seen: &mut Vec<String>) -> std::collections::BTreeSet<String> {
    let mut out = std::collections::BTreeSet::new();
    if !name.starts_with('@') {
        out.insert(name.to_string());
        return out;
    }
    if seen.iter().any(|s| s == name) {
        return out;
    }
    seen.push(name.to_string());
    let o = Command::new("systemd-analyze")
        .args(["syscall-filter", name])
        .output()
        .expect("systemd-analyze syscall-filter");
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    for item in text
        .lines()
        .skip(1)
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
    {
        out.extend(syscall_group(item, seen));
    }
    out
}

/// The unit's SystemCallFilter lines leave every call the daemon makes
/// allowed, and any call outside them fails with EPERM rather than
/// killing it. The recorder's clock query (clock_adjtime, in @privileged)
/// had killed the daemon with SIGSYS on its first recording.
#[test]
fn the_system_call_filter_allows_every_call_the_daemon_makes() {
    let u = unit();
    assert_eq!(one(&u, "SystemCallErrorNumber"), "EPERM");
    assert!(values(&u, "ProtectClock").iter().all(|v| v == "no"));
    let probe = Command::new("systemd-analyze").arg("--version").output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!("no systemd-analyze here: the filter's groups not expanded");
        return;
    }
    let mut allowed = std::collections::BTreeSet::new();
    for (i, line) in values(&u, "SystemCallFilter").iter().enumerate() {
        let (deny, items) = match line.strip_prefix('~') {
            Some(rest) => (true, rest),
            None => (false, line.as_str()),
        };
        assert!(i > 0 || !deny, "the first filter line is the allow list");
        for item in items.split_whitespace() {
            let calls = syscall_group(item, &mut Vec::new());
            if deny {
                allowed.retain(|c| !calls.contains(c));
            } else {
                allowed.extend(calls);
            }
        }
    }
    let missing: Vec<_> = DAEMON_SYSCALLS
        .iter()
        .filter(|c| !allowed.contains(**c))
        .collect();
    assert!(missing.is_empty(), "denied by the unit: {missing:?}");
}
