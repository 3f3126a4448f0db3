//! Embeds the shipped default config, tank scene, zigzag trajectory and tank
//! calibration into the binary so that `lightposed` with no arguments runs
//! from anywhere. Those files are written by other parts of the project; a
//! plain `include_str!` would break the build while one is missing, so this
//! script emits `Some(include_str!(..))` for each file that exists and `None`
//! otherwise, and asks cargo to look again whenever one appears or changes.

use std::io::Write;
use std::path::{Path, PathBuf};

fn main() {
    let manifest =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let root = manifest.join("../..");
    let files = [
        ("DEFAULT_CONFIG", "config/lightposed.toml"),
        ("TANK_SCENE", "config/scenes/tank.toml"),
        ("ZIGZAG_TRAJECTORY", "config/trajectories/zigzag.csv"),
        ("TANK_CALIBRATION", "config/calibration/tank.toml"),
    ];
    let out =
        PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("embedded.rs");
    let mut f = std::fs::File::create(&out).expect("OUT_DIR is writable");
    for (name, rel) in files {
        let path = root.join(rel);
        // A missing file is watched too: cargo reruns this script until it exists.
        println!("cargo:rerun-if-changed={}", path.display());
        let value = if Path::new(&path).is_file() {
            let abs = path.canonicalize().expect("an existing file canonicalizes");
            format!("Some(include_str!({:?}))", abs.display().to_string())
        } else {
            "None".to_string()
        };
        writeln!(f, "/// `{rel}` at build time, `None` if it did not exist.").expect("write");
        writeln!(f, "pub const {name}: Option<&str> = {value};").expect("write");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
