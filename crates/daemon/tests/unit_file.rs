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
