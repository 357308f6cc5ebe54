//! Which strategy settings the scene's author wrote down. The planner
//! ([`crate::control::derive`]) derives every setting from the model; a value the author wrote
//! wins over the derived one (and is warned about when it cannot work).

use std::collections::BTreeSet;

/// The settings the planner derives, as `section.field` of the scene file: all of
/// `[strategy]`, and the contact angle β and the stage speed V of `[push]`.
pub const DERIVABLE: [&str; 19] = [
    "push.contact_angle_deg",
    "push.speed_um_per_s",
    "strategy.start_height_um",
    "strategy.approach_speed_um_per_s",
    "strategy.travel_speed_um_per_s",
    "strategy.substrate_threshold_mv",
    "strategy.step_um",
    "strategy.dwell_ms",
    "strategy.set_point_v",
    "strategy.approach_distance_um",
    "strategy.search_range_um",
    "strategy.safety_limit_v",
    "strategy.lost_threshold_mv",
    "strategy.max_push_um",
    "strategy.clearance_um",
    "strategy.phase_timeout_s",
    "strategy.control",
    "strategy.z_gain_nm_per_v",
    "strategy.follow_slope",
];

/// The derivable settings a scene gives by hand.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct HandSet(BTreeSet<&'static str>);

impl HandSet {
    /// Every derivable setting (a scene built in code: its values are all meant).
    pub fn all() -> HandSet {
        HandSet(DERIVABLE.into_iter().collect())
    }

    /// None: the planner derives every setting.
    pub fn none() -> HandSet {
        HandSet::default()
    }

    /// The derivable settings present in a scene file's text (already parsed as TOML).
    pub fn from_table(table: &toml::Table) -> HandSet {
        let present = |key: &str| {
            let (section, field) = key.split_once('.').expect("section.field");
            table
                .get(section)
                .and_then(toml::Value::as_table)
                .is_some_and(|t| t.contains_key(field))
        };
        HandSet(DERIVABLE.into_iter().filter(|k| present(k)).collect())
    }

    /// Whether `key` (`section.field`) was given by hand.
    pub fn contains(&self, key: &str) -> bool {
        self.0.contains(key)
    }

    /// Marks `key` as given by hand (a command-line override, an edit in code).
    pub fn insert(&mut self, key: &'static str) {
        self.0.insert(key);
    }

    /// The hand-set keys, sorted.
    pub fn keys(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.0.iter().copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_keys_written_in_the_file_are_hand_set() {
        let t: toml::Table =
            toml::from_str("[push]\nparticle_id = 1\nspeed_um_per_s = 2.0\n[strategy]\nstep_um = 0.1\n")
                .expect("valid TOML");
        let h = HandSet::from_table(&t);
        assert_eq!(
            h.keys().collect::<Vec<_>>(),
            ["push.speed_um_per_s", "strategy.step_um"]
        );
        assert!(!h.contains("push.contact_angle_deg"));
        assert_eq!(HandSet::all().keys().count(), DERIVABLE.len());
    }
}
