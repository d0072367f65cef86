//! `facelab transfer`: a picture, a clip or an OpenFace file onto the face, with the judge's
//! verdict.

use facelab::learn::Normalization;
use facelab::observe::AU_NAMES;
use facelab::transfer::network::FLAT_SPREAD;
use facelab::transfer::{transfer_path, TransferMethod, TransferOptions};

use super::{photo_neutral, print_landmarked, Context};
use crate::cli::TransferArgs;

pub fn run(args: TransferArgs, cx: &Context) -> anyhow::Result<()> {
    let input = args
        .input
        .or(args.openface)
        .expect("clap requires an input");
    let (model, neck) = (
        cx.layout.file(args.model),
        args.neck.map(|n| cx.layout.file(n)),
    );
    let method = TransferMethod::for_input(
        &input,
        args.method
            .as_deref()
            .map(|m| TransferMethod::parse(m).expect("clap checked")),
    )?;
    println!("method: {} (--method {})", method.describe(), method.name());
    let (summary, landmarked) = transfer_path(
        &input,
        &TransferOptions {
            model,
            normalize: Normalization::None,
            out: args.out,
            render_frames: args.frames,
            ignore_pose: args.ignore_pose,
            neck,
            pictures: None,
            input_blendshapes: None,
            judge: !args.no_judge,
            fitted: None,
            layout: cx.layout.clone(),
        },
        args.normalize
            .map(|n| Normalization::parse(&n).expect("clap checked")),
        args.neutral.as_deref().map(photo_neutral),
        Some(method),
    )?;
    if let Some(l) = &landmarked {
        print_landmarked(l);
    }
    if !summary.flat.is_empty() {
        let names: Vec<&str> = summary.flat.iter().map(|&k| AU_NAMES[k]).collect();
        println!(
            "normalization: {} of {} AUs barely vary across the {} frame(s) (spread < \
             {FLAT_SPREAD} AU) and keep their own reading: {}",
            names.len(),
            AU_NAMES.len(),
            summary.rows,
            names.join(" ")
        );
    }
    if let Some((rms, max)) = summary.pose_error {
        println!("head pose through the neck: RMS error {rms:.2} deg, max {max:.2} deg");
    }
    if !summary.unsolved.is_empty() {
        eprintln!(
            "warning: {} of {} frames did not converge and are written with success = 0, left \
             out of the scores: {}",
            summary.unsolved.len(),
            summary.rows,
            summary.unsolved.join("; ")
        );
    }
    if let Some(f) = &summary.fidelity {
        for line in &f.summary {
            println!("{line}");
        }
    }
    println!(
        "{} frames transferred, {} skipped (success = 0); AU MSE mean {:.4}",
        summary.rows,
        summary.skipped,
        summary.mean()
    );
    for (a, m) in AU_NAMES.iter().zip(&summary.mse) {
        println!("{a} {m:.4}");
    }
    for p in &summary.written {
        println!("wrote {}", p.display());
    }
    Ok(())
}
