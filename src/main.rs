//! The `facelab` command line: parse, call the library, print the error chain, exit non-zero
//! on failure.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};

use anyhow::Context;
use facelab::experiments::bench::{
    bench_landmark, bench_neck, bench_observe, bench_solve, bench_train, bench_transfer,
};
use facelab::experiments::face::{gallery, parse_assignments, render_to, FaceSource, PoseRequest};
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

#[derive(Parser)]
#[command(
    name = "facelab",
    version,
    about = "Biomechanical facial expression transfer, reproduced"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args, Clone)]
struct FaceArgs {
    /// Base mesh (OBJ, cm) [default: assets/face/canonical_face.obj]
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Expression weight table [default: experiments/expressions.csv]
    #[arg(long)]
    expressions: Option<PathBuf>,
    /// Loop subdivision levels (0, 1 or 2)
    #[arg(long, default_value_t = 0)]
    subdivisions: u8,
    /// Shear modulus of the tissue prisms as a fraction of E/3 [default: 1, the layers'
    /// continuum shear stiffness; 0 = springs alone]
    #[arg(long)]
    shear_modulus_fraction: Option<f64>,
}

impl FaceArgs {
    fn source(&self) -> FaceSource {
        FaceSource {
            mesh: self.mesh.clone(),
            expressions: self.expressions.clone(),
            subdivisions: self.subdivisions,
            shear_modulus_fraction: self.shear_modulus_fraction,
        }
    }
}

/// What to pose: an expression at a scale, then explicit activations.
#[derive(clap::Args, Clone)]
struct PoseArgs {
    /// joy, sadness, anger, fear, disgust or surprise
    #[arg(long)]
    expression: Option<String>,
    /// Expression scale s in [0, 1] (a = w_e * s)
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Activations, e.g. zygomaticus_major_left=0.7,frontalis_medial_right=0.3
    #[arg(long)]
    activation: Option<String>,
    /// Jaw rotation in [0, 1]
    #[arg(long)]
    jaw_rotation: Option<f64>,
}

impl PoseArgs {
    fn request(&self) -> anyhow::Result<PoseRequest> {
        Ok(PoseRequest {
            expression: self.expression.as_ref().map(|e| e.parse()).transpose()?,
            scale: self.scale,
            activations: self
                .activation
                .as_ref()
                .map(|a| parse_assignments(a))
                .transpose()?
                .unwrap_or_default(),
            jaw_rotation: self.jaw_rotation,
        })
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum View {
    Frontal,
    ThreeQuarter,
}

#[derive(Subcommand)]
enum Command {
    /// Render the face for an expression and/or explicit activations.
    Render {
        #[command(flatten)]
        face: FaceArgs,
        #[command(flatten)]
        pose: PoseArgs,
        /// Draw the muscles over the face, coloured by activation
        #[arg(long)]
        overlay: bool,
        #[arg(long, value_enum, default_value_t = View::Frontal)]
        view: View,
        #[arg(long, default_value_t = 480)]
        width: u32,
        #[arg(long, default_value_t = 560)]
        height: u32,
        #[arg(long)]
        out: PathBuf,
    },
    /// Render the rest face, each expression at s = 1 and each muscle alone.
    Gallery {
        #[command(flatten)]
        face: FaceArgs,
        #[arg(long, default_value = "figures/face")]
        out: PathBuf,
    },
    /// Read the 17 OpenFace AUs: of the simulated face (--expression/--activation), of a
    /// real OpenFace file's 3D landmarks (--openface), recompute the AU gains (--calibrate), or
    /// fit the observer to OpenFace on real faces (--fit).
    Observe {
        /// A photo (PNG, JPEG), a folder of frames, an animated GIF or a video (via ffmpeg),
        /// through the built-in landmarker: writes openface.csv, landmarks.csv and the
        /// landmarks drawn into the folder --out
        #[arg(conflicts_with_all = ["openface", "fit", "calibrate"], requires = "out")]
        input: Option<PathBuf>,
        /// For a picture input: the neutral face [default: model for one picture, median
        /// for several]
        #[arg(long, value_parser = ["model", "median"], requires = "input")]
        neutral: Option<String>,
        #[command(flatten)]
        face: FaceArgs,
        /// AU calibration table: gains (experiments/au_calibration.csv, the default) or a
        /// fitted readout (experiments/au_observer_fit.csv); with --fit, the gains compared
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// Fit the observer's readout to the AUs of the real OpenFace files of --realdata,
        /// validate it leave-one-person-out, and write the readout (--out) and the report
        #[arg(long, conflicts_with_all = ["calibrate", "openface"])]
        fit: bool,
        /// With --fit: the list of real files (file,person,licence)
        #[arg(long, default_value = "experiments/realdata.csv")]
        realdata: PathBuf,
        /// With --fit: the folder the listed files are in [default: ../shared/realdata]
        #[arg(long)]
        data: Option<PathBuf>,
        /// With --fit: which inputs each AU may read (au,inputs,why; `*` for all)
        #[arg(long, default_value = "experiments/au_readout_inputs.csv")]
        inputs: PathBuf,
        /// With --fit: where the validation report (lopo.csv) goes
        #[arg(long, default_value = "results/observer_fit")]
        report: PathBuf,
        /// Recompute `raw` and `gain` of the calibration table from the model and rewrite it
        #[arg(long)]
        calibrate: bool,
        #[command(flatten)]
        pose: PoseArgs,
        /// An OpenFace CSV with 3D landmarks to observe
        #[arg(long, requires = "out")]
        openface: Option<PathBuf>,
        /// The neutral face: this frame's landmarks [default: the per-landmark median]
        #[arg(long)]
        neutral_frame: Option<i64>,
        /// Where to write our AUs (OpenFace layout) for --openface; the readout for --fit
        /// [default with --fit: experiments/au_observer_fit.csv]
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Run an experiment spec: dataset, training, tables, figures (cached by content).
    Run {
        spec: PathBuf,
        /// Override a spec value, typed like the file: --set train.learning_rate=0.001
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Worker threads [default: all cores]; results do not depend on it
        #[arg(long)]
        threads: Option<usize>,
        /// Results folder (the cache is in <results>/.cache)
        #[arg(long, default_value = "results")]
        results: PathBuf,
    },
    /// Validate a spec and print it resolved, without running anything.
    Check {
        spec: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
    },
    /// Which stages of a spec are cached and which would run.
    Status {
        spec: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        #[arg(long, default_value = "results")]
        results: PathBuf,
    },
    /// Rerun a run from scratch in a temporary folder and compare its CSVs by hash.
    Verify {
        run_dir: PathBuf,
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Transfer the expressions of a photo, a folder of frames, a GIF, a video or an OpenFace
    /// CSV (its AUxx_r columns) onto the model through a run's unified network.
    Transfer {
        /// A photo (PNG, JPEG), a folder of frames, an animated GIF, a video (via ffmpeg) or an
        /// OpenFace 2.x CSV; the kind is told from the content
        #[arg(required_unless_present = "openface", conflicts_with = "openface")]
        input: Option<PathBuf>,
        /// OpenFace 2.x CSV (FeatureExtraction or FaceLandmarkImg output)
        #[arg(long)]
        openface: Option<PathBuf>,
        /// Run folder with unified.safetensors, training_aus.csv and spec.toml
        #[arg(long, default_value = "results/paper/latest")]
        model: PathBuf,
        /// Map each AU across the file onto the training data's range before the network
        /// [default: minmax for OpenFace files; none for pictures, whose AUs the run's own
        /// observer reads]
        #[arg(long, value_parser = ["none", "minmax", "zscore"])]
        normalize: Option<String>,
        /// For pictures: the neutral face the AUs are read against [default: model for one
        /// picture, median for several]
        #[arg(long, value_parser = ["model", "median"])]
        neutral: Option<String>,
        /// Frames to render as PNG [default: first, middle and last]
        #[arg(long, value_delimiter = ',')]
        frames: Vec<i64>,
        /// Keep the head still even when the file has pose_Rx, pose_Ry, pose_Rz (by default
        /// they drive the neck, with the run's voluntary.safetensors)
        #[arg(long)]
        ignore_pose: bool,
        /// Run folder with the neck's voluntary.safetensors and spec.toml, e.g.
        /// results/headpose/latest [default: the --model folder]
        #[arg(long, conflicts_with = "ignore_pose")]
        neck: Option<PathBuf>,
        #[arg(long)]
        out: PathBuf,
    },
    /// Edit activation curves (frame + one column per control) with keyframes: a cubic
    /// B-spline displacement map meets every key and keeps the rest (Choe et al. 2001).
    Edit {
        /// Curves CSV, e.g. the activations.csv of `facelab transfer`
        #[arg(long)]
        curves: PathBuf,
        /// FRAME:name=value[,name=value...]; repeatable
        #[arg(long = "key", value_name = "FRAME:NAME=VALUE", required = true)]
        keys: Vec<String>,
        /// Spacing of the B-spline knots (frames): larger is smoother and wider
        #[arg(long, default_value_t = 8.0)]
        knot_spacing: f64,
        #[arg(long)]
        out: PathBuf,
        /// Also plot the first keyed curve (original, displacement, edited) as PNG
        #[arg(long)]
        figure: Option<PathBuf>,
        /// Knot spacings shown in the figure
        #[arg(long, value_delimiter = ',', default_value = "4,12")]
        figure_spacings: Vec<f64>,
    },
    /// Apply one activation sequence to the base face and to cohort subjects of other
    /// geometry: a grid of renders and an animated GIF (Choe et al.'s retargeting).
    Retarget {
        /// Curves CSV (frame + one column per control), e.g. `facelab transfer`'s activations.csv
        #[arg(long)]
        curves: PathBuf,
        /// How many image-cohort subjects beside the base face
        #[arg(long, default_value_t = 3)]
        subjects: usize,
        /// Frames shown in the grid
        #[arg(long, value_delimiter = ',', required = true)]
        frames: Vec<f64>,
        #[arg(long)]
        out: PathBuf,
    },
    /// The face's range of motion and validity.
    Face {
        #[command(subcommand)]
        what: FaceCommand,
    },
    /// Benchmarks (run with --release).
    Bench {
        #[command(subcommand)]
        what: Bench,
    },
}

#[derive(Subcommand)]
enum FaceCommand {
    /// Per AU, how far its FACS muscles at full activation move their landmark (mm) against
    /// the published band, and the muscle-group x AU matrix with its heat map.
    Reach {
        #[command(flatten)]
        face: FaceArgs,
        /// Range-of-motion table [default: experiments/au_reach.csv]
        #[arg(long)]
        table: Option<PathBuf>,
        /// AU calibration table [default: experiments/au_calibration.csv]
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// Folder for au_reach.csv, muscle_au_matrix.csv and muscle_au_matrix.png
        #[arg(long)]
        out: PathBuf,
    },
    /// Solve every muscle group and jaw input alone, every pair of them and the six
    /// expressions at full activation; count non-converged, inverted, folded and crossed faces.
    Sweep {
        #[command(flatten)]
        face: FaceArgs,
        /// Folder for validity.csv
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Subcommand)]
enum Bench {
    /// The picture path per 640x360 frame on one thread (detection, landmarks, metric fit,
    /// observer) and a clip from frames in memory to AU rows.
    Landmark {
        /// Repetitions per stage
        #[arg(long, default_value_t = 50)]
        frames: usize,
        /// Clip length at 24 fps
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// Threads for the clip [default: 1]
        #[arg(long, default_value_t = 1)]
        threads: usize,
    },
    /// Nonlinear and linear-basis solve times and the basis' landmark error.
    Solve {
        #[command(flatten)]
        face: FaceArgs,
        /// Random samples at subdivision 0 (a fifth of them at 1)
        #[arg(long, default_value_t = 60)]
        samples: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Subdivision levels to measure
        #[arg(long, value_delimiter = ',', default_value = "0,1")]
        levels: Vec<u8>,
        /// Relative residual at which a solve has converged
        #[arg(long, default_value_t = SolveParams::default().tolerance)]
        tolerance: f64,
    },
    /// Training loop speed of the unified network's shape (data in memory).
    Train {
        #[arg(long, default_value_t = 6000)]
        pairs: usize,
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Write the pairs as CSV for benches/train_torch.py
        #[arg(long)]
        export: Option<PathBuf>,
        /// Threads for candle [default: 1, as the comparison with PyTorch uses]
        #[arg(long, default_value_t = 1)]
        threads: usize,
    },
    /// Transfer speed per frame (network, solve, observe) on one core, from a run with Table 2.
    Transfer {
        #[arg(long, default_value = "results/paper/latest")]
        model: PathBuf,
        /// Clips of each cohort to time
        #[arg(long, default_value_t = 4)]
        clips: usize,
    },
    /// Neck speed on one core: 1 s at 4 kHz with reflex and learned voluntary control
    /// (`neck.realtime_factor`), the step, the network and the teacher's fit.
    Neck {
        /// Simulated seconds
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
    },
    /// Observer speed: one face (landmarks + AUs), and reading a large OpenFace file.
    Observe {
        /// Frames of the generated OpenFace file (714 columns)
        #[arg(long, default_value_t = 20_000)]
        frames: usize,
    },
}

fn run(cli: Cli) -> anyhow::Result<()> {
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
                let report_bytes = observe::report_csv(&result.report)?;
                let readout_text = readout_csv(&result.readout, &result.provenance);
                write_atomic(&report_path, &report_bytes)
                    .with_context(|| format!("{}: cannot write", report_path.display()))?;
                write_atomic(&out, readout_text.as_bytes())
                    .with_context(|| format!("{}: cannot write", out.display()))?;
                observe::print_fit_summary(&result.report, stdout)?;
                println!("wrote {} and {}", out.display(), report_path.display());
            } else if calibrate {
                let table = observe::load_calibration(&path)?;
                let updated = observe::calibrate(&face.source(), &table)?;
                write_atomic(&path, updated.to_csv().as_bytes())
                    .with_context(|| format!("{}: cannot write", path.display()))?;
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
        } => {
            let threads = set_threads(threads)?;
            let summary = run::run(
                &spec,
                &run::RunOptions {
                    results,
                    sets,
                    threads,
                },
            )?;
            let hits = summary.stages.iter().filter(|s| s.hit).count();
            println!(
                "{} stages, {} cached, {} computed; wrote {}",
                summary.stages.len(),
                hits,
                summary.stages.len() - hits,
                summary.dir.display()
            );
        }
        Command::Check { spec, sets } => {
            let cells = facelab::spec::load(&spec, &sets)?;
            for cell in cells {
                if !cell.name.is_empty() {
                    println!("# cell {}", cell.name);
                }
                print!("{}", facelab::spec::to_toml(&cell.spec.values));
            }
        }
        Command::Status {
            spec,
            sets,
            results,
        } => {
            for (stage, key, cached) in run::status(&spec, &sets, &results)? {
                println!(
                    "{:<7} {stage} {}",
                    if cached { "cached" } else { "stale" },
                    &key[..12]
                );
            }
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
            out,
        } => {
            let input = input.or(openface).expect("clap requires an input");
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
                },
                normalize.map(|n| Normalization::parse(&n).expect("clap checked")),
                neutral.as_deref().map(photo_neutral),
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
                        if r.row.band.is_some() { "" } else { " chosen" },
                        r.observed
                    );
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
                        {
                            let mut it: Vec<usize> = of_kind.iter().map(|l| l.iterations).collect();
                            it.sort_unstable();
                            it.get(it.len() / 2).copied().unwrap_or(0)
                        }
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

/// Sets the worker count for rayon and for candle (which reads `RAYON_NUM_THREADS` on every
/// matrix product when it is unset, at a cost). Returns the count used.
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

fn set_threads(threads: Option<usize>) -> anyhow::Result<usize> {
    let n = threads.unwrap_or_else(|| {
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
