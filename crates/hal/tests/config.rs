//! The config as the daemon's file gives it: TOML into [`BackendConfig`],
//! validation errors that name the key, and `open`.

mod common;

use common::{map_tables, validate};
use lightpose_hal::config::{TempPlan, ValidBackend};
use lightpose_hal::{BackendConfig, FrameSource, HalError, PlainEnv, Stop};

fn parse(text: &str) -> Result<BackendConfig, String> {
    toml::from_str::<BackendConfig>(text).map_err(|e| e.to_string())
}

/// A full MCP3008 map: 4 chips, detector k on chip k / 8, channel k % 8.
fn mcp_map() -> String {
    map_tables("u", 8)
}

const MCP_HEAD: &str = r#"
kind = "mcp3008"
rate_hz = 10.0
chips = [
  { name = "u0", device = "/dev/spidev0.0" },
  { name = "u1", device = "/dev/spidev0.1" },
  { name = "u2", device = "/dev/spidev1.0", max_speed_hz = 1000000 },
  { name = "u3", device = "/dev/spidev1.1" },
]
"#;

/// Validate and open, as a program does.
fn open_source(cfg: &BackendConfig) -> Result<Box<dyn FrameSource>, HalError> {
    lightpose_hal::open(&cfg.validate(&PlainEnv)?, &Stop::new())
}

#[test]
fn mcp3008_config_validates_with_thermistor() {
    let text = format!(
        "{MCP_HEAD}\n[temperature]\nkind = \"thermistor\"\nfallback_c = 20.0\nboard = \"u3\"\nchannel = 7\nr_fixed_ohm = 10000.0\n{}",
        mcp_map()
    );
    let v = validate(&text).unwrap();
    let ValidBackend::Spi {
        kind,
        chips,
        common,
    } = v
    else {
        panic!("not SPI: {v:?}")
    };
    assert_eq!(kind.bits(), 10);
    // no vdd_v: the 2.7 V limit, safe at any supply
    assert_eq!(chips[0].max_speed_hz, 1_350_000);
    assert_eq!(chips[2].max_speed_hz, 1_000_000);
    assert_eq!(common.rate_hz, Some(10.0));
    assert_eq!(common.map.source_of(24), (3, 0));
    assert!(matches!(common.temp, TempPlan::Thermistor { fallback_c, .. } if fallback_c == 20.0));
}

#[test]
fn unknown_keys_are_refused() {
    let e = parse(&format!("{MCP_HEAD}\nspeed = 3\n{}", mcp_map())).unwrap_err();
    assert!(e.contains("speed"), "{e}");
    let e = parse(&format!(
        "{MCP_HEAD}\n[temperature]\nkind = \"fixed\"\nvalue_c = 3\nvalu = 4\n{}",
        mcp_map()
    ))
    .unwrap_err();
    assert!(e.contains("valu"), "{e}");
    let e = parse("kind = \"mcp9999\"").unwrap_err();
    assert!(e.contains("mcp9999"), "{e}");
}

#[test]
fn validation_errors_name_the_key() {
    let cases: Vec<(String, &str)> = vec![
        (
            format!("{}{}", MCP_HEAD.replace("rate_hz = 10.0", "rate_hz = -1.0"), mcp_map()),
            "rate_hz",
        ),
        // Its period past a Duration: the pacer ran flat out (an audit).
        (
            format!("{}{}", MCP_HEAD.replace("rate_hz = 10.0", "rate_hz = 1e-300"), mcp_map()),
            "rate_hz: 1e-300 is not 0 (as fast as possible) or in 0.001..=10000 Hz",
        ),
        (
            format!("{}{}", MCP_HEAD.replace("spidev1.1", "spidev0.0"), mcp_map()),
            "/dev/spidev0.0 is used by two chips",
        ),
        (
            format!("{}{}", MCP_HEAD.replace("1000000", "5000000"), mcp_map()),
            "chips.u2.max_speed_hz",
        ),
        (
            format!("{}{}", MCP_HEAD, mcp_map().replace("board = \"u3\"", "board = \"u9\"")),
            "unknown board \"u9\"",
        ),
        (
            format!(
                "{MCP_HEAD}\n[temperature]\nkind = \"thermistor\"\nfallback_c = 20.0\nboard = \"u0\"\nchannel = 3\nr_fixed_ohm = 1e4\n{}",
                mcp_map()
            ),
            "already feeds a detector",
        ),
    ];
    for (text, want) in cases {
        let e = validate(&text).unwrap_err();
        assert!(e.contains(want), "wanted {want:?} in {e:?}");
    }
}

#[test]
fn i2c_configs_check_addresses_fsr_and_reference() {
    let chips = |a: &str| {
        format!("chips = [{{ name = \"a0\", bus = \"/dev/i2c-1\", address = 0x48 }}, {{ name = \"a1\", bus = \"/dev/i2c-1\", address = {a} }}]\n")
    };
    let map: String = (0..25)
        .map(|k| {
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"a{}\"\nchannel = {}\n",
                k / 5,
                k % 5,
                k / 16,
                k % 8
            )
        })
        .collect();
    // ADS7828: 8 channels per chip → this map uses channels 0..8 of a0 twice
    let e = validate(&format!("kind = \"ads7828\"\n{}{map}", chips("0x49"))).unwrap_err();
    assert!(e.contains("feeds two detectors"), "{e}");
    let map7828: String = (0..25)
        .map(|k| {
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"a{}\"\nchannel = {}\n",
                k / 5,
                k % 5,
                k / 8,
                k % 8
            )
        })
        .collect();
    let four = "chips = [{ name = \"a0\", bus = \"/dev/i2c-1\", address = 0x48 }, { name = \"a1\", bus = \"/dev/i2c-1\", address = 0x49 }, { name = \"a2\", bus = \"/dev/i2c-1\", address = 0x4A }, { name = \"a3\", bus = \"/dev/i2c-1\", address = 0x4B }]\n";
    let v = validate(&format!("kind = \"ads7828\"\n{four}{map7828}")).unwrap();
    assert!(matches!(v, ValidBackend::Ads7828 { ref buses, .. } if buses.len() == 1));
    let e = validate(&format!(
        "kind = \"ads7828\"\n{}{map7828}",
        four.replace("0x4B", "0x4C")
    ))
    .unwrap_err();
    assert!(e.contains("chips.a3.address") && e.contains("0x4C"), "{e}");
    let e = validate(&format!(
        "kind = \"ads7828\"\n{}{map7828}",
        four.replace("0x4B", "0x48")
    ))
    .unwrap_err();
    assert!(e.contains("also chip \"a0\""), "{e}");
    let e = validate(&format!(
        "kind = \"ads7828\"\ninternal_ref = false\n{four}{map7828}"
    ))
    .unwrap_err();
    assert!(e.contains("v_ref"), "{e}");
    let e = validate(&format!("kind = \"ads1115\"\nfsr_v = 5.0\n{four}{map7828}")).unwrap_err();
    assert!(e.contains("fsr_v"), "{e}");
    let e = validate(&format!(
        "kind = \"ads1115\"\ndata_rate_sps = 100\n{four}{map7828}"
    ))
    .unwrap_err();
    assert!(e.contains("data_rate_sps"), "{e}");
}

#[test]
fn serial_and_sim_configs() {
    let map: String = (0..25)
        .map(|k| {
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"b{}\"\nchannel = {}\n",
                k / 5,
                k % 5,
                k / 16,
                k % 16
            )
        })
        .collect();
    let boards = "boards = [{ name = \"b0\", id = 0, path = \"/dev/ttyACM0\", channels = 16 }, { name = \"b1\", id = 1, path = \"/dev/ttyACM1\", channels = 16 }]\n";
    let v = validate(&format!("kind = \"serial\"\nadc_bits = 12\n{boards}{map}")).unwrap();
    assert!(matches!(v, ValidBackend::Serial { ref common, .. } if common.bits == 12));
    let e = validate(&format!(
        "kind = \"serial\"\n{}{map}",
        boards.replace("id = 1", "id = 0")
    ))
    .unwrap_err();
    assert!(e.contains("boards.b1.id"), "{e}");
    // opening a serial source does not touch the ports yet (they open per frame)
    let mut src = open_source(
        &parse(&format!(
            "kind = \"serial\"\ntimeout_ms = 50\n{boards}{map}"
        ))
        .unwrap(),
    )
    .unwrap();
    let e = src.next_frame().unwrap_err().to_string();
    assert!(e.contains("board b0 (/dev/ttyACM0)"), "{e}");

    let e = validate("kind = \"mock\"\ntrajectory = \"t.csv\"\n[faults]\nbus_error_prob = 1.5\n")
        .unwrap_err();
    assert!(e.contains("faults.bus_error_prob"), "{e}");
    let e = validate(
        "kind = \"mock\"\ntrajectory = \"t.csv\"\n[[faults.stuck]]\nr = 5\nc = 0\nvalue = 1\n",
    )
    .unwrap_err();
    assert!(e.contains("faults.stuck[0]"), "{e}");
    for (key, v) in [
        ("depth_bias_m", "1e300"),
        ("depth_bias_m", "nan"),
        ("pitch_bias_deg", "91.0"),
    ] {
        let e = validate(&format!(
            "kind = \"mock\"\ntrajectory = \"t.csv\"\n[faults]\n{key} = {v}\n"
        ))
        .unwrap_err();
        assert!(e.contains(&format!("faults.{key}")), "{e}");
    }
    validate("kind = \"mock\"\ntrajectory = \"t.csv\"\n[faults]\ndepth_bias_m = -0.3\npitch_bias_deg = 2.5\n")
        .unwrap();
}

#[test]
fn open_source_sim_from_files_and_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let traj = dir.path().join("t.csv");
    std::fs::write(
        &traj,
        "t,x,y,z,pitch,yaw\n0,8,0,0.1,0,0\n4,5,0.5,0.1,5,-5\n",
    )
    .unwrap();
    let text = format!(
        "kind = \"mock\"\nrate_hz = 0\nlooping = false\ntrajectory = \"{}\"\n[faults]\ndrop_every = 3\n",
        traj.display()
    );
    let mut src = open_source(&parse(&text).unwrap()).unwrap();
    assert!(
        src.describe().contains("injected faults"),
        "{}",
        src.describe()
    );
    let a = src.next_frame().unwrap();
    let b = src.next_frame().unwrap();
    assert_eq!((a.seq, b.seq), (0, 1));
    assert_eq!(src.next_frame().unwrap().seq, 3, "seq 2 dropped");
    let mut n = 0;
    while src.next_frame().is_ok() {
        n += 1;
        assert!(n < 10_000);
    }
    assert!(matches!(
        src.next_frame(),
        Err(lightpose_hal::SourceError::Ended)
    ));

    let missing = parse("kind = \"mock\"\ntrajectory = \"/nonexistent/t.csv\"\n").unwrap();
    let e = open_source(&missing).err().unwrap();
    assert!(matches!(e, HalError::Trajectory(_)), "{e:?}");
    assert!(e.to_string().contains("/nonexistent/t.csv"), "{e}");
}

/// The mock's loop key is `loop`, as for sim and replay (the name
/// config/lightposed.toml documents); `looping`, its first spelling, is
/// still read so that older configs keep working.
#[test]
fn mock_takes_loop_and_its_old_spelling_looping() {
    let looping = |extra: &str| {
        let text = format!("kind = \"mock\"\ntrajectory = \"t.csv\"\n{extra}");
        match validate(&text) {
            Ok(ValidBackend::Sim(p)) => Ok(p.looping),
            Ok(other) => panic!("not a simulator: {other:?}"),
            Err(e) => Err(e),
        }
    };
    assert_eq!(looping(""), Ok(true), "loops by default");
    assert_eq!(looping("loop = false\n"), Ok(false));
    assert_eq!(looping("loop = true\n"), Ok(true));
    assert_eq!(looping("looping = false\n"), Ok(false));
    let e = looping("loop = false\nlooping = true\n").unwrap_err();
    assert!(e.contains("duplicate field `loop`"), "{e}");
}

#[cfg(not(feature = "linux"))]
#[test]
fn hardware_kinds_need_the_linux_feature() {
    let e = open_source(&parse(&format!("{MCP_HEAD}{}", mcp_map())).unwrap())
        .err()
        .unwrap();
    assert_eq!(
        e.to_string(),
        "source kind \"mcp3008\" needs lightpose-hal built with feature \"linux\""
    );
}

#[cfg(feature = "linux")]
#[test]
fn hardware_kinds_name_the_missing_device() {
    let text = format!(
        "{}{}",
        MCP_HEAD.replace("/dev/spidev0.0", "/nonexistent/spidev9.9"),
        mcp_map()
    );
    let e = open_source(&parse(&text).unwrap()).err().unwrap();
    assert!(
        e.to_string().contains("board u0 (/nonexistent/spidev9.9)"),
        "{e}"
    );
}

/// A program's env: held texts by name, its own default trajectory.
struct Held;
impl lightpose_hal::Env for Held {
    fn default_rate_hz(&self) -> f64 {
        20.0
    }
    fn path(&self, written: &str) -> std::path::PathBuf {
        std::path::Path::new("/base").join(written)
    }
    fn text(
        &self,
        key: &str,
        written: Option<&str>,
    ) -> Result<lightpose_core::textfile::TextSource, String> {
        let text = match (key, written) {
            ("trajectory", None | Some("line")) => {
                "t,x,y,z,pitch,yaw\n0,8,0,0.1,0,0\n1,7,0,0.1,0,0\n"
            }
            ("scene", None) => "[adc]\nbits = 12\nrate_hz = 5.0\n",
            (_, w) => return Err(format!("{w:?} is not held")),
        };
        Ok(lightpose_core::textfile::TextSource::Held {
            name: format!("held:{key}"),
            text: text.into(),
        })
    }
}

#[test]
fn sim_kind_reads_the_texts_its_env_resolves() {
    let cfg = parse("kind = \"sim\"\nloop = false\n").unwrap();
    let v = cfg.validate(&Held).unwrap();
    assert_eq!(v.kind(), "sim");
    let mut src = lightpose_hal::open(&v, &Stop::new()).unwrap();
    assert_eq!(src.adc_bits(), 12, "the held scene");
    assert_eq!(src.rate_hz(), Some(20.0), "the env's rate");
    assert_eq!(src.period(), Some(std::time::Duration::from_millis(50)));
    let fast = v.free_running(Some(100.0)).unwrap();
    let mut fast_src = lightpose_hal::open(&fast, &Stop::new()).unwrap();
    assert_eq!((fast_src.period(), fast_src.rate_hz()), (None, Some(100.0)));
    assert!(fast_src.next_frame().is_ok() && src.next_frame().is_ok());
    let e = parse("kind = \"sim\"\nscene = \"other\"\n")
        .unwrap()
        .validate(&Held)
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "source config: scene: Some(\"other\") is not held"
    );
    let e = parse("kind = \"sim\"\npace = \"slow\"\n")
        .unwrap()
        .validate(&Held)
        .unwrap_err();
    assert!(
        e.to_string().contains("pace: \"slow\" is not a pace"),
        "{e}"
    );
    // A replay's log path is the env's to resolve; boards cannot run free.
    let r = parse("kind = \"replay\"\nlog = \"r.jsonl\"\n")
        .unwrap()
        .validate(&Held)
        .unwrap();
    assert!(
        matches!(&r, ValidBackend::Replay(p) if p.log == std::path::Path::new("/base/r.jsonl"))
    );
    let e = lightpose_hal::open(&r, &Stop::new()).err().unwrap();
    assert!(matches!(e, HalError::Log(_)), "{e:?}");
    let board = parse(&format!("{MCP_HEAD}{}", mcp_map())).unwrap();
    assert!(board.validate(&Held).unwrap().free_running(None).is_none());
}

// ---- issue 16: every number has a range, files are checked before a start --

/// A serial backend on one 16-channel board with `extra` keys.
fn serial_with(extra: &str, temperature: &str) -> String {
    let map: String = (0..25)
        .map(|k| {
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"b{}\"\nchannel = {}\n",
                k / 5,
                k % 5,
                k / 16,
                k % 16
            )
        })
        .collect();
    format!(
        "kind = \"serial\"\n{extra}\nboards = [{{ name = \"b0\", id = 0, path = \"/dev/ttyACM0\", channels = 16 }}, {{ name = \"b1\", id = 1, path = \"/dev/ttyACM1\", channels = 16 }}]\n{map}{temperature}"
    )
}

#[test]
fn numbers_out_of_their_range_are_refused_by_key() {
    let thermistor = |k: &str| {
        let r = if k.starts_with("r_fixed_ohm") {
            ""
        } else {
            "r_fixed_ohm = 10000.0\n"
        };
        format!("[temperature]\nkind = \"thermistor\"\nfallback_c = 20.0\nboard = \"b1\"\nchannel = 15\n{r}{k}\n")
    };
    let ds = |k: &str| format!("[temperature]\nkind = \"ds18b20\"\nfallback_c = 20.0\n{k}\n");
    for (text, key) in [
        (serial_with("timeout_ms = 600000", ""), "timeout_ms"),
        (serial_with("v_ref = 1e9", ""), "v_ref"),
        (serial_with("rate_hz = 1e9", ""), "rate_hz"),
        (
            serial_with("", "").replace(
                "path = \"/dev/ttyACM0\"",
                "path = \"/dev/ttyACM0\", baud = 100000000",
            ),
            "boards.b0.baud",
        ),
        (
            serial_with("", &thermistor("r_fixed_ohm = 1e300")),
            "temperature.r_fixed_ohm",
        ),
        (
            serial_with("", &thermistor("v_supply = 1e6")),
            "temperature.v_supply",
        ),
        (
            serial_with("", &thermistor("max_c = 1e6")),
            "temperature.max_c",
        ),
        (
            // A thermistor's window within water's: at 80 °C every
            // estimator would refuse the frame.
            serial_with("", &thermistor("max_c = 80.0")),
            "temperature.max_c",
        ),
        (
            serial_with("", &ds("interval_s = 1e9")),
            "temperature.interval_s",
        ),
        (
            serial_with("", &ds("max_age_s = 1e9")),
            "temperature.max_age_s",
        ),
        (
            serial_with(
                "",
                &ds("").replace("fallback_c = 20.0", "fallback_c = 400.0"),
            ),
            "temperature.fallback_c",
        ),
        (
            serial_with("", "[temperature]\nkind = \"fixed\"\nvalue_c = -300.0\n"),
            "temperature.value_c",
        ),
        (
            "kind = \"replay\"\nlog = \"x.jsonl\"\nmax_gap_s = 0.0\n".to_string(),
            "max_gap_s",
        ),
        (
            "kind = \"replay\"\nlog = \"x.jsonl\"\nmax_gap_s = 1e9\n".to_string(),
            "max_gap_s",
        ),
        ("kind = \"replay\"\nlog = \"\"\n".to_string(), "log"),
    ] {
        let e = validate(&text).expect_err(&text);
        assert!(
            e.starts_with(&format!("source config: {key}: ")),
            "{key}: {e}"
        );
        assert!(
            e.contains(" is not in ") || e.contains(" or in ") || e.contains("empty"),
            "{key}: {e}"
        );
    }
    // In range: accepted, with the gap bound.
    let v = validate("kind = \"replay\"\nlog = \"x.jsonl\"\nmax_gap_s = 2.5\n").unwrap();
    let ValidBackend::Replay(plan) = v else {
        panic!("{v:?}")
    };
    assert_eq!(plan.max_gap_s, 2.5);
}

#[test]
fn check_reads_every_file_a_start_would_and_opens_no_device() {
    let dir = tempfile::tempdir().unwrap();
    let check = |text: &str| {
        let v = parse(text).unwrap().validate(&PlainEnv).unwrap();
        lightpose_hal::check(&v)
    };
    // A missing trajectory, a corrupt one, a log with a bad header.
    let e = check("kind = \"mock\"\ntrajectory = \"/nonexistent/t.csv\"\n").unwrap_err();
    assert!(
        e.refuses_config() && e.to_string().contains("/nonexistent/t.csv"),
        "{e}"
    );
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "t,x\n").unwrap();
    let e = check(&format!(
        "kind = \"mock\"\ntrajectory = \"{}\"\n",
        bad.display()
    ))
    .unwrap_err();
    assert!(e.to_string().contains("bad.csv:1: header"), "{e}");
    let log = dir.path().join("bad.jsonl");
    std::fs::write(&log, "{\"class\":\"FRAME\"}\n").unwrap();
    let e = check(&format!("kind = \"replay\"\nlog = \"{}\"\n", log.display())).unwrap_err();
    assert!(e.refuses_config(), "{e}");
    assert!(
        e.to_string()
            .contains("bad.jsonl:1: first line must be class HEADER"),
        "{e}"
    );
    // Boards are not opened: a port that is not there yet is not a refusal.
    assert!(check(&serial_with("", "")).is_ok());
}
