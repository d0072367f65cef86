//! The spec's sections: `[dataset]`, `[model]` and `[train]`, `[inversion]`, `[cohort]`,
//! `[realfaces]`, `[headpose]`.

use crate::cohort::{ClipParams, CohortKind, CohortParams, SubjectParams};
use crate::headneck::HeadposeParams;
use crate::io::realdata::RealfacesParams;
use crate::learn::params::{ModelParams, TrainParams};
use crate::spec::raw::Value;
use crate::spec::SpecError;

use super::*;

/// `= v must be >= 0` unless `v` is a finite non-negative number.
pub(super) fn nonneg(v: f64) -> Option<String> {
    (!(v >= 0.0 && v.is_finite())).then(|| format!("= {v} must be >= 0"))
}

/// `[dataset]`.
pub(super) fn read_dataset(r: &mut Reader) -> Result<DatasetParams, SpecError> {
    let d = DatasetParams::default();
    let dataset = DatasetParams {
        pairs_per_expression: r.integer(
            "dataset.pairs_per_expression",
            d.pairs_per_expression as i64,
            2,
            1_000_000,
        )? as usize,
        test_fraction: r.float("dataset.test_fraction", d.test_fraction, &|v| {
            (!(v > 0.0 && v < 1.0)).then(|| format!("= {v} must lie in (0, 1)"))
        })?,
        subdivisions: r.integer("dataset.subdivisions", d.subdivisions as i64, 0, 2)? as u8,
        tolerance: r.float("dataset.tolerance", d.tolerance, &|v| {
            (!(v > 0.0 && v < 1.0)).then(|| format!("= {v} must lie in (0, 1)"))
        })?,
        shear_modulus_fraction: r.float(
            "dataset.shear_modulus_fraction",
            d.shear_modulus_fraction,
            &nonneg,
        )?,
        start: SolveStart::parse(&r.choice("dataset.start", d.start.name(), &SolveStart::NAMES)?)
            .expect("choice checked"),
        family: Family::parse(&r.choice("dataset.family", d.family.name(), &Family::NAMES)?)
            .expect("choice checked"),
        seed: r.integer("dataset.seed", d.seed as i64, 0, i64::MAX)? as u64,
        grid: r.integer("dataset.grid", d.grid as i64, 0, 16)? as usize,
    };
    if (1..3).contains(&dataset.grid) {
        if let Some(node) = r.get("dataset.grid") {
            return Err(r.invalid(
                node,
                "dataset.grid",
                format!(
                    "= {} is too coarse: the grid's cubics need 4 faces per axis (3 or more \
                     intervals), or 0 for none",
                    dataset.grid
                ),
            ));
        }
    }
    r.forget_if_unset("dataset.family");
    r.forget_if_unset("dataset.grid");
    Ok(dataset)
}

/// `[model]` and `[train]`.
pub(super) fn read_training(r: &mut Reader) -> Result<(ModelParams, TrainParams), SpecError> {
    let m = ModelParams::default();
    let model = ModelParams {
        layers: r.integer("model.layers", m.layers as i64, 1, 16)? as usize,
        width: r.integer("model.width", m.width as i64, 1, 4096)? as usize,
    };
    let t = TrainParams::default();
    let train = TrainParams {
        learning_rate: r.float("train.learning_rate", t.learning_rate, &|v| {
            (!(v > 0.0 && v.is_finite())).then(|| format!("= {v} must be positive"))
        })?,
        batch_size: r.integer("train.batch_size", t.batch_size as i64, 1, 1_000_000)? as usize,
        epochs: r.integer("train.epochs", t.epochs as i64, 1, 100_000)? as usize,
        normalization: Normalization::parse(&r.choice(
            "train.normalization",
            t.normalization.name(),
            &Normalization::NAMES,
        )?)
        .expect("choice checked"),
    };
    Ok((model, train))
}

/// `[inversion]` of a spec.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct InversionParams {
    /// Every this many video frames is inverted (images: all). Default 3.
    pub frame_stride: usize,
    /// Choe's penalty weight c for `landmarks_penalty` (eq. 10, linear penalty, in the units
    /// of the squared landmark residual, IOD^2). Default 100.
    pub penalty: f64,
    /// Nonlinear corrections of `aus_refined`. Default 2.
    pub refinements: usize,
    /// Detector noise on every landmark coordinate every method reads (IOD units). Default
    /// 0.003 (0.19 mm on the model's face), which the observer reads as about the 0.1 AU
    /// (RMS) of detector noise Table 2's cohorts carry (0.01 IOD made 0.29-0.33 AU).
    pub landmark_noise_sd: f64,
}

impl Default for InversionParams {
    fn default() -> Self {
        InversionParams {
            frame_stride: 3,
            penalty: 100.0,
            refinements: 2,
            landmark_noise_sd: 0.003,
        }
    }
}

/// `[inversion]`.
pub(super) fn read_inversion(r: &mut Reader) -> Result<InversionParams, SpecError> {
    let iv = InversionParams::default();
    let inversion = InversionParams {
        frame_stride: r.integer("inversion.frame_stride", iv.frame_stride as i64, 1, 100_000)?
            as usize,
        penalty: r.float("inversion.penalty", iv.penalty, &|v| {
            (!(v > 0.0 && v.is_finite())).then(|| format!("= {v} must be positive"))
        })?,
        refinements: r.integer("inversion.refinements", iv.refinements as i64, 0, 20)? as usize,
        landmark_noise_sd: r.float("inversion.landmark_noise_sd", iv.landmark_noise_sd, &nonneg)?,
    };
    Ok(inversion)
}

pub(super) fn read_cohort(r: &mut Reader) -> Result<CohortParams, SpecError> {
    let d = CohortParams::default();
    let nonneg = |v: f64| (!(v >= 0.0 && v.is_finite())).then(|| format!("= {v} must be >= 0"));
    let unit = |v: f64| (!(0.0..=1.0).contains(&v)).then(|| format!("= {v} must lie in [0, 1]"));
    let s = d.subjects;
    let subjects = SubjectParams {
        face_width_sd: r.float("cohort.subjects.face_width_sd", s.face_width_sd, &nonneg)?,
        brow_height_sd: r.float("cohort.subjects.brow_height_sd", s.brow_height_sd, &nonneg)?,
        nose_sd: r.float("cohort.subjects.nose_sd", s.nose_sd, &nonneg)?,
        jaw_length_sd: r.float("cohort.subjects.jaw_length_sd", s.jaw_length_sd, &nonneg)?,
        lip_thickness_sd: r.float(
            "cohort.subjects.lip_thickness_sd",
            s.lip_thickness_sd,
            &nonneg,
        )?,
        strength_median: r.float("cohort.subjects.strength_median", s.strength_median, &|v| {
            (!(v > 0.0 && v.is_finite())).then(|| format!("= {v} must be positive"))
        })?,
        strength_sd: r.float("cohort.subjects.strength_sd", s.strength_sd, &nonneg)?,
        muscle_strength_sd: r.float(
            "cohort.subjects.muscle_strength_sd",
            s.muscle_strength_sd,
            &nonneg,
        )?,
        stiffness_sd: r.float("cohort.subjects.stiffness_sd", s.stiffness_sd, &nonneg)?,
        weight_sd: r.float("cohort.subjects.weight_sd", s.weight_sd, &nonneg)?,
        extra_muscle_probability: r.float(
            "cohort.subjects.extra_muscle_probability",
            s.extra_muscle_probability,
            &unit,
        )?,
        extra_muscle_weight: r.float(
            "cohort.subjects.extra_muscle_weight",
            s.extra_muscle_weight,
            &unit,
        )?,
    };
    let degrees =
        |v: f64| (!(0.0..=20.0).contains(&v)).then(|| format!("= {v} must lie in [0, 20] degrees"));
    let mut clip = |kind: CohortKind| -> Result<ClipParams, SpecError> {
        let c = *d.clip(kind);
        let k = |field: &str| format!("cohort.{}.{field}", kind.name());
        let frames_max = if kind.is_video() { 100_000 } else { 1 };
        let p = ClipParams {
            subjects: r.integer(&k("subjects"), c.subjects as i64, 1, 10_000)? as usize,
            frames: r.integer(&k("frames"), c.frames as i64, 1, frames_max)? as usize,
            peak_min: r.float(&k("peak_min"), c.peak_min, &unit)?,
            peak_max: r.float(&k("peak_max"), c.peak_max, &unit)?,
            head_rotation_sd: r.float(&k("head_rotation_sd"), c.head_rotation_sd, &degrees)?,
            head_motion_deg: r.float(&k("head_motion_deg"), c.head_motion_deg, &degrees)?,
            head_motion_hz: r.float(&k("head_motion_hz"), c.head_motion_hz, &|v| {
                (!(v > 0.0 && v <= 10.0)).then(|| format!("= {v} must lie in (0, 10] Hz"))
            })?,
            fps: r.float(&k("fps"), c.fps, &|v| {
                (!(v > 0.0 && v.is_finite())).then(|| format!("= {v} must be positive"))
            })?,
            syllable_rate: r.float(&k("syllable_rate"), c.syllable_rate, &nonneg)?,
            jaw_amplitude: r.float(&k("jaw_amplitude"), c.jaw_amplitude, &unit)?,
            ramp_frames: r.integer(&k("ramp_frames"), c.ramp_frames as i64, 1, 100_000)? as usize,
        };
        if p.peak_min > p.peak_max {
            let key = k("peak_min");
            let node = r.get(&key).or_else(|| r.get(&k("peak_max")));
            if let Some(node) = node {
                return Err(r.invalid(
                    node,
                    &key,
                    format!("= {} exceeds peak_max = {}", p.peak_min, p.peak_max),
                ));
            }
        }
        Ok(p)
    };
    let images = clip(CohortKind::Images)?;
    let onset_videos = clip(CohortKind::OnsetVideos)?;
    let talking_videos = clip(CohortKind::TalkingVideos)?;
    Ok(CohortParams {
        seed: r.integer("cohort.seed", d.seed as i64, 0, i64::MAX)? as u64,
        noise_sd: r.float("cohort.noise_sd", d.noise_sd, &nonneg)?,
        subjects,
        images,
        onset_videos,
        talking_videos,
    })
}

/// `[realfaces]`: read (and recorded) only when `tables` lists "realfaces", so other specs'
/// values stay as they were.
pub(super) fn read_realfaces(
    r: &mut Reader,
    tables: &[Table],
) -> Result<RealfacesParams, SpecError> {
    let files = r.data_file("realfaces.files", RealfacesParams::DEFAULT_FILES)?;
    let data = match r.get("realfaces.data") {
        None => None,
        Some(node) => match &node.value {
            Value::String(s) => {
                r.values
                    .insert("realfaces.data".into(), toml::Value::String(s.clone()));
                Some(s.clone())
            }
            other => {
                return Err(r.invalid(
                    node,
                    "realfaces.data",
                    format!("must be a string (a folder), not {}", other.type_name()),
                ))
            }
        },
    };
    let frame_stride = r.integer("realfaces.frame_stride", 1, 1, 100_000)? as usize;
    if !tables.contains(&Table::Realfaces) {
        for key in [
            "realfaces.files",
            "realfaces.data",
            "realfaces.frame_stride",
        ] {
            r.forget_if_unset(key);
        }
    }
    let root = data
        .as_ref()
        .map_or_else(|| r.layout.realdata(), std::path::PathBuf::from);
    Ok(RealfacesParams {
        files,
        data,
        root,
        frame_stride,
    })
}

pub(super) fn read_headpose(r: &mut Reader) -> Result<HeadposeParams, SpecError> {
    let d = HeadposeParams::default();
    let positive =
        |v: f64| (!(v > 0.0 && v.is_finite())).then(|| format!("= {v} must be positive"));
    let degrees = |limit: f64| {
        move |v: f64| {
            (!(0.0..=limit).contains(&v)).then(|| format!("= {v} must lie in [0, {limit}]"))
        }
    };
    Ok(HeadposeParams {
        seed: r.integer("headpose.seed", d.seed as i64, 0, i64::MAX)? as u64,
        fit_targets: r.integer("headpose.fit_targets", d.fit_targets as i64, 2, 1_000_000)?
            as usize,
        poses_per_target: r.integer(
            "headpose.poses_per_target",
            d.poses_per_target as i64,
            1,
            10_000,
        )? as usize,
        test_fraction: r.float("headpose.test_fraction", d.test_fraction, &|v| {
            (!(v > 0.0 && v < 1.0)).then(|| format!("= {v} must lie in (0, 1)"))
        })?,
        model: ModelParams {
            layers: r.integer("headpose.layers", d.model.layers as i64, 1, 16)? as usize,
            width: r.integer("headpose.width", d.model.width as i64, 1, 4096)? as usize,
        },
        train: TrainParams {
            learning_rate: r.float("headpose.learning_rate", d.train.learning_rate, &positive)?,
            batch_size: r.integer(
                "headpose.batch_size",
                d.train.batch_size as i64,
                1,
                1_000_000,
            )? as usize,
            epochs: r.integer("headpose.epochs", d.train.epochs as i64, 1, 100_000)? as usize,
            normalization: d.train.normalization,
        },
        // The neck's commanded range is (40, 50, 30): targets beyond it would be clamped.
        range_degrees: [
            r.float("headpose.pitch_degrees", d.range_degrees[0], &degrees(40.0))?,
            r.float("headpose.yaw_degrees", d.range_degrees[1], &degrees(50.0))?,
            r.float("headpose.roll_degrees", d.range_degrees[2], &degrees(30.0))?,
        ],
        duration: r.float("headpose.duration", d.duration, &|v| {
            (!(0.6..=60.0).contains(&v)).then(|| format!("= {v} must lie in [0.6, 60] s"))
        })?,
        settle_degrees: r.float("headpose.settle_degrees", d.settle_degrees, &positive)?,
        sequence_seconds: r.float("headpose.sequence_seconds", d.sequence_seconds, &|v| {
            (!(1.0..=60.0).contains(&v)).then(|| format!("= {v} must lie in [1, 60] s"))
        })?,
        reflex: crate::sim::neck::ReflexParams {
            strain_gain: r.float("headpose.strain_gain", d.reflex.strain_gain, &|v| {
                (!(v >= 0.0 && v.is_finite())).then(|| format!("= {v} must be >= 0"))
            })?,
            rate_gain: r.float("headpose.rate_gain", d.reflex.rate_gain, &|v| {
                (!(v >= 0.0 && v.is_finite())).then(|| format!("= {v} must be >= 0"))
            })?,
        },
    })
}

/// Where a run's units of work run (`[launcher]`, or `facelab run --launcher`): on this
/// machine, or as Slurm jobs. Not a result: never recorded in a run's `spec.toml` (the
/// manifest records it), so the same spec gives the same outputs however it ran.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LauncherParams {
    pub kind: LauncherKind,
    /// `sbatch --partition`.
    pub partition: Option<String>,
    /// `sbatch --time` (Slurm's formats: `MM`, `HH:MM:SS`, `D-HH`...).
    pub time: Option<String>,
    /// `sbatch --cpus-per-task` (default 2).
    pub cpus_per_task: Option<u32>,
    /// `sbatch --mem` (e.g. `4G`).
    pub mem: Option<String>,
    /// `sbatch --account`.
    pub account: Option<String>,
    /// Further `sbatch` options, passed as they are (e.g. `["--qos=short"]`).
    pub sbatch: Vec<String>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LauncherKind {
    #[default]
    Local,
    Slurm,
}

impl LauncherKind {
    pub fn parse(s: &str) -> Option<LauncherKind> {
        match s {
            "local" => Some(LauncherKind::Local),
            "slurm" => Some(LauncherKind::Slurm),
            _ => None,
        }
    }
}

pub(super) fn read_launcher(r: &mut Reader) -> Result<LauncherParams, SpecError> {
    let kind = LauncherKind::parse(&r.choice("launcher.kind", "local", &["local", "slurm"])?)
        .expect("choice checked");
    let text = |r: &mut Reader, key: &str| -> Result<Option<String>, SpecError> {
        match r.get(key) {
            None => Ok(None),
            Some(node) => match &node.value {
                Value::String(s) if !s.is_empty() && !s.contains(char::is_whitespace) => {
                    Ok(Some(s.clone()))
                }
                _ => Err(r.invalid(node, key, "must be a non-empty word".into())),
            },
        }
    };
    let partition = text(r, "launcher.partition")?;
    let time = text(r, "launcher.time")?;
    let mem = text(r, "launcher.mem")?;
    let account = text(r, "launcher.account")?;
    let cpus_per_task = match r.get("launcher.cpus_per_task") {
        None => None,
        Some(_) => Some(r.integer("launcher.cpus_per_task", 2, 1, 4096)? as u32),
    };
    let mut sbatch = Vec::new();
    if r.get("launcher.sbatch").is_some() {
        for node in r.list("launcher.sbatch", Vec::new())? {
            match &node.value {
                Value::String(s) if s.starts_with('-') => sbatch.push(s.clone()),
                _ => {
                    return Err(r.invalid(
                        node,
                        "launcher.sbatch",
                        "must list sbatch options as strings (\"--qos=short\")".into(),
                    ))
                }
            }
        }
    }
    // Where a run runs is not what it computes: kept out of the recorded spec.
    r.values.retain(|k, _| !k.starts_with("launcher."));
    Ok(LauncherParams {
        kind,
        partition,
        time,
        cpus_per_task,
        mem,
        account,
        sbatch,
    })
}
