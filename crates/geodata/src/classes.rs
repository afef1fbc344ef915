//! urbansem's semantic classes, shared by the real dataset readers, the simulator and `srtree`.
//!
//! The class set is the thesis' (§3.3.1): car, building, street, sidewalk, bicycle, other,
//! tree, pole, grass. Every dataset's own class ids are mapped onto it by its reader in
//! [`crate::datasets`]; points without a label carry [`Class::Unlabelled`].

use serde::{Deserialize, Serialize};

/// A semantic class of a point, a cell or an object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[repr(u8)]
pub enum Class {
    /// No label known.
    Unlabelled = 0,
    /// Cars, trucks, vans (parked or moving).
    Car = 1,
    /// Building facades and roofs.
    Building = 2,
    /// Driving area: road surface and parking lanes.
    Street = 3,
    /// Sidewalks, footpaths, plazas.
    Sidewalk = 4,
    /// Bicycles and motorcycles.
    Bicycle = 5,
    /// Everything else (fences, walls, pedestrians, signs, construction sites…).
    Other = 6,
    /// Trees and other high vegetation.
    Tree = 7,
    /// Poles, lamp posts, traffic lights.
    Pole = 8,
    /// Grass, terrain, low vegetation.
    Grass = 9,
}

impl Class {
    /// All classes in id order, `Unlabelled` first.
    pub const ALL: [Class; 10] = [
        Class::Unlabelled,
        Class::Car,
        Class::Building,
        Class::Street,
        Class::Sidewalk,
        Class::Bicycle,
        Class::Other,
        Class::Tree,
        Class::Pole,
        Class::Grass,
    ];

    /// Number of classes including `Unlabelled`.
    pub const COUNT: usize = 10;

    /// The class with this numeric id (the value stored in a `label` column), if any.
    pub fn from_id(id: u8) -> Option<Class> {
        Class::ALL.get(usize::from(id)).copied()
    }

    /// The numeric id stored in `label` columns.
    pub fn id(self) -> u8 {
        self as u8
    }

    /// Lower-case English name, as used in CLI output and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Class::Unlabelled => "unlabelled",
            Class::Car => "car",
            Class::Building => "building",
            Class::Street => "street",
            Class::Sidewalk => "sidewalk",
            Class::Bicycle => "bicycle",
            Class::Other => "other",
            Class::Tree => "tree",
            Class::Pole => "pole",
            Class::Grass => "grass",
        }
    }

    /// The class with this lower-case name, if any.
    pub fn from_name(name: &str) -> Option<Class> {
        Class::ALL.iter().copied().find(|c| c.name() == name)
    }

    /// A display colour (sRGB) for figures.
    pub fn color_rgb(self) -> [u8; 3] {
        match self {
            Class::Unlabelled => [160, 160, 160],
            Class::Car => [220, 40, 40],
            Class::Building => [200, 140, 60],
            Class::Street => [80, 80, 90],
            Class::Sidewalk => [190, 190, 200],
            Class::Bicycle => [240, 120, 200],
            Class::Other => [120, 60, 160],
            Class::Tree => [30, 130, 40],
            Class::Pole => [250, 220, 40],
            Class::Grass => [130, 200, 90],
        }
    }
}

impl std::fmt::Display for Class {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_names_round_trip() {
        for c in Class::ALL {
            assert_eq!(Class::from_id(c.id()), Some(c));
            assert_eq!(Class::from_name(c.name()), Some(c));
        }
        assert_eq!(Class::from_id(10), None);
        assert_eq!(Class::ALL.len(), Class::COUNT);
    }
}
