//! `facelab observe`: the AUs of a picture, of a real OpenFace file or of the simulated face;
//! or the observer's calibration (`--calibrate`) and its readout fitted to real faces (`--fit`).

use std::path::PathBuf;

use facelab::io::atomic::write_atomic;
use facelab::io::observer_fit::{read_any_calibration, readout_csv, DEFAULT_READOUT};
use facelab::tools::observe;
use facelab::transfer::pictures::landmark_input;

use super::{photo_neutral, print_landmarked, Context};
use crate::cli::ObserveArgs;

pub fn run(args: ObserveArgs, cx: &Context) -> anyhow::Result<()> {
    let path = args
        .calibration
        .clone()
        .unwrap_or_else(|| cx.layout.calibration());
    let stdout = &mut std::io::stdout().lock();
    if let Some(input) = &args.input {
        let out = args
            .out
            .as_ref()
            .expect("clap requires --out with an input");
        let model = args.face.source(&cx.layout).model()?;
        let l = landmark_input(
            input,
            out,
            &model,
            read_any_calibration(&path)?,
            args.neutral.as_deref().map(photo_neutral),
        )?;
        print_landmarked(&l);
        for p in &l.written {
            println!("wrote {}", p.display());
        }
        return Ok(());
    }
    if let Some(input) = &args.openface {
        let out = args
            .out
            .as_ref()
            .expect("clap requires --out with --openface");
        let neutral = match args.neutral_frame {
            Some(f) => observe::Neutral::Frame(f),
            None => observe::Neutral::Median,
        };
        let calibration = read_any_calibration(&path)?;
        let agreement = observe::observe_openface(input, out, neutral, calibration)?;
        observe::print_agreement(&agreement, stdout)?;
        println!("wrote {}", out.display());
        return Ok(());
    }
    if args.fit {
        let table = observe::load_calibration(&path)?;
        let root = args.data.unwrap_or_else(|| cx.layout.realdata());
        let out = args.out.unwrap_or_else(|| PathBuf::from(DEFAULT_READOUT));
        let result = observe::fit_observer(
            &cx.layout.file(&args.realdata),
            &root,
            &cx.layout.file(&args.inputs),
            &table.calibration(),
        )?;
        let report_path = args.report.join("lopo.csv");
        let report_bytes = observe::report_csv(&result.report);
        let readout_text = readout_csv(&result.readout, &result.provenance);
        write_atomic(&report_path, &report_bytes)?;
        write_atomic(&out, readout_text.as_bytes())?;
        observe::print_fit_summary(&result.report, stdout)?;
        println!("wrote {} and {}", out.display(), report_path.display());
    } else if args.calibrate {
        let table = observe::load_calibration(&path)?;
        let updated = observe::calibrate(&args.face.source(&cx.layout), &table)?;
        write_atomic(&path, updated.to_csv().as_bytes())?;
        println!("wrote {}", path.display());
    } else {
        let request = args.pose.request()?;
        let source = args.face.source(&cx.layout);
        let model = source.model()?;
        let a = request.activations(&source.weights()?)?;
        let observer = facelab::observe::model_observer(&model, read_any_calibration(&path)?)?;
        let o = observe::observe_activations(&model, &observer, &a)?;
        observe::print_observation(&o, stdout)?;
    }
    Ok(())
}
