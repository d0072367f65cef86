//! The command line's arguments (clap): every subcommand, option and its help.

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};

use facelab::io::face::FaceSource;
use facelab::sim::SolveParams;
use facelab::tools::face::{parse_assignments, PoseRequest};

#[derive(Parser)]
#[command(
    name = "facelab",
    version,
    about = "Biomechanical facial expression transfer, reproduced"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// Print errors only (no stage lines, no progress)
    #[arg(long, short, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Also print every stage found in the cache
    #[arg(long, short, global = true)]
    pub verbose: bool,
}

#[derive(clap::Args, Clone)]
pub struct FaceArgs {
    /// Base mesh (OBJ, cm) [default: assets/face/canonical_face.obj]
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Expression weight table [default: experiments/expressions.csv]
    #[arg(long)]
    pub expressions: Option<PathBuf>,
    /// Loop subdivision levels (0, 1 or 2)
    #[arg(long, default_value_t = 0)]
    pub subdivisions: u8,
    /// Shear modulus of the tissue prisms as a fraction of E/3 [default: 1, the layers'
    /// continuum shear stiffness; 0 = springs alone]
    #[arg(long)]
    pub shear_modulus_fraction: Option<f64>,
}

impl FaceArgs {
    /// The face these arguments name; what they leave out is the layout's.
    pub fn source(&self, layout: &facelab::io::Layout) -> FaceSource {
        FaceSource {
            mesh: self.mesh.clone().unwrap_or_else(|| layout.mesh()),
            expressions: self
                .expressions
                .clone()
                .unwrap_or_else(|| layout.expressions()),
            subdivisions: self.subdivisions,
            shear_modulus_fraction: self.shear_modulus_fraction,
        }
    }
}

/// What to pose: an expression at a scale, then explicit activations.
#[derive(clap::Args, Clone)]
pub struct PoseArgs {
    /// joy, sadness, anger, fear, disgust or surprise
    #[arg(long)]
    pub expression: Option<String>,
    /// Expression scale s in [0, 1] (a = w_e * s)
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Activations, e.g. zygomaticus_major_left=0.7,frontalis_medial_right=0.3
    #[arg(long)]
    pub activation: Option<String>,
    /// Jaw rotation in [0, 1]
    #[arg(long)]
    pub jaw_rotation: Option<f64>,
}

impl PoseArgs {
    pub fn request(&self) -> anyhow::Result<PoseRequest> {
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
pub enum View {
    Frontal,
    ThreeQuarter,
}

#[derive(Subcommand)]
pub enum Command {
    /// Render the face for an expression and/or explicit activations.
    Render(RenderArgs),
    /// Render the rest face, each expression at s = 1 and each muscle alone.
    Gallery(GalleryArgs),
    /// Read the 17 OpenFace AUs: of the simulated face (--expression/--activation), of a
    /// real OpenFace file's 3D landmarks (--openface), recompute the AU gains (--calibrate), or
    /// fit the observer to OpenFace on real faces (--fit).
    Observe(ObserveArgs),
    /// Run an experiment spec: dataset, training, tables, figures (cached by content).
    Run(RunArgs),
    /// (A Slurm array task of a submitted run: its units into the cache.)
    #[command(hide = true)]
    Task(TaskArgs),
    /// Validate a spec and print it resolved, without running anything.
    Check(SpecArgs),
    /// Which stages of a spec are cached and which would run.
    Status(StatusArgs),
    /// Rerun a run from scratch in a temporary folder and compare its CSVs by hash.
    Verify(VerifyArgs),
    /// Transfer the expressions of a photo, a folder of frames, a GIF, a video or an OpenFace
    /// CSV (its AUxx_r columns) onto the model through a run's unified network.
    Transfer(TransferArgs),
    /// Edit activation curves (frame + one column per control) with keyframes: a cubic
    /// B-spline displacement map meets every key and keeps the rest (Choe et al. 2001).
    Edit(EditArgs),
    /// Apply one activation sequence to the base face and to cohort subjects of other
    /// geometry: a grid of renders and an animated GIF (Choe et al.'s retargeting).
    Retarget(RetargetArgs),
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

/// `facelab render`'s arguments.
#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub face: FaceArgs,
    #[command(flatten)]
    pub pose: PoseArgs,
    /// Draw the muscles over the face, coloured by activation
    #[arg(long)]
    pub overlay: bool,
    /// Camera view
    #[arg(long, value_enum, default_value_t = View::Frontal)]
    pub view: View,
    #[arg(long, default_value_t = 480)]
    pub width: u32,
    #[arg(long, default_value_t = 560)]
    pub height: u32,
    /// Output file or folder
    #[arg(long)]
    pub out: PathBuf,
}

/// `facelab gallery`'s arguments.
#[derive(clap::Args)]
pub struct GalleryArgs {
    #[command(flatten)]
    pub face: FaceArgs,
    /// Output file or folder
    #[arg(long, default_value = "figures/face")]
    pub out: PathBuf,
}

/// `facelab observe`'s arguments.
#[derive(clap::Args)]
pub struct ObserveArgs {
    /// A photo (PNG, JPEG), a folder of frames, an animated GIF or a video (via ffmpeg),
    /// through the built-in landmarker: writes openface.csv, landmarks.csv,
    /// blendshapes.csv (MediaPipe's 52 ARKit-named scores per frame) and the landmarks
    /// drawn into the folder --out
    #[arg(conflicts_with_all = ["openface", "fit", "calibrate"], requires = "out")]
    pub input: Option<PathBuf>,
    /// For a picture input: the neutral face [default: model for one picture, median
    /// for several]
    #[arg(long, value_parser = ["model", "median"], requires = "input")]
    pub neutral: Option<String>,
    #[command(flatten)]
    pub face: FaceArgs,
    /// AU calibration table: gains (experiments/au_calibration.csv, the default) or a
    /// fitted readout (experiments/au_observer_fit.csv); with --fit, the gains compared
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Fit the observer's readout to the AUs of the real OpenFace files of --realdata,
    /// validate it leave-one-person-out, and write the readout (--out) and the report
    #[arg(long, conflicts_with_all = ["calibrate", "openface"])]
    pub fit: bool,
    /// With --fit: the list of real files (file,person,licence)
    #[arg(long, default_value = "experiments/realdata.csv")]
    pub realdata: PathBuf,
    /// With --fit: the folder the listed files are in [default: ../shared/realdata]
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// With --fit: which inputs each AU may read (au,inputs,why; `*` for all)
    #[arg(long, default_value = "experiments/au_readout_inputs.csv")]
    pub inputs: PathBuf,
    /// With --fit: where the validation report (lopo.csv) goes
    #[arg(long, default_value = "results/observer_fit")]
    pub report: PathBuf,
    /// Recompute `raw` and `gain` of the calibration table from the model and rewrite it
    #[arg(long)]
    pub calibrate: bool,
    #[command(flatten)]
    pub pose: PoseArgs,
    /// An OpenFace CSV with 3D landmarks to observe
    #[arg(long, requires = "out")]
    pub openface: Option<PathBuf>,
    /// The neutral face: this frame's landmarks [default: the per-landmark median]
    #[arg(long)]
    pub neutral_frame: Option<i64>,
    /// Where to write our AUs (OpenFace layout) for --openface; the readout for --fit
    /// [default with --fit: experiments/au_observer_fit.csv]
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// `facelab run`'s arguments.
#[derive(clap::Args)]
pub struct RunArgs {
    #[command(flatten)]
    pub spec: SpecArgs,
    /// With --set: also replace the tables and figures beside the results folder
    #[arg(long, requires = "sets")]
    pub publish: bool,
    /// Worker threads [default: all cores]; results do not depend on it
    #[arg(long)]
    pub threads: Option<usize>,
    /// Results folder (the cache is in <results>/.cache)
    #[arg(long, default_value = "results")]
    pub results: PathBuf,
    /// Where the units of work run [default: the spec's `[launcher] kind`, else local]:
    /// `slurm` submits them as Slurm job arrays and a final job (see docs/running.md)
    #[arg(long, value_parser = ["local", "slurm"])]
    pub launcher: Option<String>,
    /// With --launcher slurm: wait until the jobs ended; fail naming each failed task
    #[arg(long)]
    pub wait: bool,
    /// (The final job of a Slurm run: finish this run folder from the cache.)
    #[arg(long, hide = true)]
    pub assemble: Option<PathBuf>,
}

/// `facelab task`'s arguments.
#[derive(clap::Args)]
pub struct TaskArgs {
    /// The submission's logs/launch.json
    pub launch: PathBuf,
    /// The array: cells or seeds
    pub array: String,
    /// The task's index [default: $SLURM_ARRAY_TASK_ID]
    #[arg(long)]
    pub index: Option<usize>,
}

/// A spec and its overrides: `facelab check`'s arguments, and the first of `run`'s and
/// `status`'s.
#[derive(clap::Args)]
pub struct SpecArgs {
    /// The spec file (TOML), e.g. experiments/paper.toml
    pub spec: PathBuf,
    /// Override a spec value, typed like the file: --set train.epochs=50. An overridden run
    /// writes its tables and figures into its own run folder
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

/// `facelab status`'s arguments.
#[derive(clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    pub spec: SpecArgs,
    /// Results folder (the cache is in <results>/.cache)
    #[arg(long, default_value = "results")]
    pub results: PathBuf,
}

/// `facelab verify`'s arguments.
#[derive(clap::Args)]
pub struct VerifyArgs {
    /// A run folder, e.g. results/paper/latest
    pub run_dir: PathBuf,
    /// Worker threads [default: all cores]; results do not depend on it
    #[arg(long)]
    pub threads: Option<usize>,
}

/// `facelab transfer`'s arguments.
#[derive(clap::Args)]
pub struct TransferArgs {
    /// A photo (PNG, JPEG), a folder of frames, an animated GIF, a video (via ffmpeg) or an
    /// OpenFace 2.x CSV; the kind is told from the content
    #[arg(required_unless_present = "openface", conflicts_with = "openface")]
    pub input: Option<PathBuf>,
    /// OpenFace 2.x CSV (FeatureExtraction or FaceLandmarkImg output)
    #[arg(long)]
    pub openface: Option<PathBuf>,
    /// Run folder with unified.safetensors, training_aus.csv and spec.toml
    #[arg(long, default_value = "results/paper/latest")]
    pub model: PathBuf,
    /// Map each AU across the file onto the training data's range before the network
    /// [default: minmax for OpenFace files; none for pictures, whose AUs the run's own
    /// observer reads]
    #[arg(long, value_parser = ["none", "minmax", "zscore"])]
    pub normalize: Option<String>,
    /// For pictures: the neutral face the AUs are read against [default: model for one
    /// picture, median for several]
    #[arg(long, value_parser = ["model", "median"])]
    pub neutral: Option<String>,
    /// Frames to render as PNG [default: first, middle and last]
    #[arg(long, value_delimiter = ',')]
    pub frames: Vec<i64>,
    /// Keep the head still even when the file has pose_Rx, pose_Ry, pose_Rz (by default
    /// they drive the neck, with the run's voluntary.safetensors)
    #[arg(long)]
    pub ignore_pose: bool,
    /// Run folder with the neck's voluntary.safetensors and spec.toml, e.g.
    /// results/headpose/latest [default: the --model folder]
    #[arg(long, conflicts_with = "ignore_pose")]
    pub neck: Option<PathBuf>,
    /// Skip the judge (MediaPipe's blendshapes of the input and the transferred face:
    /// fidelity.csv, fidelity.md)
    #[arg(long)]
    pub no_judge: bool,
    /// How the expression becomes activations: `landmarks`, the landmark-space fit to the
    /// person's landmark motion from their neutral face (the default for pictures; an
    /// OpenFace file needs its 3D landmarks), or `network`, the run's unified network on
    /// the AUs (the default for OpenFace files), or `aus`, the AU-space fit: the
    /// activations whose face reads as the input's AUs, through the face itself
    #[arg(long, value_parser = ["landmarks", "network", "aus"])]
    pub method: Option<String>,
    /// Output file or folder
    #[arg(long)]
    pub out: PathBuf,
}

/// `facelab edit`'s arguments.
#[derive(clap::Args)]
pub struct EditArgs {
    /// Curves CSV, e.g. the activations.csv of `facelab transfer`
    #[arg(long)]
    pub curves: PathBuf,
    /// FRAME:name=value[,name=value...]; repeatable
    #[arg(long = "key", value_name = "FRAME:NAME=VALUE", required = true)]
    pub keys: Vec<String>,
    /// Spacing of the B-spline knots (frames): larger is smoother and wider
    #[arg(long, default_value_t = 8.0)]
    pub knot_spacing: f64,
    /// Output file or folder
    #[arg(long)]
    pub out: PathBuf,
    /// Also plot the first keyed curve (original, displacement, edited) as PNG
    #[arg(long)]
    pub figure: Option<PathBuf>,
    /// Knot spacings shown in the figure
    #[arg(long, value_delimiter = ',', default_value = "4,12")]
    pub figure_spacings: Vec<f64>,
}

/// `facelab retarget`'s arguments.
#[derive(clap::Args)]
pub struct RetargetArgs {
    /// Curves CSV (frame + one column per control), e.g. `facelab transfer`'s activations.csv
    #[arg(long)]
    pub curves: PathBuf,
    /// How many image-cohort subjects beside the base face
    #[arg(long, default_value_t = 3)]
    pub subjects: usize,
    /// Frames shown in the grid
    #[arg(long, value_delimiter = ',', required = true)]
    pub frames: Vec<f64>,
    /// Output file or folder
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Subcommand)]
pub enum FaceCommand {
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
    /// What MediaPipe's blendshapes read on the face: rest, the six expressions at s = 1 and
    /// each AU's muscles alone, from a frontal render and from the projected vertices.
    Judge {
        #[command(flatten)]
        face: FaceArgs,
        /// Folder for judge.csv and judge.png
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
pub enum Bench {
    /// The picture path per 640x360 frame on one thread (detection, landmarks, metric fit,
    /// observer) and a clip from frames in memory to AU rows.
    Landmark {
        /// Repetitions per stage
        #[arg(long, default_value_t = 50)]
        frames: usize,
        /// Clip length at 24 fps
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// Threads for the clip
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
        /// Intervals of the grid of equilibria to start the samples from (`dataset.grid`;
        /// 0 = none, else 3 or more), measured at subdivision 0
        #[arg(long, default_value_t = 4)]
        grid: usize,
    },
    /// Training loop speed of the unified network's shape (data in memory): one network, five
    /// seeds batched, and the paper's 35 networks as the training stage runs them.
    Train {
        /// Training pairs (random, in memory)
        #[arg(long, default_value_t = 6000)]
        pairs: usize,
        /// Epochs to time
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Write the pairs as CSV for benches/train_torch.py
        #[arg(long)]
        export: Option<PathBuf>,
        /// Threads for candle [default: 1, as the comparison with PyTorch uses]
        #[arg(long, default_value_t = 1, hide_default_value = true)]
        threads: usize,
    },
    /// Transfer speed per frame (network, solve, observe) on one core, from a run with Table 2.
    Transfer {
        /// Run folder with unified.safetensors and training_aus.csv
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

impl Command {
    /// A path inside the checkout the command works on (a spec, a run folder, a model run):
    /// data files resolve against that checkout when the working folder is not in one.
    pub fn anchor(&self) -> Option<&std::path::Path> {
        match self {
            Command::Run(a) => Some(&a.spec.spec),
            Command::Check(a) => Some(&a.spec),
            Command::Status(a) => Some(&a.spec.spec),
            Command::Verify(a) => Some(&a.run_dir),
            Command::Transfer(a) => Some(&a.model),
            _ => None,
        }
    }

    /// The worker threads the command asked for (`--threads`, or the one core a benchmark
    /// measures on); `None` leaves the choice to [`crate::commands::set_threads`].
    pub fn threads(&self) -> Option<usize> {
        match self {
            Command::Run(a) => a.threads,
            Command::Verify(a) => a.threads,
            Command::Bench { what } => match what {
                Bench::Landmark { threads, .. } | Bench::Train { threads, .. } => Some(*threads),
                Bench::Transfer { .. } | Bench::Neck { .. } => Some(1),
                Bench::Observe { .. } | Bench::Solve { .. } => None,
            },
            _ => None,
        }
    }
}
