//! Which of the vehicle's own sensors a simulated run carries (spec v2):
//! the sets that `lightpose bench` and `lightpose crb` compare, from the
//! light alone to attitude + depth + DVL.
//!
//! Why one type: the trade table, the bound and the diagnostics must mean
//! the same scene by "depth alone", so a set is applied to a scene in one
//! place: a sensor the set has keeps the scene's own noise if the scene
//! names it, else takes MODEL.md's; a sensor the set lacks is removed.

use lightpose_sim::Scene;
#[cfg(test)]
use lightpose_sim::{DepthNoise, DvlNoise};

/// A set of own sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SensorSet {
    pub attitude: bool,
    pub depth: bool,
    pub dvl: bool,
}

/// What `--sensors` takes, for error messages.
pub const CHOICES: &str =
    "scene, none, attitude, depth, attitude+depth or all (or a + of attitude, depth, dvl)";

/// `--sensors` of `crb` and `montecarlo`: `scene` leaves the scene's own
/// sensors as they are; any other word is a set ([`SensorSet::parse`]) put
/// on the scene. `None` when the word is neither.
pub fn apply_choice(choice: &str, scene: &mut Scene) -> Option<()> {
    if choice != "scene" {
        SensorSet::parse(choice)?.apply(scene);
    }
    Some(())
}

impl SensorSet {
    pub const NONE: SensorSet = SensorSet::new(false, false, false);
    pub const ATTITUDE: SensorSet = SensorSet::new(true, false, false);
    pub const DEPTH: SensorSet = SensorSet::new(false, true, false);
    pub const ATTITUDE_DEPTH: SensorSet = SensorSet::new(true, true, false);
    pub const ALL: SensorSet = SensorSet::new(true, true, true);

    /// The five sets of the trade table, from none to all.
    pub const TABLE: [SensorSet; 5] = [
        SensorSet::NONE,
        SensorSet::ATTITUDE,
        SensorSet::DEPTH,
        SensorSet::ATTITUDE_DEPTH,
        SensorSet::ALL,
    ];

    pub const fn new(attitude: bool, depth: bool, dvl: bool) -> Self {
        SensorSet {
            attitude,
            depth,
            dvl,
        }
    }

    /// The words `--sensors` takes: `none`, `all`, or sensors joined by
    /// `+` (`attitude`, `depth`, `dvl`), e.g. `attitude+depth`.
    pub fn parse(s: &str) -> Option<SensorSet> {
        match s {
            "none" => return Some(SensorSet::NONE),
            "all" => return Some(SensorSet::ALL),
            _ => {}
        }
        let mut set = SensorSet::NONE;
        for w in s.split('+') {
            let slot = match w.trim() {
                "attitude" => &mut set.attitude,
                "depth" => &mut set.depth,
                "dvl" => &mut set.dvl,
                _ => return None,
            };
            if *slot {
                return None;
            }
            *slot = true;
        }
        Some(set)
    }

    /// The set's name as [`SensorSet::parse`] reads it.
    pub fn name(&self) -> String {
        match *self {
            SensorSet::NONE => "none".into(),
            SensorSet::ALL => "all".into(),
            s => {
                let mut w = Vec::new();
                for (on, n) in [(s.attitude, "attitude"), (s.depth, "depth"), (s.dvl, "dvl")] {
                    if on {
                        w.push(n);
                    }
                }
                w.join("+")
            }
        }
    }

    /// Words for a table heading ("attitude + depth + DVL", "no own sensor").
    pub fn label(&self) -> String {
        if *self == SensorSet::NONE {
            return "no own sensor".into();
        }
        let mut w = Vec::new();
        for (on, n) in [
            (self.attitude, "attitude"),
            (self.depth, "depth"),
            (self.dvl, "DVL"),
        ] {
            if on {
                w.push(n);
            }
        }
        w.join(" + ")
    }

    /// The set the scene itself has.
    pub fn of(scene: &Scene) -> SensorSet {
        SensorSet::new(
            scene.attitude.is_some(),
            scene.depth.is_some(),
            scene.dvl.is_some(),
        )
    }

    /// Give `scene` exactly this set: a sensor it names keeps its noise,
    /// one it lacks gets MODEL.md's, one not in the set is removed.
    pub fn apply(&self, scene: &mut Scene) {
        scene.attitude = self.attitude.then(|| scene.attitude.unwrap_or_default());
        scene.depth = self.depth.then(|| scene.depth.unwrap_or_default());
        scene.dvl = self.dvl.then(|| scene.dvl.unwrap_or_default());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_words_are_refused() {
        for s in SensorSet::TABLE {
            assert_eq!(SensorSet::parse(&s.name()), Some(s));
        }
        assert_eq!(
            SensorSet::parse("depth+attitude"),
            Some(SensorSet::ATTITUDE_DEPTH)
        );
        assert_eq!(SensorSet::parse("attitude+depth+dvl"), Some(SensorSet::ALL));
        assert_eq!(
            SensorSet::parse("dvl").map(|s| s.name()),
            Some("dvl".into())
        );
        for bad in ["", "gps", "depth+depth", "attitude+"] {
            assert_eq!(SensorSet::parse(bad), None, "{bad}");
        }
        assert_eq!(SensorSet::ALL.label(), "attitude + depth + DVL");
    }

    #[test]
    fn apply_keeps_a_scenes_own_noise() {
        let mut s = Scene {
            depth: Some(DepthNoise { sigma_m: 0.05 }),
            ..Scene::default()
        };
        SensorSet::ALL.apply(&mut s);
        assert_eq!(s.depth, Some(DepthNoise { sigma_m: 0.05 }));
        assert_eq!(s.dvl, Some(DvlNoise::default()));
        assert_eq!(SensorSet::of(&s), SensorSet::ALL);
        SensorSet::ATTITUDE.apply(&mut s);
        assert_eq!(SensorSet::of(&s), SensorSet::ATTITUDE);
    }
}
