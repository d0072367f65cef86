//! The `facelab` command line: parse, call the library, print the error chain, exit non-zero
//! on failure.

mod cli;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use anyhow::Context;
use facelab::experiments::bench::{
    bench_landmark, bench_neck, bench_observe, bench_solve, bench_train, bench_transfer,
};
use facelab::experiments::face::{gallery, render_to};
use facelab::experiments::observe;
use facelab::experiments::reach;
use facelab::experiments::run;
use facelab::experiments::transfer;
use facelab::io::atomic::write_atomic;
use facelab::io::calibration::default_calibration_path;
use facelab::io::observer_fit::{read_any_calibration, readout_csv, DEFAULT_READOUT};
use facelab::learn::Normalization;
use facelab::observe::AU_NAMES;
use facelab::report::render::{Camera, RenderOptions};
use facelab::sim::SolveParams;

use cli::*;

fn run(cli: Cli) -> anyhow::Result<()> {
    use facelab::experiments::stage::{set_verbosity, Verbosity};
    set_verbosity(match (cli.quiet, cli.verbose) {
        (true, _) => Verbosity::Quiet,
        (_, true) => Verbosity::Verbose,
        _ => Verbosity::Normal,
    });
    if let Some(path) = cli.command.anchor() {
        facelab::io::set_data_root(path.parent().unwrap_or(path));
    }
    match cli.command {
        Command::Render {
            face,
            pose,
            overlay,
            view,
            width,
            height,
            out,
        } => {
            let request = pose.request()?;
            let options = RenderOptions {
                width,
                height,
                camera: match view {
                    View::Frontal => Camera::frontal(),
                    View::ThreeQuarter => Camera::three_quarter(),
                },
                muscle_overlay: overlay,
            };
            render_to(&face.source(), &request, &options, &out)?;
            println!("wrote {}", out.display());
        }
        Command::Gallery { face, out } => {
            let written = gallery(&face.source(), &out)?;
            println!("wrote {} images to {}", written.len(), out.display());
        }
        Command::Observe {
            input,
            neutral,
            face,
            calibration,
            calibrate,
            fit,
            realdata,
            data,
            inputs,
            report,
            pose,
            openface,
            neutral_frame,
            out,
        } => {
            let path = calibration.unwrap_or_else(default_calibration_path);
            let stdout = &mut std::io::stdout().lock();
            if let Some(input) = input {
                let out = out.expect("clap requires --out with an input");
                let model = face.source().model()?;
                let l = facelab::experiments::photos::landmark_input(
                    &input,
                    &out,
                    &model,
                    read_any_calibration(&path)?,
                    neutral.as_deref().map(photo_neutral),
                )?;
                print_landmarked(&l);
                for p in &l.written {
                    println!("wrote {}", p.display());
                }
                return Ok(());
            }
            if let Some(input) = openface {
                let out = out.expect("clap requires --out with --openface");
                let neutral = match neutral_frame {
                    Some(f) => observe::Neutral::Frame(f),
                    None => observe::Neutral::Median,
                };
                let calibration = read_any_calibration(&path)?;
                let agreement = observe::observe_openface(&input, &out, neutral, calibration)?;
                observe::print_agreement(&agreement, stdout)?;
                println!("wrote {}", out.display());
                return Ok(());
            }
            if fit {
                let table = observe::load_calibration(&path)?;
                let root = data.unwrap_or_else(observe::default_realdata_root);
                let out = out.unwrap_or_else(|| PathBuf::from(DEFAULT_READOUT));
                let result =
                    observe::fit_observer(&realdata, &root, &inputs, &table.calibration())?;
                let report_path = report.join("lopo.csv");
                let report_bytes = observe::report_csv(&result.report);
                let readout_text = readout_csv(&result.readout, &result.provenance);
                write_atomic(&report_path, &report_bytes)?;
                write_atomic(&out, readout_text.as_bytes())?;
                observe::print_fit_summary(&result.report, stdout)?;
                println!("wrote {} and {}", out.display(), report_path.display());
            } else if calibrate {
                let table = observe::load_calibration(&path)?;
                let updated = observe::calibrate(&face.source(), &table)?;
                write_atomic(&path, updated.to_csv().as_bytes())?;
                println!("wrote {}", path.display());
            } else {
                let request = pose.request()?;
                let source = face.source();
                let model = source.model()?;
                let a = request.activations(&source.weights()?)?;
                let observer = observe::model_observer(&model, read_any_calibration(&path)?)?;
                let o = observe::observe_activations(&model, &observer, &a)?;
                observe::print_observation(&o, stdout)?;
            }
        }
        Command::Run {
            spec,
            sets,
            threads,
            results,
            publish,
            launcher,
            wait,
            assemble,
        } => {
            let threads = set_threads(threads)?;
            let spec = data_arg(spec);
            let given = launcher
                .as_deref()
                .and_then(facelab::spec::LauncherKind::parse);
            let opts = run::RunOptions {
                results: results_folder(results),
                sets,
                threads,
                publish,
                assemble,
            };
            let kind = run::launcher_of(&spec, &opts.sets, given)?;
            if kind == facelab::spec::LauncherKind::Slurm && opts.assemble.is_none() {
                let l = run::launch(&spec, &opts)?;
                let job = |j: &Option<String>| j.clone().unwrap_or_else(|| "-".into());
                println!(
                    "submitted {} task(s) ({} cached, not submitted): cells array {}, seeds \
                     array {}, final job {}; run folder {}",
                    l.tasks,
                    l.skipped,
                    job(&l.cells_job),
                    job(&l.seeds_job),
                    l.final_job,
                    l.run_dir.display()
                );
                if wait {
                    run::wait(&l)?;
                }
                return Ok(());
            }
            if wait {
                anyhow::bail!("--wait is for --launcher slurm; a local run always waits");
            }
            let summary = run::run(&spec, &opts)?;
            let hits = summary.stages.iter().filter(|s| s.hit).count();
            println!(
                "{} stages, {} cached, {} computed; wrote {}",
                summary.stages.len(),
                hits,
                summary.stages.len() - hits,
                summary.dir.display()
            );
        }
        Command::Task {
            launch,
            array,
            index,
        } => {
            set_threads(None)?;
            run::task(&launch, &array, index)?;
        }
        Command::Check { spec, sets } => {
            let cells = facelab::spec::load(&data_arg(spec), &sets)?;
            for cell in cells {
                if !cell.name.is_empty() {
                    println!("# cell {}", cell.name);
                }
                print!("{}", cell.spec.to_toml());
            }
        }
        Command::Status {
            spec,
            sets,
            results,
        } => {
            let results = results_folder(results);
            let lines = run::status(&data_arg(spec), &sets, &results)?;
            let (mut cached, mut todo) = (0, 0);
            for line in &lines {
                let (state, note) = match &line.state {
                    run::UnitState::Cached => ("cached", String::new()),
                    run::UnitState::Missing => ("missing", String::new()),
                    run::UnitState::Damaged(why) => ("damaged", format!(" ({why})")),
                    run::UnitState::Waiting(why) => ("waiting", format!(" ({why})")),
                    run::UnitState::Queued(by) => ("queued", format!(" ({by})")),
                    run::UnitState::Running(by) => ("running", format!(" ({by})")),
                    run::UnitState::Failed(why) => ("failed", format!(" ({why})")),
                };
                if line.state == run::UnitState::Cached {
                    cached += 1;
                } else {
                    todo += 1;
                }
                let cell = if line.cell.is_empty() {
                    String::new()
                } else {
                    format!(" [{}]", line.cell)
                };
                let key = line
                    .unit
                    .as_ref()
                    .map_or("-".to_string(), |u| u.key[..12].to_string());
                println!("{state:<8} {key:<12} {}{cell}{note}", line.label);
            }
            println!(
                "{cached} cached, {todo} to run in {}; status reads the cache and changes nothing",
                results.join(".cache").display()
            );
        }
        Command::Verify { run_dir, threads } => {
            let threads = set_threads(threads)?;
            let differ = run::verify(&run_dir, threads)?;
            if differ.is_empty() {
                println!("{}: every CSV reproduced byte for byte", run_dir.display());
            } else {
                anyhow::bail!(
                    "{}: these outputs differ on rerun: {}",
                    run_dir.display(),
                    differ.join(", ")
                );
            }
        }
        Command::Transfer {
            input,
            openface,
            model,
            normalize,
            neutral,
            frames,
            ignore_pose,
            neck,
            no_judge,
            method,
            out,
        } => {
            let input = input.or(openface).expect("clap requires an input");
            let (model, neck) = (data_arg(model), neck.map(data_arg));
            let (summary, landmarked) = transfer::transfer_path(
                &input,
                &transfer::TransferOptions {
                    openface: input.clone(),
                    model,
                    normalize: Normalization::None,
                    out,
                    render_frames: frames,
                    ignore_pose,
                    neck,
                    pictures: None,
                    openface_bytes: None,
                    input_blendshapes: None,
                    judge: !no_judge,
                    fitted: None,
                },
                normalize.map(|n| Normalization::parse(&n).expect("clap checked")),
                neutral.as_deref().map(photo_neutral),
                method
                    .as_deref()
                    .map(|m| transfer::TransferMethod::parse(m).expect("clap checked")),
            )?;
            if let Some(l) = &landmarked {
                print_landmarked(l);
            }
            if !summary.flat.is_empty() {
                let names: Vec<&str> = summary.flat.iter().map(|&k| AU_NAMES[k]).collect();
                println!(
                    "normalization: {} of {} AUs barely vary across the {} frame(s) (spread < \
                     {} AU) and keep their own reading: {}",
                    names.len(),
                    AU_NAMES.len(),
                    summary.rows,
                    facelab::experiments::table2::FLAT_SPREAD,
                    names.join(" ")
                );
            }
            if let Some((rms, max)) = summary.pose_error {
                println!("head pose through the neck: RMS error {rms:.2} deg, max {max:.2} deg");
            }
            if !summary.unsolved.is_empty() {
                eprintln!(
                    "warning: {} of {} frames did not converge and are written with success = \
                     0, left out of the scores: {}",
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
        }
        Command::Edit {
            curves,
            keys,
            knot_spacing,
            out,
            figure,
            figure_spacings,
        } => {
            let written = facelab::experiments::editing::edit_file(
                &curves,
                &keys,
                knot_spacing,
                &out,
                figure.as_deref().map(|f| (f, figure_spacings.as_slice())),
            )?;
            for p in written {
                println!("wrote {}", p.display());
            }
        }
        Command::Retarget {
            curves,
            subjects,
            frames,
            out,
        } => {
            for p in facelab::experiments::editing::retarget(&curves, subjects, &frames, &out)? {
                println!("wrote {}", p.display());
            }
        }
        Command::Face { what } => match what {
            FaceCommand::Reach {
                face,
                table,
                calibration,
                out,
            } => {
                let table = table.unwrap_or_else(facelab::io::reach::default_reach_path);
                let (rows, written) =
                    reach::write_reach(&face.source(), &table, calibration.as_deref(), &out)?;
                println!("row\tdisplacement_mm\ttarget_mm\tobserved");
                for r in &rows {
                    let target = r
                        .row
                        .target()
                        .map_or("-".to_string(), |(a, b)| format!("{a}-{b}"));
                    let mark = if r.in_target() { "" } else { "  (outside)" };
                    println!(
                        "{}\t{:.2}\t{target}{}\t{:.2}{mark}",
                        r.row.row,
                        r.displacement_mm,
                        if r.row.chosen.is_some() {
                            " chosen"
                        } else {
                            ""
                        },
                        r.observed
                    );
                }
                for path in written {
                    eprintln!("wrote {}", path.display());
                }
            }
            FaceCommand::Judge { face, out } => {
                let (lines, written) =
                    facelab::experiments::face::face_judge(&face.source(), &out)?;
                let labels = facelab::judge::GROUP_LABELS;
                println!("case\treading\t{}", labels.join("\t"));
                for l in &lines {
                    let cells: Vec<String> = match &l.scores {
                        Some(s) => facelab::judge::groups(s)
                            .iter()
                            .map(|v| format!("{v:.2}"))
                            .collect(),
                        None => vec!["-".into(); labels.len()],
                    };
                    println!("{}\t{}\t{}", l.case, l.reading.name(), cells.join("\t"));
                }
                for path in written {
                    eprintln!("wrote {}", path.display());
                }
            }
            FaceCommand::Sweep { face, out } => {
                let lines = reach::write_sweep(&face.source(), &out)?;
                for kind in ["single", "pair", "expression"] {
                    let of_kind: Vec<_> = lines.iter().filter(|l| l.kind == kind).collect();
                    let converged = of_kind.iter().filter(|l| l.converged).count();
                    let valid = of_kind.iter().filter(|l| l.is_valid()).count();
                    println!(
                        "{kind}: {} cases, {converged} converged, {valid} valid; iterations \
                         median {}",
                        of_kind.len(),
                        facelab::stats::median(
                            &mut of_kind
                                .iter()
                                .map(|l| l.iterations as f64)
                                .collect::<Vec<_>>()
                        )
                    );
                }
                for l in lines.iter().filter(|l| !l.is_valid()) {
                    println!(
                        "invalid: {} ({} inverted, {} folded, {} lip / {} lid crossings; lips \
                         {} mm, lids {} mm) {}",
                        l.case,
                        l.inverted_prisms,
                        l.folded_triangles,
                        l.lip_crossings,
                        l.lid_crossings,
                        l.min_lip_gap_mm,
                        l.min_lid_gap_mm,
                        l.error
                    );
                }
                eprintln!("wrote {}", out.join("validity.csv").display());
                if lines.iter().any(|l| !l.is_valid()) {
                    anyhow::bail!("some faces of the sweep are not valid (see above)");
                }
            }
        },
        Command::Bench { what } => match what {
            Bench::Landmark {
                frames,
                seconds,
                threads,
            } => {
                set_threads(Some(threads))?;
                bench_landmark(frames, seconds, &mut std::io::stdout().lock())?
            }
            Bench::Train {
                pairs,
                epochs,
                export,
                threads,
            } => {
                set_threads(Some(threads))?;
                bench_train(
                    pairs,
                    epochs,
                    export.as_deref(),
                    &mut std::io::stdout().lock(),
                )?
            }
            Bench::Transfer { model, clips } => {
                set_threads(Some(1))?;
                bench_transfer(&model, clips, &mut std::io::stdout().lock())?
            }
            Bench::Neck { seconds } => {
                set_threads(Some(1))?;
                bench_neck(seconds, &mut std::io::stdout().lock())?
            }
            Bench::Observe { frames } => bench_observe(frames, &mut std::io::stdout().lock())?,
            Bench::Solve {
                face,
                samples,
                seed,
                levels,
                tolerance,
            } => bench_solve(
                &face.source(),
                &levels,
                samples,
                seed,
                &SolveParams {
                    tolerance,
                    ..SolveParams::default()
                },
                &mut std::io::stdout().lock(),
            )?,
        },
    }
    Ok(())
}

fn photo_neutral(name: &str) -> facelab::experiments::photos::PhotoNeutral {
    use facelab::experiments::photos::PhotoNeutral;
    match name {
        "model" => PhotoNeutral::Model,
        _ => PhotoNeutral::Median,
    }
}

fn print_landmarked(l: &facelab::experiments::photos::LandmarkOutput) {
    for w in &l.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "{:?}: a face in {} frame(s), none in {}",
        l.kind, l.faces, l.missing
    );
}

/// Sets the worker count for rayon and for candle (which reads `RAYON_NUM_THREADS` on every
/// matrix product when it is unset, at a cost). Returns the count used.
fn set_threads(threads: Option<usize>) -> anyhow::Result<usize> {
    // Inside a Slurm allocation, "all cores" are the task's.
    let allocated = std::env::var("SLURM_CPUS_PER_TASK")
        .ok()
        .and_then(|v| v.parse::<usize>().ok());
    let n = threads.or(allocated).unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    if n == 0 {
        anyhow::bail!("--threads must be at least 1");
    }
    std::env::set_var("RAYON_NUM_THREADS", n.to_string());
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
        .context("starting the thread pool")?;
    Ok(n)
}

/// A file or folder of the checkout named on the command line (a spec, a run folder): as
/// given where it exists, else found in the checkout or the binary's built-in copy
/// ([`facelab::io::data_path`]), so `facelab run experiments/smoke.toml` and the default
/// `--model results/paper/latest` work from any folder.
fn data_arg(given: PathBuf) -> PathBuf {
    if given.exists() || given.is_absolute() {
        return given;
    }
    given.to_str().map_or(given.clone(), facelab::io::data_path)
}

/// The results folder: the default `results` means the checkout's `results/` when the working
/// folder is inside a checkout (so a run from a subfolder writes where a run from the root
/// does); anything else is taken as given, relative to the working folder.
fn results_folder(given: PathBuf) -> PathBuf {
    if given != std::path::Path::new("results") {
        return given;
    }
    std::env::current_dir()
        .ok()
        .and_then(|d| facelab::io::find_root(&d))
        .map_or(given, |root| root.join("results"))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
