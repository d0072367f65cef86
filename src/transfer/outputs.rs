//! What a transfer writes into its output folder: the transferred face's AUs
//! (`transferred.csv`, OpenFace's layout, with the neck's head rotation where the neck
//! moved), the activations (`activations.csv`), the AU MSE against the input (`mse.csv`,
//! leaving out frames whose face did not solve), the neck's tracking (`head_pose.csv`), the
//! GIF and the stills, and the judge's verdict (`fidelity.csv`, `fidelity.md`).

use std::path::PathBuf;

use anyhow::Result;
use image::RgbImage;

use super::fidelity::{Fidelity, JudgeFrames};
use super::neck::HeadTrack;
use super::network::au_mse;
use super::TransferOptions;
use crate::io::atomic::write_atomic;
use crate::io::openface::{write_openface, FaceRow, OpenFaceFile};
use crate::io::rows::{self, num, CsvRow};
use crate::landmark::Blendshapes;
use crate::observe::{AU_COUNT, AU_NAMES};
use crate::report::compose::gif_bytes;
use crate::report::save_png;
use crate::sim::controls::control_names;
use crate::sim::Activations;

/// What a transfer made, frame by frame, to be written.
pub(super) struct Made<'a> {
    pub file: &'a OpenFaceFile,
    pub opts: &'a TransferOptions,
    /// The input's AUs per frame.
    pub reference: &'a [[f64; AU_COUNT]],
    pub acts: &'a [Activations],
    /// The transferred face's AUs per frame (zeros where it did not solve).
    pub transferred: &'a [[f64; AU_COUNT]],
    pub solved: &'a [bool],
    pub head: Option<&'a HeadTrack>,
    /// Seconds between frames.
    pub dt: f64,
    /// Every how many frames the GIF takes one.
    pub gif_every: usize,
    pub frames: &'a [RgbImage],
    pub stills: &'a [(i64, RgbImage)],
    pub judged: Option<JudgeFrames>,
}

/// What the written files say.
pub(super) struct Written {
    pub written: Vec<PathBuf>,
    pub mse: [f64; AU_COUNT],
    pub pose_error: Option<(f64, f64)>,
    pub fidelity: Option<Fidelity>,
}

/// Writes a transfer's files (each atomically) into `opts.out`.
pub(super) fn write(made: Made<'_>) -> Result<Written> {
    let Made {
        file,
        opts,
        reference,
        acts,
        transferred,
        solved,
        head,
        dt,
        gif_every,
        frames,
        stills,
        judged,
    } = made;
    let n = file.rows.len();
    let out = &opts.out;
    let mut written = Vec::new();
    let rows: Vec<FaceRow> = file
        .rows
        .iter()
        .zip(transferred)
        .enumerate()
        .map(|(i, (r, aus))| FaceRow {
            aus: *aus,
            success: solved[i],
            // The neck's head rotation, with the file's translation.
            pose: head.as_ref().and_then(|h| {
                let p = h.pose[i];
                r.pose.map(|t| [t[0], t[1], t[2], p.pitch, p.yaw, p.roll])
            }),
            landmarks_2d: None,
            landmarks_3d: None,
            ..r.clone()
        })
        .collect();
    let path = out.join("transferred.csv");
    write_openface(&path, &rows)?;
    written.push(path);

    let mut text = format!("frame,{}\n", control_names().join(","));
    for (r, a) in file.rows.iter().zip(acts) {
        text.push_str(&r.frame.to_string());
        for v in a.values() {
            text.push_str(&format!(",{v:.6}"));
        }
        text.push('\n');
    }
    let mut write = |name: &str, bytes: &[u8]| -> Result<()> {
        let path = out.join(name);
        write_atomic(&path, bytes)?;
        written.push(path);
        Ok(())
    };
    write("activations.csv", text.as_bytes())?;
    // Frames the face could not be solved for are written with success = 0 and left out of
    // the scores.
    let (kept_ref, kept_out): (Vec<[f64; AU_COUNT]>, Vec<[f64; AU_COUNT]>) = reference
        .iter()
        .zip(transferred)
        .zip(solved)
        .filter(|(_, ok)| **ok)
        .map(|((r, t), _)| (*r, *t))
        .unzip();
    let mse = au_mse(&kept_ref, &kept_out);
    let mean = mse.iter().sum::<f64>() / AU_COUNT as f64;
    let lines: Vec<MseLine> = AU_NAMES
        .iter()
        .zip(&mse)
        .map(|(a, &mse)| (a.to_string(), mse))
        .chain([("mean".to_string(), mean)])
        .map(|(au, mse)| MseLine { au, mse })
        .collect();
    write("mse.csv", rows::to_csv(&lines).as_bytes())?;
    let mut pose_error = None;
    if let Some(h) = &head {
        let mut text =
            String::from("frame,target_Rx,target_Ry,target_Rz,pose_Rx,pose_Ry,pose_Rz,error_deg\n");
        let mut errors = Vec::with_capacity(n);
        for ((r, target), pose) in file.rows.iter().zip(&h.target).zip(&h.pose) {
            let e = pose.error_degrees(*target);
            errors.push(e);
            text.push_str(&format!(
                "{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{e:.3}\n",
                r.frame, target.pitch, target.yaw, target.roll, pose.pitch, pose.yaw, pose.roll
            ));
        }
        write("head_pose.csv", text.as_bytes())?;
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
        pose_error = Some((rms, errors.iter().copied().fold(0.0, f64::max)));
    }
    if frames.len() > 1 {
        let delay = (1000.0 * dt * gif_every as f64).round().max(20.0) as u32;
        write("transfer.gif", &gif_bytes(frames, delay)?)?;
    }
    for (frame, image) in stills {
        let path = out.join(format!("frame_{frame:05}.png"));
        save_png(image, &path)?;
        written.push(path);
    }
    let fidelity = match judged {
        Some(j) => {
            let frames: Vec<i64> = file.rows.iter().map(|r| r.frame).collect();
            let input: Option<Vec<Option<Blendshapes>>> =
                opts.input_blendshapes.as_ref().map(|b| {
                    frames
                        .iter()
                        .map(|f| {
                            usize::try_from(f - 1)
                                .ok()
                                .and_then(|k| b.get(k).copied().flatten())
                        })
                        .collect()
                });
            let fidelity = j.finish(&frames, input);
            for (name, bytes) in [
                ("fidelity.csv", fidelity.csv.as_bytes()),
                ("fidelity.md", fidelity.markdown.as_bytes()),
            ] {
                let path = out.join(name);
                write_atomic(&path, bytes)?;
                written.push(path);
            }
            Some(fidelity)
        }
        None => None,
    };
    Ok(Written {
        written,
        mse,
        pose_error,
        fidelity,
    })
}

/// A line of a transfer's `mse.csv`: an AU (or `mean`) and its MSE against the input.
#[derive(serde::Serialize, serde::Deserialize)]
struct MseLine {
    au: String,
    #[serde(serialize_with = "num::sci::<6, _>")]
    mse: f64,
}

impl CsvRow for MseLine {}
