//! OSM tag rules shared by every consumer of a map: which ways cars drive on.
//!
//! One place for the reading of a tag, so the simulator that writes the truth and the
//! estimators that read the map agree (`highway=*` values as in the OSM wiki's
//! "Key:highway"; `_link` ways take the rule of their main type).

/// Whether cars drive on a `highway=*` value.
pub fn is_drivable(highway: &str) -> bool {
    matches!(
        highway.trim_end_matches("_link"),
        "motorway"
            | "trunk"
            | "primary"
            | "secondary"
            | "tertiary"
            | "unclassified"
            | "residential"
            | "living_street"
            | "service"
            | "road"
            | "busway"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roads_drive_paths_do_not() {
        for h in [
            "residential",
            "primary_link",
            "service",
            "motorway",
            "busway",
        ] {
            assert!(is_drivable(h), "{h}");
        }
        for h in [
            "footway",
            "path",
            "cycleway",
            "steps",
            "pedestrian",
            "track",
            "",
        ] {
            assert!(!is_drivable(h), "{h}");
        }
    }
}
