//! Scene files with well-typed but impossible numbers (NaN, inf, 1e300,
//! negative noise, an offset outside the ADC, …) are refused with one line
//! naming the file, the line, `[table] key` and the bound; every scene the
//! repository ships or tests with still loads.

use lightpose_sim::Scene;
use std::path::{Path, PathBuf};

/// Every float key of a scene file, by table.
const FLOAT_KEYS: &[(&str, &str)] = &[
    ("beacon", "v1"),
    ("beacon", "sigma_b_deg"),
    ("water", "k_d"),
    ("water", "temp_c"),
    ("scattering", "omega"),
    ("scattering", "sigma_h_deg"),
    ("array", "spacing_deg"),
    ("array", "radius_m"),
    ("array", "sigma_r_deg"),
    ("array", "gain"),
    ("array", "offset_v"),
    ("adc", "v_ref"),
    ("adc", "rate_hz"),
    ("noise", "sigma_e_v"),
    ("noise", "kappa_v"),
    ("noise", "sigma_temp_c"),
    ("montecarlo", "sigma_temp_c"),
    ("montecarlo", "sigma_k_d"),
    ("attitude", "sigma_pitch_deg"),
    ("attitude", "sigma_yaw_deg"),
    ("depth", "sigma_m"),
    ("dvl", "sigma_mps"),
];

/// The one-line error of a refused scene; panics (the test fails) if accepted.
fn refused(text: &str) -> String {
    match Scene::parse(text, "bad.toml") {
        Ok(_) => panic!("accepted: {text:?}"),
        Err(e) => {
            let e = e.to_string();
            assert_eq!(e.lines().count(), 1, "error spans lines: {e}");
            e
        }
    }
}

fn accepted(text: &str) -> Scene {
    match Scene::parse(text, "good.toml") {
        Ok(s) => s,
        Err(e) => panic!("refused {text:?}: {e}"),
    }
}

/// `[table]` with `key = value` on line 3 (a comment first, so the line is checked).
fn scene(table: &str, key: &str, value: &str) -> String {
    format!("# bad\n[{table}]\n{key} = {value}\n")
}

#[test]
fn non_finite_and_huge_numbers_are_refused_for_every_key() {
    for &(table, key) in FLOAT_KEYS {
        let low = if key == "temp_c" { "-1e300" } else { "-1" };
        for value in ["nan", "inf", "-inf", "1e300", "-1e300", low] {
            let e = refused(&scene(table, key, value));
            let want = format!("bad.toml:3: [{table}] {key}: ");
            assert!(e.starts_with(&want), "{table}.{key} = {value}: {e}");
            assert!(e.contains("must be in "), "no bound named: {e}");
        }
    }
}

/// Each rule family: (scene text, the `[table] key` named, the bound named).
#[test]
fn each_rule_names_its_key_and_bound() {
    let cases: &[(&str, &str, &str)] = &[
        // dark offsets are ADC readings: within [0, v_ref]
        (
            "[array]\noffset_v = -1\n",
            "[array] offset_v",
            "in [0, 5] V",
        ),
        (
            "[array]\noffset_v = 5.01\n",
            "[array] offset_v",
            "in [0, 5] V",
        ),
        (
            "[adc]\nv_ref = 3.3\n[array]\noffset_v = 4\n",
            "[array] offset_v",
            "in [0, 3.3] V",
        ),
        // noise sigmas within the ADC range; the temperature's within the temperature range
        (
            "[noise]\nsigma_e_v = 5.5\n",
            "[noise] sigma_e_v",
            "in [0, 5] V",
        ),
        (
            "[noise]\nkappa_v = 1e300\n",
            "[noise] kappa_v",
            "in [0, 5] V",
        ),
        (
            "[noise]\nsigma_temp_c = -0.1\n",
            "[noise] sigma_temp_c",
            "in [0, 65] °C",
        ),
        (
            "[montecarlo]\nsigma_temp_c = 51\n",
            "[montecarlo] sigma_temp_c",
            "in [0, 50] °C",
        ),
        (
            "[montecarlo]\nsigma_k_d = 10.5\n",
            "[montecarlo] sigma_k_d",
            "in [0, 10] m⁻¹",
        ),
        // vehicle sensors below generous physical bounds
        (
            "[depth]\nsigma_m = 100.5\n",
            "[depth] sigma_m",
            "in [0, 100] m",
        ),
        (
            "[dvl]\nsigma_mps = 11\n",
            "[dvl] sigma_mps",
            "in [0, 10] m/s",
        ),
        (
            "[attitude]\nsigma_yaw_deg = 181\n",
            "[attitude] sigma_yaw_deg",
            "in [0, 180]°",
        ),
        // the beacon: 0 (off) up to 1e6 × v_ref
        (
            "[beacon]\nv1 = 5.1e6\n",
            "[beacon] v1",
            "in [0, 5000000] V·m²",
        ),
        (
            "[adc]\nv_ref = 1\n[beacon]\nv1 = 2e6\n",
            "[beacon] v1",
            "in [0, 1000000] V·m²",
        ),
        (
            "[beacon]\nsigma_b_deg = 90\n",
            "[beacon] sigma_b_deg",
            "in (0, 90)°",
        ),
        // water and scattering
        ("[water]\nk_d = 150\n", "[water] k_d", "in [0, 100] m⁻¹"),
        ("[water]\ntemp_c = -6\n", "[water] temp_c", "in [-5, 60] °C"),
        ("[water]\ntemp_c = 61\n", "[water] temp_c", "in [-5, 60] °C"),
        (
            "[scattering]\nomega = 1001\n",
            "[scattering] omega",
            "in [0, 1000]",
        ),
        (
            "[scattering]\nsigma_h_deg = 0\n",
            "[scattering] sigma_h_deg",
            "in (0, 90)°",
        ),
        // the array and the ADC
        (
            "[array]\nradius_m = 0\n",
            "[array] radius_m",
            "in (0, 10] m",
        ),
        (
            "[array]\nradius_m = 11\n",
            "[array] radius_m",
            "in (0, 10] m",
        ),
        ("[array]\ngain = 0\n", "[array] gain", "in (0, 1000]"),
        ("[array]\ngain = 1e4\n", "[array] gain", "in (0, 1000]"),
        (
            "[array]\nspacing_deg = 30\n",
            "[array] spacing_deg",
            "in (0, 22.5]°",
        ),
        ("[adc]\nv_ref = 0\n", "[adc] v_ref", "in [0.001, 50] V"),
        ("[adc]\nv_ref = 51\n", "[adc] v_ref", "in [0.001, 50] V"),
        (
            "[adc]\nrate_hz = 0\n",
            "[adc] rate_hz",
            "in (0, 1000000] Hz",
        ),
    ];
    for (text, key, bound) in cases {
        let e = refused(text);
        let line = text.lines().count();
        assert!(
            e.starts_with(&format!("bad.toml:{line}: {key}: ")),
            "{text:?}: {e}"
        );
        assert!(e.contains(bound), "{text:?}: want {bound:?} in {e}");
    }
}

#[test]
fn a_bad_channel_and_a_default_that_does_not_fit_are_named() {
    let list = |last: &str| format!("[array]\noffset_v = [{}{last}]\n", "0.1, ".repeat(24));
    let e = refused(&list("-0.2"));
    assert!(
        e.starts_with("bad.toml:2: [array] offset_v: channel 24 = -0.2 is impossible"),
        "{e}"
    );
    // A 0.1 V reference leaves no room for the default 0.15 V offset.
    let e = refused("[adc]\nv_ref = 0.1\n");
    assert!(
        e.contains("[array] offset_v: the default 0.15 is impossible here: must be in [0, 0.1] V"),
        "{e}"
    );
}

#[test]
fn generous_but_legitimate_values_are_accepted() {
    let s = accepted("[beacon]\nv1 = 0\n");
    assert_eq!(s.light.v1, 0.0); // the beacon off: a dark sweep
    let s = accepted("[beacon]\nv1 = 1e6\n"); // saturates at any range: still a test scene
    assert_eq!(s.light.v1, 1e6);
    let s = accepted("[array]\noffset_v = 5.0\n[noise]\nsigma_e_v = 0\nkappa_v = 5\n");
    assert_eq!(s.offset_v[0], 5.0);
    let s = accepted("[array]\noffset_v = 0\n[water]\nk_d = 0\ntemp_c = -5\n");
    assert_eq!((s.offset_v[7], s.light.k_d, s.temp_c), (0.0, 0.0, -5.0));
    let s = accepted("[adc]\nv_ref = 10\n[array]\noffset_v = 7.5\n");
    assert_eq!(s.offset_v[24], 7.5);
    let s =
        accepted("[depth]\nsigma_m = 50\n[dvl]\nsigma_mps = 5\n[attitude]\nsigma_yaw_deg = 180\n");
    assert_eq!(s.depth.map(|d| d.sigma_m), Some(50.0));
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn every_shipped_and_tested_scene_still_loads() {
    let dirs = [
        "config/scenes",
        "tests/data",
        "tests/data/heldout",
        "fuzz/seeds/scene",
    ];
    let mut n = 0;
    for dir in dirs {
        let entries = std::fs::read_dir(repo().join(dir)).expect("scene directory");
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                if let Err(e) = Scene::load(&path) {
                    panic!("{} no longer loads: {e}", path.display());
                }
                n += 1;
            }
        }
    }
    assert!(n >= 10, "only {n} scenes found");
    let example = repo().join("../shared/spec/scene-example.toml");
    if let Err(e) = Scene::load(&example) {
        panic!("scene-example.toml no longer loads: {e}");
    }
}
