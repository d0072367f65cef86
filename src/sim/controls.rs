//! The 56 control inputs of the face, in the network's output order: 52 muscle activations
//! (`<pair>_left`, `<pair>_right` for each of the 26 pairs, in table order), then
//! `jaw_rotation`, `jaw_slide`, `jaw_twist` and `auxiliary` (paper 4.1).
//!
//! All inputs lie in [0, 1]. Slide and twist are neutral at 0.5; the auxiliary output is
//! carried through unused by the face, as in the paper.

use std::sync::OnceLock;

use super::muscles::{Side, MUSCLE_PAIRS};

pub const MUSCLE_COUNT: usize = 2 * MUSCLE_PAIRS.len();
pub const JAW_ROTATION: usize = MUSCLE_COUNT;
pub const JAW_SLIDE: usize = MUSCLE_COUNT + 1;
pub const JAW_TWIST: usize = MUSCLE_COUNT + 2;
pub const AUXILIARY: usize = MUSCLE_COUNT + 3;
pub const CONTROL_COUNT: usize = MUSCLE_COUNT + 4;

/// Index of muscle `pair` on `side`.
pub const fn muscle_index(pair: usize, side: Side) -> usize {
    2 * pair
        + match side {
            Side::Left => 0,
            Side::Right => 1,
        }
}

/// Control names in output order.
pub fn control_names() -> &'static [String] {
    static NAMES: OnceLock<Vec<String>> = OnceLock::new();
    NAMES.get_or_init(|| {
        let mut names = Vec::with_capacity(CONTROL_COUNT);
        for pair in &MUSCLE_PAIRS {
            for side in [Side::Left, Side::Right] {
                names.push(format!("{}_{}", pair.name, side.suffix()));
            }
        }
        for name in ["jaw_rotation", "jaw_slide", "jaw_twist", "auxiliary"] {
            names.push(name.to_string());
        }
        names
    })
}

/// Index of a control by name.
pub fn control_index(name: &str) -> Option<usize> {
    control_names().iter().position(|n| n == name)
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ControlError {
    #[error("unknown control `{name}`{}", suggestion(name))]
    Unknown { name: String },
    #[error("control `{name}` = {value} is outside [0, 1]")]
    OutOfRange { name: String, value: f64 },
}

fn suggestion(name: &str) -> String {
    let best = control_names()
        .iter()
        .min_by_key(|candidate| edit_distance(name, candidate));
    match best {
        Some(b) if edit_distance(name, b) <= name.len() / 2 + 2 => {
            format!(" (did you mean `{b}`?)")
        }
        _ => String::new(),
    }
}

/// Levenshtein distance, for "did you mean" hints.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// A full set of control inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct Activations {
    values: [f64; CONTROL_COUNT],
}

impl Default for Activations {
    fn default() -> Self {
        Self::neutral()
    }
}

impl Activations {
    /// Everything relaxed: muscles and jaw rotation 0, slide and twist 0.5.
    pub fn neutral() -> Activations {
        let mut values = [0.0; CONTROL_COUNT];
        values[JAW_SLIDE] = 0.5;
        values[JAW_TWIST] = 0.5;
        Activations { values }
    }

    /// From values in output order; each must lie in [0, 1].
    pub fn from_values(values: &[f64; CONTROL_COUNT]) -> Result<Activations, ControlError> {
        let mut a = Activations::neutral();
        for (i, &v) in values.iter().enumerate() {
            a.set_index(i, v)?;
        }
        Ok(a)
    }

    pub fn values(&self) -> &[f64; CONTROL_COUNT] {
        &self.values
    }

    pub fn get(&self, index: usize) -> f64 {
        self.values[index]
    }

    pub fn muscle(&self, pair: usize, side: Side) -> f64 {
        self.values[muscle_index(pair, side)]
    }

    /// Sets a control by index, rejecting values outside [0, 1] (and NaN).
    pub fn set_index(&mut self, index: usize, value: f64) -> Result<(), ControlError> {
        if !(0.0..=1.0).contains(&value) {
            return Err(ControlError::OutOfRange {
                name: control_names()[index].clone(),
                value,
            });
        }
        self.values[index] = value;
        Ok(())
    }

    /// Sets a control by name.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), ControlError> {
        let index = control_index(name).ok_or_else(|| ControlError::Unknown {
            name: name.to_string(),
        })?;
        self.set_index(index, value)
    }

    /// The mirror image: left and right muscles swapped, jaw twist reversed.
    pub fn mirrored(&self) -> Activations {
        let mut out = self.clone();
        for pair in 0..MUSCLE_PAIRS.len() {
            out.values[muscle_index(pair, Side::Left)] = self.muscle(pair, Side::Right);
            out.values[muscle_index(pair, Side::Right)] = self.muscle(pair, Side::Left);
        }
        out.values[JAW_TWIST] = 1.0 - self.values[JAW_TWIST];
        out
    }

    /// `neutral + t (self - neutral)`: the continuation path from rest.
    pub fn scaled_from_neutral(&self, t: f64) -> Activations {
        let neutral = Activations::neutral();
        let mut out = neutral.clone();
        for i in 0..CONTROL_COUNT {
            out.values[i] = neutral.values[i] + t * (self.values[i] - neutral.values[i]);
        }
        out
    }

    /// True when every input is at its neutral value.
    pub fn is_neutral(&self) -> bool {
        let neutral = Activations::neutral();
        self.values[..AUXILIARY] == neutral.values[..AUXILIARY]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifty_six_controls_in_network_order() {
        let names = control_names();
        assert_eq!(names.len(), 56);
        assert_eq!(names[0], "frontalis_medial_left");
        assert_eq!(names[1], "frontalis_medial_right");
        assert_eq!(names[52], "jaw_rotation");
        assert_eq!(names[55], "auxiliary");
    }

    #[test]
    fn unknown_name_suggests_the_nearest() {
        let err = Activations::neutral()
            .set("zygomatic_major_left", 0.5)
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "unknown control `zygomatic_major_left` (did you mean `zygomaticus_major_left`?)"
        );
    }

    #[test]
    fn out_of_range_and_nan_are_rejected() {
        let mut a = Activations::neutral();
        assert!(a.set("jaw_rotation", 1.5).is_err());
        assert!(a.set("jaw_rotation", f64::NAN).is_err());
        assert!(a.set("jaw_rotation", 1.0).is_ok());
    }
}
