//! Geometry priors conditioned on a segment's OSM tags (issue 17 item 3).
//!
//! How wide a street is depends first on what the map says about it: its `width=*` when
//! mapped, else its `lanes=*`, else its `highway` class (a service road is 3–5 m, a primary
//! road 11–16 m). Thesis §4.4.2 uses one Gaussian on (offset, log width) for every segment;
//! a segment whose corridor says little about its width (few usable bins, occluded kerbs)
//! is then pulled to the city-wide mean. [`TagPrior`] learns from training segments one
//! Gaussian on log width per tag group instead:
//!
//! - a segment with a `width` tag: log width = ln(tag) + a learnt bias (group `width`);
//! - else with `lanes`: ln(lanes) + a learnt log lane width (group `lanes`);
//! - else by class: the `highway` value without `_link` (group `highway=CLASS`);
//! - for the with-sidewalk target, `sidewalk=no|none|separate` is a group of its own
//!   (suffix `;sidewalk=no`), since such a road has nothing beside it.
//!
//! Each group's mean and spread are shrunk toward its parent by [`PSEUDO_SEGMENTS`]
//! pseudo-observations (class groups toward the global fit, `width`/`lanes` groups toward
//! the pooled residuals of their kind), so a group of one or two segments stays near the
//! pooled estimate and a large group speaks for itself. A segment whose group was never seen
//! in training falls back to its class group, then to the global prior. Offsets keep the
//! global prior (the map's tags say nothing about which way a centre line is drawn off).
//! The pseudo-count was set once, before the first run, and not tuned.

use std::collections::BTreeMap;

use geodata::osm::OsmMap;
use serde::{Deserialize, Serialize};

use crate::potentials::{prior_table, GeometryPrior, ThetaGrid};

/// Pseudo-segments of the parent in each group's mean and variance.
pub const PSEUDO_SEGMENTS: f64 = 3.0;

/// Smallest spread of log width a group may have (as [`GeometryPrior::fit`]'s floor).
pub const MIN_SIGMA_LOG_WIDTH: f64 = 0.05;

/// What the map says about a segment's cross-section.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentTags {
    /// `highway` class without `_link`.
    pub class: String,
    /// `width=*`, metres, when mapped (and plausible: 0.5–60 m).
    pub width_m: Option<f64>,
    /// `lanes=*`, when mapped (1–12).
    pub lanes: Option<u32>,
    /// `sidewalk=no|none|separate`.
    pub no_sidewalk: bool,
    /// Distance of the footways mapped as the road's sidewalks from its centre line, metres
    /// ([`geodata::osm::sidewalks`]), when it has them.
    pub mapped_sidewalk_m: Option<f64>,
}

impl SegmentTags {
    /// The tags of segment `s` of `map`'s street network (its way's tags).
    pub fn of(map: &OsmMap, s: usize) -> SegmentTags {
        let seg = &map.streets.segments[s];
        let way = map.highways.get(seg.way_index);
        SegmentTags {
            class: seg.highway.trim_end_matches("_link").to_string(),
            width_m: way
                .and_then(|w| w.width_m)
                .filter(|w| w.is_finite() && (0.5..=60.0).contains(w)),
            lanes: way.and_then(|w| w.lanes).filter(|l| (1..=12).contains(l)),
            no_sidewalk: way
                .is_some_and(|w| matches!(w.sidewalk.as_deref(), Some("no" | "none" | "separate"))),
            mapped_sidewalk_m: way.and_then(|w| w.mapped_sidewalk_m),
        }
    }

    /// The tags, and whether sidewalks are mapped but not where (what neighbours must share
    /// to be coupled).
    pub fn without_geometry(self) -> SegmentTags {
        SegmentTags {
            mapped_sidewalk_m: self.mapped_sidewalk_m.map(|_| 0.0),
            ..self
        }
    }

    /// The group of the most specific tag (`width`, `lanes` or none) and its basis
    /// (ln of the tag value), and the class group.
    fn groups(&self, sidewalk_groups: bool) -> (Option<(String, f64)>, String) {
        let suffix = if sidewalk_groups && self.no_sidewalk {
            ";sidewalk=no"
        } else {
            ""
        };
        let specific = match (self.width_m, self.lanes) {
            (Some(w), _) => Some((format!("width{suffix}"), w.ln())),
            (None, Some(l)) => Some((format!("lanes{suffix}"), f64::from(l).ln())),
            _ => None,
        };
        (specific, format!("highway={}{suffix}", self.class))
    }
}

/// One group's Gaussian on log width (minus the group's basis).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WidthGroup {
    /// Mean of log width minus the basis (ln of the tag value; 0 for class groups).
    pub mean: f64,
    /// Standard deviation of the same.
    pub sigma: f64,
    /// Training segments in the group.
    pub segments: usize,
}

/// A geometry prior per OSM tag group, learnt from training segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TagPrior {
    /// Whether `sidewalk=no|none|separate` makes groups of their own (for the with-sidewalk
    /// target: such a road has nothing beside it).
    pub sidewalk_groups: bool,
    /// The global prior: offsets, and log width where no group applies.
    pub global: GeometryPrior,
    /// Groups by key (`width`, `lanes`, `highway=CLASS`, each maybe with `;sidewalk=no`).
    pub groups: BTreeMap<String, WidthGroup>,
}

/// Mean and spread of `xs` shrunk toward (`mean0`, `sigma0`) by [`PSEUDO_SEGMENTS`].
fn shrunk(xs: &[f64], mean0: f64, sigma0: f64) -> WidthGroup {
    let (mean, sigma) = pooled(xs, PSEUDO_SEGMENTS, mean0, sigma0);
    WidthGroup {
        mean,
        sigma: sigma.max(MIN_SIGMA_LOG_WIDTH),
        segments: xs.len(),
    }
}

/// Mean and standard deviation of `xs` together with `k` pseudo-observations of mean
/// `mean0` and spread `sigma0` (`k` = 0: of `xs` alone).
fn pooled(xs: &[f64], k: f64, mean0: f64, sigma0: f64) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = (xs.iter().sum::<f64>() + k * mean0) / (n + k);
    let var = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() + k * sigma0 * sigma0) / (n + k);
    (mean, var.sqrt())
}

impl TagPrior {
    /// Fits the groups on training segments: their tags and true (offset, width);
    /// `sidewalk_groups` as [`TagPrior::sidewalk_groups`].
    pub fn fit(samples: &[(SegmentTags, (f64, f64))], sidewalk_groups: bool) -> TagPrior {
        let geometries: Vec<(f64, f64)> = samples.iter().map(|s| s.1).collect();
        let global = GeometryPrior::fit(&geometries);
        let mut class: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        let mut specific: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        // Residuals of each specific kind over every suffix, for the kind's parent.
        let mut kinds: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
        for (tags, (_, w)) in samples {
            let lw = w.max(0.1).ln();
            let (spec, cls) = tags.groups(sidewalk_groups);
            class.entry(cls).or_default().push(lw);
            if let Some((key, basis)) = spec {
                let kind = if key.starts_with("width") {
                    "width"
                } else {
                    "lanes"
                };
                kinds.entry(kind).or_default().push(lw - basis);
                specific.entry(key).or_default().push(lw - basis);
            }
        }
        let mut groups = BTreeMap::new();
        for (key, xs) in class {
            groups.insert(
                key,
                shrunk(&xs, global.mean_log_width, global.sigma_log_width),
            );
        }
        let parents: BTreeMap<&str, WidthGroup> = kinds
            .iter()
            .map(|(kind, xs)| {
                let n = xs.len() as f64;
                let mean = xs.iter().sum::<f64>() / n;
                (*kind, shrunk(xs, mean, global.sigma_log_width))
            })
            .collect();
        for (key, xs) in specific {
            let kind = if key.starts_with("width") {
                "width"
            } else {
                "lanes"
            };
            let p = parents[kind];
            groups.insert(key, shrunk(&xs, p.mean, p.sigma));
        }
        TagPrior {
            sidewalk_groups,
            global,
            groups,
        }
    }

    /// The prior of a segment with these tags.
    pub fn for_tags(&self, tags: &SegmentTags) -> GeometryPrior {
        let (spec, cls) = tags.groups(self.sidewalk_groups);
        let (basis, group) = match spec.and_then(|(k, b)| self.groups.get(&k).map(|g| (b, g))) {
            Some(found) => found,
            None => match self.groups.get(&cls) {
                Some(g) => (0.0, g),
                None => return self.global,
            },
        };
        GeometryPrior {
            mean_log_width: basis + group.mean,
            sigma_log_width: group.sigma,
            ..self.global
        }
    }

    /// The first value out of range, named by its field.
    pub fn check(&self) -> Result<(), String> {
        for (key, g) in &self.groups {
            if !g.mean.is_finite() {
                return Err(format!(
                    "tag_prior.groups[{key}].mean = {} is not finite",
                    g.mean
                ));
            }
            if !(g.sigma.is_finite() && g.sigma > 0.0) {
                return Err(format!(
                    "tag_prior.groups[{key}].sigma = {} is out of range (expected a finite number > 0)",
                    g.sigma
                ));
            }
        }
        Ok(())
    }
}

/// Smallest spread of a sidewalk margin or of an offset difference, metres.
pub const MIN_SIGMA_MARGIN_M: f64 = 0.1;

/// One group's Gaussian on the sidewalk margin and on the centre shift, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MarginGroup {
    /// Mean margin: (width with sidewalk − driving-area width) / 2.
    pub mean_m: f64,
    /// Standard deviation of the margin.
    pub sigma_m: f64,
    /// Mean shift of the centre: offset with sidewalk − driving-area offset.
    pub mean_shift_m: f64,
    /// Standard deviation of the shift.
    pub sigma_shift_m: f64,
    /// Training segments in the group.
    pub segments: usize,
}

/// A training segment for [`SidewalkPrior::fit`]: its tags, true driving area and true
/// geometry with sidewalk, each (offset, width) in metres.
pub type MarginSample = (SegmentTags, (f64, f64), (f64, f64));

/// The with-sidewalk prior given a segment's driving area: the sidewalk margin per
/// `highway` class (and `sidewalk=no`), learnt from training segments with both truths.
///
/// A road whose sidewalks the map draws as footways of their own
/// ([`SegmentTags::mapped_sidewalk_m`]) says where its sidewalk is: its prior is centred on
/// those footways' distance plus a learnt margin ([`SidewalkPrior::mapped`], the outer edge
/// beyond the footways' centre lines), whatever its driving area.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SidewalkPrior {
    /// The margin over every training segment without mapped sidewalks (over all when every
    /// one has them).
    pub global: MarginGroup,
    /// Groups by key (`highway=CLASS`, maybe with `;sidewalk=no`), over training segments
    /// without mapped sidewalks.
    pub groups: BTreeMap<String, MarginGroup>,
    /// Over training segments with mapped sidewalks: half the width with sidewalk minus the
    /// footways' distance (`mean_m`, `sigma_m`), and the centre shift as in the groups.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mapped: Option<MarginGroup>,
}

/// Mean and spread of `xs` shrunk toward (`mean0`, `sigma0`) by [`PSEUDO_SEGMENTS`], with a
/// floor of [`MIN_SIGMA_MARGIN_M`].
fn shrunk_m(xs: &[f64], mean0: f64, sigma0: f64) -> (f64, f64) {
    let (mean, sigma) = pooled(xs, PSEUDO_SEGMENTS, mean0, sigma0);
    (mean, sigma.max(MIN_SIGMA_MARGIN_M))
}

impl SidewalkPrior {
    /// Fits the margins on training segments: tags, true driving area and true geometry
    /// with sidewalk (offset, width). `None` without samples.
    pub fn fit(samples: &[MarginSample]) -> Option<SidewalkPrior> {
        if samples.is_empty() {
            return None;
        }
        let margin = |s: &MarginSample| 0.5 * (s.2 .1 - s.1 .1);
        let shift = |s: &MarginSample| s.2 .0 - s.1 .0;
        // The global margin over the roads without mapped sidewalks (their margin is another
        // quantity), or over every road when all have them.
        let plain: Vec<&MarginSample> = samples
            .iter()
            .filter(|s| s.0.mapped_sidewalk_m.is_none())
            .collect();
        let plain = if plain.is_empty() {
            samples.iter().collect()
        } else {
            plain
        };
        let all_m: Vec<f64> = plain.iter().map(|s| margin(s)).collect();
        let all_d: Vec<f64> = plain.iter().map(|s| shift(s)).collect();
        let (gm, gsm) = pooled(&all_m, 0.0, 0.0, 0.0);
        let gsm = gsm.max(MIN_SIGMA_MARGIN_M);
        let (gd, gsd) = pooled(&all_d, 0.0, 0.0, 0.0);
        let gsd = gsd.max(MIN_SIGMA_MARGIN_M);
        let global = MarginGroup {
            mean_m: gm,
            sigma_m: gsm,
            mean_shift_m: gd,
            sigma_shift_m: gsd,
            segments: plain.len(),
        };
        let mut by: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
        let (mut mapped_m, mut mapped_d) = (Vec::new(), Vec::new());
        for s in samples {
            if let Some(d) = s.0.mapped_sidewalk_m {
                mapped_m.push(0.5 * s.2 .1 - d);
                mapped_d.push(shift(s));
                continue;
            }
            let e = by.entry(s.0.groups(true).1).or_default();
            e.0.push(margin(s));
            e.1.push(shift(s));
        }
        let mapped = (!mapped_m.is_empty()).then(|| {
            let mean = mapped_m.iter().sum::<f64>() / mapped_m.len() as f64;
            let (mean_m, sigma_m) = shrunk_m(&mapped_m, mean, gsm);
            let (mean_shift_m, sigma_shift_m) = shrunk_m(&mapped_d, gd, gsd);
            MarginGroup {
                mean_m,
                sigma_m,
                mean_shift_m,
                sigma_shift_m,
                segments: mapped_m.len(),
            }
        });
        let groups = by
            .into_iter()
            .map(|(key, (ms, ds))| {
                let (mean_m, sigma_m) = shrunk_m(&ms, gm, gsm);
                let (mean_shift_m, sigma_shift_m) = shrunk_m(&ds, gd, gsd);
                (
                    key,
                    MarginGroup {
                        mean_m,
                        sigma_m,
                        mean_shift_m,
                        sigma_shift_m,
                        segments: ms.len(),
                    },
                )
            })
            .collect();
        Some(SidewalkPrior {
            global,
            groups,
            mapped,
        })
    }

    /// The with-sidewalk prior of a segment with these tags whose driving area was estimated
    /// as `driving` (offset, width) with width spread `spread_m`; offsets spread as the
    /// learnt shift plus half the width spread (one kerb moves the centre by half as much).
    pub fn given_driving_area(
        &self,
        tags: &SegmentTags,
        driving: (f64, f64),
        spread_m: f64,
    ) -> GeometryPrior {
        if let (Some(d), Some(g)) = (tags.mapped_sidewalk_m, &self.mapped) {
            let width = (2.0 * (d + g.mean_m)).max(driving.1).max(0.5);
            let sigma_d = (g.sigma_shift_m.powi(2) + 0.25 * spread_m * spread_m).sqrt();
            return GeometryPrior {
                mean_offset_m: driving.0 + g.mean_shift_m,
                sigma_offset_m: sigma_d.max(0.2),
                mean_log_width: width.ln(),
                sigma_log_width: (2.0 * g.sigma_m / width).max(MIN_SIGMA_LOG_WIDTH),
            };
        }
        let g = self
            .groups
            .get(&tags.groups(true).1)
            .unwrap_or(&self.global);
        let width = (driving.1 + 2.0 * g.mean_m).max(0.5);
        let sigma_w = (4.0 * g.sigma_m * g.sigma_m + spread_m * spread_m).sqrt();
        let sigma_d = (g.sigma_shift_m.powi(2) + 0.25 * spread_m * spread_m).sqrt();
        GeometryPrior {
            mean_offset_m: driving.0 + g.mean_shift_m,
            sigma_offset_m: sigma_d.max(0.2),
            mean_log_width: width.ln(),
            sigma_log_width: (sigma_w / width).max(MIN_SIGMA_LOG_WIDTH),
        }
    }

    /// The first value out of range, named by its field.
    pub fn check(&self) -> Result<(), String> {
        for (key, g) in std::iter::once(("global".to_string(), &self.global))
            .chain(self.groups.iter().map(|(k, g)| (format!("groups[{k}]"), g)))
            .chain(self.mapped.iter().map(|g| ("mapped".to_string(), g)))
        {
            for (name, v, positive) in [
                ("mean_m", g.mean_m, false),
                ("sigma_m", g.sigma_m, true),
                ("mean_shift_m", g.mean_shift_m, false),
                ("sigma_shift_m", g.sigma_shift_m, true),
            ] {
                if !v.is_finite() || (positive && v <= 0.0) {
                    return Err(format!(
                        "sidewalk_prior.{key}.{name} = {v} is out of range (expected a finite number{})",
                        if positive { " > 0" } else { "" }
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The prior tables of a set of segments, one table per distinct prior.
#[derive(Debug, Clone)]
pub struct PriorTables {
    tables: Vec<Vec<f64>>,
    index: Vec<usize>,
}

impl PriorTables {
    /// One table per distinct prior among `priors` (one prior per segment, in order).
    pub fn new(priors: &[GeometryPrior], grid: &ThetaGrid) -> PriorTables {
        let mut seen: Vec<GeometryPrior> = Vec::new();
        let mut tables = Vec::new();
        let index = priors
            .iter()
            .map(|p| match seen.iter().position(|q| q == p) {
                Some(i) => i,
                None => {
                    seen.push(*p);
                    tables.push(prior_table(p, grid));
                    seen.len() - 1
                }
            })
            .collect();
        PriorTables { tables, index }
    }

    /// The table of segment `k` (its position in the list given to [`PriorTables::new`]).
    pub fn table(&self, k: usize) -> &[f64] {
        &self.tables[self.index[k]]
    }

    /// Distinct tables.
    pub fn distinct(&self) -> usize {
        self.tables.len()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn tags(class: &str, width: Option<f64>, lanes: Option<u32>, no_sw: bool) -> SegmentTags {
        SegmentTags {
            class: class.into(),
            width_m: width,
            lanes,
            no_sidewalk: no_sw,
            mapped_sidewalk_m: None,
        }
    }

    #[test]
    fn classes_learn_their_own_widths_and_unseen_ones_fall_back() {
        let mut samples = Vec::new();
        for i in 0..30 {
            let j = f64::from(i % 5) * 0.1;
            samples.push((tags("service", None, None, false), (0.0, 3.5 + j)));
            samples.push((tags("primary", None, None, false), (0.2, 13.0 + j)));
        }
        let p = TagPrior::fit(&samples, false);
        let service = p.for_tags(&tags("service", None, None, false));
        let primary = p.for_tags(&tags("primary", None, None, true));
        assert!(
            (service.mean_log_width.exp() - 3.7).abs() < 0.3,
            "{service:?}"
        );
        assert!(
            (primary.mean_log_width.exp() - 13.2).abs() < 0.8,
            "{primary:?}"
        );
        assert!(service.sigma_log_width < p.global.sigma_log_width);
        // Offsets are global.
        assert_eq!(service.mean_offset_m, p.global.mean_offset_m);
        assert_eq!(p.for_tags(&tags("tertiary", None, None, false)), p.global);
        // A tag never seen in training falls back to the class.
        assert_eq!(
            p.for_tags(&tags("service", Some(9.0), None, false)),
            service
        );
    }

    #[test]
    fn width_tags_and_lanes_scale_their_groups() {
        let mut samples = Vec::new();
        for w in [6.0, 8.0, 10.0, 12.0, 14.0, 16.0] {
            samples.push((tags("residential", Some(w), None, false), (0.0, w)));
        }
        for l in [1u32, 2, 3, 4] {
            samples.push((
                tags("secondary", None, Some(l), false),
                (0.0, 3.2 * f64::from(l)),
            ));
        }
        let p = TagPrior::fit(&samples, false);
        let w = p.for_tags(&tags("residential", Some(11.0), None, false));
        assert!((w.mean_log_width.exp() - 11.0).abs() < 1e-9, "{w:?}");
        assert!(w.sigma_log_width < 0.5 * p.global.sigma_log_width, "{w:?}");
        let l = p.for_tags(&tags("secondary", None, Some(5), false));
        assert!((l.mean_log_width.exp() - 16.0).abs() < 1e-6, "{l:?}");
    }

    #[test]
    fn a_small_group_is_shrunk_toward_its_parent() {
        let mut samples: Vec<_> = (0..40)
            .map(|i| {
                (
                    tags("residential", None, None, false),
                    (0.0, 7.0 + f64::from(i % 3)),
                )
            })
            .collect();
        samples.push((tags("busway", None, None, false), (0.0, 30.0)));
        let p = TagPrior::fit(&samples, false);
        let b = p.for_tags(&tags("busway", None, None, false));
        let g = p.global.mean_log_width;
        // One segment moves the mean a quarter of the way (1 / (1 + 3)).
        assert!((b.mean_log_width - (g + 0.25 * (30f64.ln() - g))).abs() < 1e-9);
    }

    #[test]
    fn sidewalk_no_is_its_own_group_only_with_sidewalk() {
        let mut samples = Vec::new();
        for i in 0..20 {
            let j = f64::from(i % 4) * 0.2;
            samples.push((tags("residential", None, None, false), (0.0, 12.0 + j)));
            samples.push((tags("residential", None, None, true), (0.0, 7.0 + j)));
        }
        let ws = TagPrior::fit(&samples, true);
        let with = ws.for_tags(&tags("residential", None, None, false));
        let without = ws.for_tags(&tags("residential", None, None, true));
        assert!(with.mean_log_width.exp() > 11.0 && without.mean_log_width.exp() < 8.0);
        let da = TagPrior::fit(&samples, false);
        assert_eq!(
            da.for_tags(&tags("residential", None, None, false)),
            da.for_tags(&tags("residential", None, None, true))
        );
    }

    #[test]
    fn sidewalk_margins_are_learnt_per_class_and_centred_on_the_driving_area() {
        let mut samples = Vec::new();
        for i in 0..20 {
            let j = f64::from(i % 5) * 0.1;
            let da = 5.0 + f64::from(i % 7);
            // Primary roads: 3 m sidewalks, shifted 0.2 m to the left; service: none.
            samples.push((
                tags("primary", None, Some(2), false),
                (0.1, da),
                (0.3, da + 2.0 * (3.0 + j)),
            ));
            samples.push((
                tags("service", None, None, false),
                (0.0, 3.5),
                (0.0, 3.5 + 2.0 * j),
            ));
        }
        assert_eq!(SidewalkPrior::fit(&[]), None);
        let p = SidewalkPrior::fit(&samples).unwrap();
        p.check().unwrap();
        let primary = &p.groups["highway=primary"];
        assert!((primary.mean_m - 3.2).abs() < 0.2, "{primary:?}");
        assert!((primary.mean_shift_m - 0.2).abs() < 0.05, "{primary:?}");
        assert!(p.groups["highway=service"].mean_m < 0.5);
        // Centred on the driving area plus both margins, whatever the lanes say.
        let g = p.given_driving_area(&tags("primary", None, Some(4), false), (1.0, 14.0), 0.0);
        assert!((g.mean_log_width.exp() - (14.0 + 2.0 * primary.mean_m)).abs() < 1e-9);
        assert!((g.mean_offset_m - (1.0 + primary.mean_shift_m)).abs() < 1e-9);
        // An uncertain driving area widens the prior; an unseen class takes the global margin.
        let loose = p.given_driving_area(&tags("primary", None, None, false), (1.0, 14.0), 2.0);
        assert!(loose.sigma_log_width > g.sigma_log_width);
        assert!(loose.sigma_offset_m > g.sigma_offset_m);
        let other = p.given_driving_area(&tags("tertiary", None, None, false), (0.0, 8.0), 0.0);
        assert!((other.mean_log_width.exp() - (8.0 + 2.0 * p.global.mean_m)).abs() < 1e-9);
        let mut bad = p.clone();
        bad.groups.get_mut("highway=service").unwrap().sigma_m = 0.0;
        assert!(bad
            .check()
            .unwrap_err()
            .contains("sidewalk_prior.groups[highway=service].sigma_m"));
        assert_eq!(p.mapped, None);
    }

    #[test]
    fn mapped_sidewalks_centre_the_prior_on_the_footways() {
        let mapped = |d: f64| SegmentTags {
            mapped_sidewalk_m: Some(d),
            ..tags("residential", None, None, false)
        };
        let mut samples = Vec::new();
        for i in 0..20 {
            let (da, j) = (6.0 + f64::from(i % 3), f64::from(i % 5) * 0.1);
            // Plain residential roads: 2 m sidewalks; mapped ones reach 1.2 m beyond the
            // footways' centre lines, whatever their driving area.
            samples.push((
                tags("residential", None, None, false),
                (0.0, da),
                (0.0, da + 4.0),
            ));
            let d = 5.0 + f64::from(i % 4);
            samples.push((mapped(d), (0.0, da), (0.0, 2.0 * (d + 1.1 + j))));
        }
        let p = SidewalkPrior::fit(&samples).unwrap();
        p.check().unwrap();
        let m = p.mapped.unwrap();
        assert_eq!((m.segments, p.global.segments), (20, 20));
        assert!((m.mean_m - 1.3).abs() < 0.05, "{m:?}");
        // The class group learnt from the plain roads alone.
        assert!((p.groups["highway=residential"].mean_m - 2.0).abs() < 1e-9);
        let g = p.given_driving_area(&mapped(7.0), (0.5, 7.0), 1.0);
        assert!((g.mean_log_width.exp() - 2.0 * (7.0 + m.mean_m)).abs() < 1e-9);
        assert!((g.mean_offset_m - 0.5).abs() < 0.1);
        let plain = p.given_driving_area(&tags("residential", None, None, false), (0.5, 7.0), 1.0);
        assert!((plain.mean_log_width.exp() - 11.0).abs() < 1e-9);
        // A model without the group (trained before it existed) reads and falls back.
        let old: SidewalkPrior = serde_json::from_str(
            &serde_json::to_string(&SidewalkPrior {
                mapped: None,
                ..p.clone()
            })
            .unwrap(),
        )
        .unwrap();
        let fallback = old.given_driving_area(&mapped(7.0), (0.5, 7.0), 1.0);
        assert!((fallback.mean_log_width.exp() - 11.0).abs() < 1e-9);
    }

    #[test]
    fn prior_tables_are_shared_between_equal_priors() {
        let grid = crate::model::GeometryOptions::default().theta_grid();
        let a = GeometryPrior::fit(&[(0.0, 7.0), (0.5, 9.0)]);
        let b = GeometryPrior::fit(&[(0.0, 3.0), (0.5, 4.0)]);
        let t = PriorTables::new(&[a, b, a, a, b], &grid);
        assert_eq!(t.distinct(), 2);
        assert_eq!(t.table(2), prior_table(&a, &grid).as_slice());
        assert_eq!(t.table(4), prior_table(&b, &grid).as_slice());
    }
}
