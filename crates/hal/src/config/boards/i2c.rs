//! The I²C boards' validators: ADS1115 (its data rate, supply and how
//! many frames a bus can carry) and ADS7828, and the chips' bus layout.

use super::*;

/// `kind = "ads1115"`.
pub(in crate::config) fn ads1115(
    c: &Ads1115Config,
    env: &dyn Env,
) -> Result<ValidBackend, HalError> {
    let fsr = Fsr::from_volts(c.fsr_v).ok_or_else(|| {
        err(
            "fsr_v",
            format!(
                "{} is not one of 6.144, 4.096, 2.048, 1.024, 0.512, 0.256",
                c.fsr_v
            ),
        )
    })?;
    let data_rate = DataRate::from_sps(c.data_rate_sps).ok_or_else(|| {
        err(
            "data_rate_sps",
            format!(
                "{} is not one of 8, 16, 32, 64, 128, 250, 475, 860",
                c.data_rate_sps
            ),
        )
    })?;
    ads1115_supply(c.vdd_v, fsr)?;
    let scl = match c.i2c_clock_hz {
        Some(hz) if (10_000..=ads1115::MAX_CLOCK_HZ).contains(&hz) => Some(hz),
        Some(hz) => {
            return Err(err(
                "i2c_clock_hz",
                format!("{hz} is not in 10000..={}", ads1115::MAX_CLOCK_HZ),
            ))
        }
        None => None,
    };
    let (buses, chips) = i2c_layout(&c.chips, ads1115::ADDR_MIN, ads1115::ADDR_MAX)?;
    let boards = i2c_boards(&chips, ads1115::CHANNELS);
    let shared = Shared {
        rate_hz: c.rate_hz,
        sample_hz: c.sample_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: ads1115::BITS,
        v_ref: fsr.volts(),
        supply: DividerSupply::Required(format!(
            "an ADS1115's reference is its PGA full scale (fsr_v = {} V), inside the chip and not the divider's supply; give the voltage the divider hangs off (e.g. 3.3)",
            fsr.volts()
        )),
    };
    let mut common = common(shared, boards, env)?;
    match c.sample_hz {
        // One sample a frame: the frame rule as it always was.
        None => ads1115_frame_fits(&common, data_rate, scl)?,
        Some(_) => {
            let wanted = wanted_counts(&common);
            let rounds = wanted.iter().copied().max().unwrap_or(0);
            let n: u32 = wanted.iter().sum();
            let hz = scl.unwrap_or(timing::DEFAULT_I2C_HZ);
            let what = format!(
                "{rounds} conversions of 1.1/DR at data_rate_sps = {}, {n} channels' I2C transfers at {} kHz",
                data_rate.sps(),
                hz / 1000
            );
            timing::keeps_up(
                &mut common,
                c.sample_hz,
                timing::ads1115(rounds, n, data_rate, hz),
                &what,
            )?;
        }
    }
    with_beacons(&mut common, &c.beacons)?;
    Ok(ValidBackend::Ads1115 {
        fsr,
        data_rate,
        buses,
        chips,
        common,
    })
}

/// With the supply declared, a full scale above it is refused: the inputs
/// are measured only up to VDD, so the top counts (and saturation) never
/// come.
fn ads1115_supply(vdd_v: Option<f64>, fsr: Fsr) -> Result<(), HalError> {
    let Some(v) = vdd_v else { return Ok(()) };
    let vdd = within("vdd_v", v, 2.0, 5.5, " V")?;
    if fsr.volts() <= vdd {
        return Ok(());
    }
    let top = (vdd / fsr.volts() * 32767.0).round();
    let fits = [6.144, 4.096, 2.048, 1.024, 0.512, 0.256]
        .into_iter()
        .find(|&f| f <= vdd)
        .unwrap_or(0.256);
    Err(err(
        "fsr_v",
        format!(
            "{} V is above vdd_v = {vdd} V: the inputs are measured only up to VDD, so counts stop near {top} of 32767 and saturation is never seen; use fsr_v = {fits} or lower",
            fsr.volts()
        ),
    ))
}

/// The frame must be read well within its period: the ADS1115 converts
/// for 1.1/DR a channel (the bank overlaps one channel of every chip) and
/// every channel costs bus time. Above 80 % of the period the pacer would
/// slip behind and the frames' rate be a lie.
fn ads1115_frame_fits(common: &Common, dr: DataRate, scl: Option<u32>) -> Result<(), HalError> {
    let Some(rate) = common.rate_hz else {
        return Ok(());
    };
    let wanted = common.wanted();
    let rounds = wanted.iter().map(|m| m.count_ones()).max().unwrap_or(0);
    let channels: u32 = wanted.iter().map(|m| m.count_ones()).sum();
    let hz = scl.unwrap_or(100_000);
    let secs = ads1115::frame_read_ns(rounds, channels, dr, hz) as f64 * 1e-9;
    if rate * secs <= 0.8 {
        return Ok(());
    }
    let assumed = if scl.is_some() {
        ""
    } else {
        ", assumed: no i2c_clock_hz"
    };
    // What else would shorten the read: a faster chip, else a faster bus.
    let remedy = if dr.sps() < 860 {
        "or raise data_rate_sps"
    } else if hz < 400_000 {
        "or raise i2c_clock_hz (400 kHz fast mode)"
    } else {
        "or spread the channels over more chips"
    };
    Err(err(
        "rate_hz",
        format!(
            "{rate} Hz with data_rate_sps = {}: reading a frame takes {:.1} ms ({rounds} conversions of 1.1/DR in turn, {channels} channels' I2C transfers at {} kHz{assumed}), over 80 % of the {:.1} ms period; at most {:.2} Hz fits, {remedy}",
            dr.sps(),
            secs * 1e3,
            hz as f64 / 1e3,
            1e3 / rate,
            0.8 / secs
        ),
    ))
}

/// `kind = "ads7828"`.
pub(in crate::config) fn ads7828(
    c: &Ads7828Config,
    env: &dyn Env,
) -> Result<ValidBackend, HalError> {
    let (power, v_ref) = match (c.internal_ref, c.v_ref) {
        (true, None) => (PowerMode::InternalRef, 2.5),
        (true, Some(v)) if (v - 2.5).abs() < 1e-9 => (PowerMode::InternalRef, 2.5),
        (true, Some(v)) => {
            return Err(err(
                "v_ref",
                format!("{v} V given with internal_ref = true (the internal reference is 2.5 V)"),
            ))
        }
        (false, Some(v)) => (
            PowerMode::ExternalRef,
            positive_to("v_ref", v, MAX_V, " V")?,
        ),
        (false, None) => return Err(err("v_ref", "required when internal_ref = false")),
    };
    let (buses, chips) = i2c_layout(&c.chips, ads7828::ADDR_MIN, ads7828::ADDR_MAX)?;
    let boards = i2c_boards(&chips, ads7828::CHANNELS);
    let supply = match power {
        PowerMode::InternalRef => DividerSupply::Required(
            "with internal_ref = true the reference is the chip's own 2.5 V, the divider's supply only if it hangs off REFOUT (then give 2.5); give the voltage the divider hangs off".into(),
        ),
        _ => DividerSupply::IsRef,
    };
    let scl = match c.i2c_clock_hz {
        None => timing::DEFAULT_I2C_HZ,
        Some(hz) if (10_000..=ads7828::MAX_CLOCK_HZ).contains(&hz) => hz,
        Some(hz) => {
            return Err(err(
                "i2c_clock_hz",
                format!("{hz} is not in 10000..={}", ads7828::MAX_CLOCK_HZ),
            ))
        }
    };
    let shared = Shared {
        rate_hz: c.rate_hz,
        sample_hz: c.sample_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: 12,
        v_ref,
        supply,
    };
    let mut common = common(shared, boards, env)?;
    let n: u32 = wanted_counts(&common).iter().sum();
    let what = format!(
        "{n} conversions of {} I2C clocks at {} kHz and two messages of {:.0} µs each",
        timing::ADS7828_CLOCKS_PER_CHANNEL,
        scl / 1000,
        timing::I2C_MESSAGE_OVERHEAD_S * 1e6
    );
    timing::keeps_up(&mut common, c.sample_hz, timing::ads7828(n, scl), &what)?;
    with_beacons(&mut common, &c.beacons)?;
    Ok(ValidBackend::Ads7828 {
        power,
        buses,
        chips,
        common,
    })
}

fn i2c_boards(chips: &[I2cChipPlan], channels: u8) -> Vec<BoardSpec> {
    chips
        .iter()
        .map(|p| BoardSpec {
            name: p.name.clone(),
            channels,
        })
        .collect()
}

/// Buses in order of first use, and each chip's bus index; two chips on one
/// bus and address are refused.
fn i2c_layout(
    chips: &[I2cChipConfig],
    lo: u8,
    hi: u8,
) -> Result<(Vec<String>, Vec<I2cChipPlan>), HalError> {
    unique_names("chips", chips.iter().map(|c| c.name.as_str()))?;
    let mut buses: Vec<String> = Vec::new();
    let mut plans: Vec<I2cChipPlan> = Vec::new();
    for c in chips {
        if !(lo..=hi).contains(&c.address) {
            return Err(err(
                format!("chips.{}.address", c.name),
                format!("0x{:02X} is not in 0x{lo:02X}..=0x{hi:02X}", c.address),
            ));
        }
        let bus = match buses.iter().position(|b| *b == c.bus) {
            Some(i) => i,
            None => {
                buses.push(c.bus.clone());
                buses.len() - 1
            }
        };
        if let Some(other) = plans
            .iter()
            .find(|p| p.bus == bus && p.address == c.address)
        {
            return Err(err(
                format!("chips.{}.address", c.name),
                format!(
                    "0x{:02X} on {} is also chip \"{}\"",
                    c.address, c.bus, other.name
                ),
            ));
        }
        plans.push(I2cChipPlan {
            name: c.name.clone(),
            bus,
            address: c.address,
        });
    }
    Ok((buses, plans))
}
