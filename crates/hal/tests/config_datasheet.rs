//! Board tables checked against the chips' datasheets: a thermistor
//! divider's supply where the ADC is not ratiometric, the ADS1115's frame
//! time against the frame rate and its full scale against its supply, the
//! MCP3x08's clock against its supply. Every example in config/examples
//! still validates.

mod common;

use common::{map_tables, validate};
use lightpose_hal::config::{TempPlan, ValidBackend};
use lightpose_hal::{BackendConfig, PlainEnv};

/// `n` I²C chips (four per bus), detector k on chip k / per, channel k % per.
fn i2c_table(kind: &str, n: usize, per: usize, extra: &str) -> String {
    let chips: Vec<String> = (0..n)
        .map(|i| {
            format!(
                "{{ name = \"a{i}\", bus = \"/dev/i2c-{}\", address = 0x{:02X} }}",
                1 + i / 4,
                0x48 + i % 4
            )
        })
        .collect();
    format!(
        "kind = \"{kind}\"\n{extra}\nchips = [{}]\n{}",
        chips.join(", "),
        map_tables("a", per)
    )
}

/// Four MCP3x08 on SPI0/SPI1 as config/examples maps them (detector k on
/// chip k / 8, channel k % 8), `speed` appended to the first chip's table.
fn spi_table(kind: &str, extra: &str, speed: &str) -> String {
    let map: String = (0..25)
        .map(|k| {
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"u{}\"\nchannel = {}\n",
                k / 5,
                k % 5,
                k / 8,
                k % 8
            )
        })
        .collect();
    format!(
        "kind = \"{kind}\"\n{extra}\nchips = [{{ name = \"u0\", device = \"/dev/spidev0.0\"{speed} }}, {{ name = \"u1\", device = \"/dev/spidev0.1\" }}, {{ name = \"u2\", device = \"/dev/spidev1.0\" }}, {{ name = \"u3\", device = \"/dev/spidev1.1\" }}]\n{map}"
    )
}

fn thermistor(board: &str, channel: u8, extra: &str) -> String {
    format!("[temperature]\nkind = \"thermistor\"\nfallback_c = 20.0\nboard = \"{board}\"\nchannel = {channel}\nr_fixed_ohm = 10000.0\n{extra}\n")
}

fn supply_of(v: &ValidBackend) -> (f64, f64) {
    let common = match v {
        ValidBackend::Ads1115 { common, .. }
        | ValidBackend::Ads7828 { common, .. }
        | ValidBackend::Spi { common, .. } => common,
        other => panic!("not a board: {other:?}"),
    };
    match &common.temp {
        TempPlan::Thermistor { params, .. } => (params.v_supply, params.v_ref),
        other => panic!("not a thermistor: {other:?}"),
    }
}

#[test]
fn a_thermistor_divider_needs_its_supply_where_the_reference_is_not_it() {
    // ADS1115: the reference is the PGA's full scale, inside the chip.
    let base = i2c_table("ads1115", 7, 4, "fsr_v = 4.096");
    let e = validate(&format!("{base}{}", thermistor("a6", 2, ""))).unwrap_err();
    assert!(
        e.starts_with("source config: temperature.v_supply: required: ")
            && e.contains("fsr_v = 4.096 V")
            && !e.contains('\n'),
        "{e}"
    );
    let v = validate(&format!("{base}{}", thermistor("a6", 2, "v_supply = 3.3"))).unwrap();
    assert_eq!(supply_of(&v), (3.3, 4.096));

    // ADS7828 on its internal reference: the same, unless given.
    let base = i2c_table("ads7828", 4, 8, "");
    let e = validate(&format!("{base}{}", thermistor("a3", 7, ""))).unwrap_err();
    assert!(
        e.contains("temperature.v_supply: required: ") && e.contains("internal_ref = true"),
        "{e}"
    );
    let v = validate(&format!("{base}{}", thermistor("a3", 7, "v_supply = 2.5"))).unwrap();
    assert_eq!(supply_of(&v), (2.5, 2.5));

    // Ratiometric: ADS7828 on an external reference, MCP3008 (v_ref).
    let base = i2c_table("ads7828", 4, 8, "internal_ref = false\nv_ref = 3.3");
    let v = validate(&format!("{base}{}", thermistor("a3", 7, ""))).unwrap();
    assert_eq!(supply_of(&v), (3.3, 3.3));
    let mcp = i2c_table("ads7828", 4, 8, "v_ref = 3.3")
        .replace("kind = \"ads7828\"", "kind = \"mcp3008\"")
        .replace(
            "bus = \"/dev/i2c-1\", address = 0x48",
            "device = \"/dev/spidev0.0\"",
        )
        .replace(
            "bus = \"/dev/i2c-1\", address = 0x49",
            "device = \"/dev/spidev0.1\"",
        )
        .replace(
            "bus = \"/dev/i2c-1\", address = 0x4A",
            "device = \"/dev/spidev1.0\"",
        )
        .replace(
            "bus = \"/dev/i2c-1\", address = 0x4B",
            "device = \"/dev/spidev1.1\"",
        );
    let v = validate(&format!("{mcp}{}", thermistor("a3", 7, ""))).unwrap();
    assert_eq!(supply_of(&v), (3.3, 3.3));
}

#[test]
fn an_ads1115_frame_must_be_read_within_its_period() {
    // 7 chips, 25 channels: 4 rounds. At 32 SPS that is 4 × 34.4 ms of
    // conversions and 25 × 1.36 ms of 100 kHz bus: 171.5 ms, 86 % of 5 Hz.
    let t = |extra: &str| validate(&i2c_table("ads1115", 7, 4, extra));
    let e = t("rate_hz = 5.0\ndata_rate_sps = 32").unwrap_err();
    assert!(
        e.starts_with("source config: rate_hz: 5 Hz with data_rate_sps = 32: ")
            && e.contains("takes 171.5 ms")
            && e.contains("at most 4.66 Hz fits")
            && e.contains("assumed: no i2c_clock_hz")
            && !e.contains('\n'),
        "{e}"
    );
    // A known faster bus, a lower rate or a faster data rate fit.
    assert!(t("rate_hz = 5.0\ndata_rate_sps = 32\ni2c_clock_hz = 400000").is_ok());
    assert!(t("rate_hz = 4.5\ndata_rate_sps = 32").is_ok());
    assert!(t("rate_hz = 5.0\ndata_rate_sps = 128").is_ok());
    // as fast as it goes: nothing to miss
    assert!(t("rate_hz = 0\ndata_rate_sps = 8").is_ok());
    // 860 SPS: 4 × 1.28 ms + 34 ms of bus, 78 % of 20 Hz; a thermistor
    // channel is one more channel's transfers: 81 %.
    assert!(t("rate_hz = 20.0\ndata_rate_sps = 860").is_ok());
    let therm = thermistor("a6", 1, "v_supply = 3.3");
    let base = i2c_table("ads1115", 7, 4, "rate_hz = 20.0\ndata_rate_sps = 860");
    let e = validate(&format!("{base}{therm}")).unwrap_err();
    assert!(
        e.contains("takes 40.5 ms (4 conversions") && e.contains("26 channels"),
        "{e}"
    );
    assert!(e.contains("at most 19.76 Hz"), "{e}");
    // At the chip's fastest data rate the remedy is the bus, then chips.
    assert!(
        e.ends_with("or raise i2c_clock_hz (400 kHz fast mode)"),
        "{e}"
    );
    assert!(t("rate_hz = 5.0\ndata_rate_sps = 32")
        .unwrap_err()
        .ends_with("or raise data_rate_sps"));
    let fast = i2c_table(
        "ads1115",
        7,
        4,
        "rate_hz = 200.0\ndata_rate_sps = 860\ni2c_clock_hz = 400000",
    );
    let e = validate(&fast).unwrap_err();
    assert!(e.ends_with("or spread the channels over more chips"), "{e}");
    let e = t("i2c_clock_hz = 5000000").unwrap_err();
    assert!(
        e.contains("i2c_clock_hz: 5000000 is not in 10000..=3400000"),
        "{e}"
    );
}

#[test]
fn an_ads1115_full_scale_above_its_declared_supply_is_refused() {
    let t = |extra: &str| validate(&i2c_table("ads1115", 7, 4, extra));
    let e = t("fsr_v = 4.096\nvdd_v = 3.3").unwrap_err();
    assert!(
        e.starts_with("source config: fsr_v: 4.096 V is above vdd_v = 3.3 V")
            && e.contains("near 26399 of 32767")
            && e.contains("use fsr_v = 2.048"),
        "{e}"
    );
    let e = t("fsr_v = 6.144\nvdd_v = 5.0").unwrap_err();
    assert!(e.contains("use fsr_v = 4.096"), "{e}");
    assert!(t("fsr_v = 4.096\nvdd_v = 5.0").is_ok());
    assert!(t("fsr_v = 2.048\nvdd_v = 3.3").is_ok());
    // without vdd_v nothing is known, nothing refused
    assert!(t("fsr_v = 4.096").is_ok());
    let e = t("vdd_v = 1.8").unwrap_err();
    assert!(e.contains("vdd_v: 1.8 is not in 2..=5.5 V"), "{e}");
}

#[test]
fn an_mcp3x08_clock_follows_its_declared_supply() {
    let mcp = |kind: &str, extra: &str, speed: &str| {
        validate(&spi_table(kind, extra, speed)).map(|v| match v {
            ValidBackend::Spi { chips, .. } => chips[0].max_speed_hz,
            other => panic!("not SPI: {other:?}"),
        })
    };
    // Unknown supply: the 2.7 V figure, by default and at most.
    assert_eq!(mcp("mcp3008", "", ""), Ok(1_350_000));
    assert_eq!(mcp("mcp3208", "", ""), Ok(1_000_000));
    let e = mcp("mcp3008", "", ", max_speed_hz = 3600000").unwrap_err();
    assert!(
        e.starts_with("source config: chips.u0.max_speed_hz: 3600000 is above 1350000, the MCP3008's limit at 2.7 V; declare the chips' supply as vdd_v"),
        "{e}"
    );
    // Declared: on the line between the 2.7 V and 5 V figures.
    assert_eq!(mcp("mcp3008", "vdd_v = 5.0", ""), Ok(3_600_000));
    assert_eq!(mcp("mcp3008", "vdd_v = 3.3", ""), Ok(1_936_956));
    assert_eq!(
        mcp("mcp3008", "vdd_v = 5.0", ", max_speed_hz = 3600000"),
        Ok(3_600_000)
    );
    let e = mcp("mcp3208", "vdd_v = 3.3", ", max_speed_hz = 2000000").unwrap_err();
    assert!(
        e.contains("2000000 is above 1260869, the MCP3208's limit at vdd_v = 3.3 V"),
        "{e}"
    );
    let e = mcp("mcp3008", "vdd_v = 2.5", "").unwrap_err();
    assert!(e.contains("vdd_v: 2.5 is not in 2.7..=5.5 V"), "{e}");
    let e = mcp("mcp3008", "", ", max_speed_hz = 0").unwrap_err();
    assert!(e.contains("0 is not in 1..=1350000"), "{e}");
}

/// Spec v3: `sample_hz` samples of every channel a second. Whether the
/// bank keeps up is computed from its clocks and transfer sizes
/// (`config::timing`) and said at validation, so `--check-config` tells;
/// so is the spacing of its channels (MODEL.md `channel_skew_s`).
#[test]
fn a_sample_rate_is_checked_against_what_the_bus_can_give() {
    let spi = |extra: &str| {
        validate(&spi_table(
            "mcp3008",
            &format!("rate_hz = 5.0\n{extra}"),
            "",
        ))
    };
    // One sample a frame: the bank's spacing is known all the same. At the
    // 2.7 V clock (1.35 MHz) a channel is 24 clocks and the kernel's 10 µs.
    let v = spi("").expect("5 Hz fits");
    let ValidBackend::Spi { common, .. } = &v else {
        panic!("{v:?}")
    };
    assert_eq!(common.samples_per_frame, 1);
    assert!(
        (common.channel_skew_s - (24.0 / 1.35e6 + 10e-6)).abs() < 1e-12,
        "{}",
        common.channel_skew_s
    );
    // 2 kHz is more than 25 such channels give (at most 1152 Hz) ...
    let e = spi("sample_hz = 2000.0").unwrap_err();
    assert!(
        e.starts_with("source config: sample_hz: 2000 Hz: one sample of every channel takes 694.4 µs (25 transfers")
            && e.contains("at most 1152.0 Hz fits")
            && !e.contains('\n'),
        "{e}"
    );
    // ... but at 3.6 MHz (vdd_v = 5) the bank gives 1.92 kHz: the bus check
    // passes, and a burst needs a blinking beacon to demodulate.
    let e = spi("vdd_v = 5.0\nsample_hz = 1000.0").unwrap_err();
    assert!(
        e.starts_with("source config: beacons: ") && e.contains("no beacon blinks"),
        "{e}"
    );
    let v = spi("vdd_v = 5.0\nsample_hz = 1000.0\nbeacons = [{ id = \"beacon\", mod_hz = 250.0 }]")
        .expect("1 kHz fits at 3.6 MHz");
    let ValidBackend::Spi { common, .. } = &v else {
        panic!("{v:?}")
    };
    let s = common.sampling().expect("bursts");
    assert_eq!((s.samples_per_frame, s.sample_hz), (200, 1000.0));
    assert!((s.channel_skew_s - (24.0 / 3.6e6 + 10e-6)).abs() < 1e-12);
    assert_eq!(
        (s.beacons[0].id.as_str(), s.beacons[0].mod_hz),
        ("beacon", 250.0)
    );
    // A mod_hz the samples cannot resolve (3 samples a period), and
    // beacons without sample_hz, are refused at `beacons`.
    let e = spi(
        "vdd_v = 5.0\nsample_hz = 1000.0\nbeacons = [{ id = \"b\", mod_hz = 333.3333333333333 }]",
    )
    .unwrap_err();
    assert!(e.starts_with("source config: beacons: beacon \"b\""), "{e}");
    let e = spi("beacons = [{ id = \"b\", mod_hz = 250.0 }]").unwrap_err();
    assert!(e.contains("beacons: given without sample_hz"), "{e}");
    // N must be whole, and needs a paced rate.
    let e = spi("sample_hz = 12.5").unwrap_err();
    assert!(
        e.contains("sample_hz: 12.5 is not a whole multiple of rate_hz = 5"),
        "{e}"
    );
    assert!(spi("sample_hz = 5.0").is_ok(), "one sample a frame, said");
    let e = spi("sample_hz = 5.0").map(|_| ()).and(
        validate(&i2c_table(
            "ads7828",
            4,
            8,
            "rate_hz = 0\nsample_hz = 100.0",
        ))
        .map(|_| ()),
    );
    assert!(e.unwrap_err().contains("sample_hz: needs a frame rate"));
    // I²C: 25 ADS7828 conversions at 100 kHz take 13.25 ms: 5 Hz fits, 65 Hz
    // does not, and no blinking beacon can be sampled.
    assert!(validate(&i2c_table("ads7828", 4, 8, "rate_hz = 5.0")).is_ok());
    let e = validate(&i2c_table("ads7828", 4, 8, "rate_hz = 65.0")).unwrap_err();
    assert!(
        e.starts_with("source config: rate_hz: 65 Hz: one sample of every channel takes 13.25 ms"),
        "{e}"
    );
    let e = validate(&i2c_table(
        "ads7828",
        4,
        8,
        "rate_hz = 5.0\ni2c_clock_hz = 400000\nsample_hz = 500.0",
    ))
    .unwrap_err();
    assert!(e.contains("at most 196.9 Hz fits"), "{e}");
    let e = validate(&i2c_table(
        "ads1115",
        7,
        4,
        "rate_hz = 5.0\ndata_rate_sps = 860\nsample_hz = 500.0",
    ))
    .unwrap_err();
    assert!(
        e.starts_with("source config: sample_hz: 500 Hz: one sample of every channel takes"),
        "{e}"
    );
}

#[test]
fn the_shipped_board_examples_validate() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples");
    for name in [
        "ads1115.toml",
        "ads7828.toml",
        "mcp3008.toml",
        "mcp3008-beacon.toml",
    ] {
        let text = std::fs::read_to_string(dir.join(name)).unwrap();
        let table: toml::Table = toml::from_str(&text).unwrap();
        let backend = table["backend"].clone();
        let cfg: BackendConfig = backend.try_into().unwrap_or_else(|e| panic!("{name}: {e}"));
        cfg.validate(&PlainEnv)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

/// An ADS1115 bank can sample a slow beacon: seven chips at 860 SPS and
/// 400 kHz give at most 58.8 samples a second, so 40 Hz of samples at
/// 10 frames a second (N = 4) and a 10 Hz beacon (4 samples a period)
/// pass; the skew it reports is the mean spacing of its rounds.
#[test]
fn an_ads1115_bank_samples_a_slow_beacon_and_refuses_a_mod_hz_it_cannot_resolve() {
    let t = |extra: &str| {
        validate(&i2c_table(
            "ads1115",
            7,
            4,
            &format!("rate_hz = 10.0\ni2c_clock_hz = 400000\nsample_hz = 40.0\n{extra}"),
        ))
    };
    let v = t("beacons = [{ id = \"b\", mod_hz = 10.0 }]").expect("fits");
    let ValidBackend::Ads1115 { common, .. } = &v else {
        panic!("{v:?}")
    };
    let s = common.sampling().expect("bursts");
    assert_eq!((s.samples_per_frame, s.sample_hz), (4, 40.0));
    assert!(s.channel_skew_s > 0.0 && s.channel_skew_s * 25.0 < 1.0 / 40.0);
    // 40 / 15 samples a period is no whole number.
    let e = t("beacons = [{ id = \"b\", mod_hz = 15.0 }]").unwrap_err();
    assert!(e.starts_with("source config: beacons: beacon \"b\""), "{e}");
    // Two beacons with one id.
    let e =
        t("beacons = [{ id = \"b\", mod_hz = 10.0 }, { id = \"b\", mod_hz = 5.0 }]").unwrap_err();
    assert!(e.contains("beacons: name \"b\" is used twice"), "{e}");
}
