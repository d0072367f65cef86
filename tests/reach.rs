//! The face's range of motion (`facelab face reach`) and the validity checks it and the
//! sweep rely on.

use facelab::sim::tissue::SURFACE;
use facelab::sim::validity::defects;

use super::{model, temp};

fn run(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(args)
        .current_dir(super::root())
        .output()
        .expect("run facelab");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn rest_face_has_no_defects() {
    let m = model();
    let d = defects(m, &m.rest_state());
    assert!(d.is_clean(), "{d}");
    // The canonical face rests with its lips 5 mm apart at the middle and its lids open.
    assert!(d.min_lip_gap > 0.0 && d.min_lid_gap > 1e-3, "{d}");
}

#[test]
fn lips_pushed_through_each_other_are_caught() {
    let m = model();
    let mut s = m.rest_state();
    // Inner lip midpoints: 13 (upper), 14 (lower); lift the lower one 2 mm above the upper.
    let upper = s.positions[SURFACE * m.vertex_count() + 13];
    s.positions[14][1] = upper[1] + 2e-3;
    let d = defects(m, &s);
    assert!(d.lip_crossings >= 1, "{d}");
    assert!(d.min_lip_gap < -1.5e-3, "{d}");
    assert_eq!(d.lid_crossings, 0, "{d}");
}

#[test]
fn lids_pushed_through_each_other_are_caught() {
    let m = model();
    let mut s = m.rest_state();
    // Right eye lid midpoints: 159 (upper), 145 (lower).
    s.positions[159][1] = s.positions[145][1] - 1.5e-3;
    let d = defects(m, &s);
    assert!(d.lid_crossings >= 1, "{d}");
    assert_eq!(d.lip_crossings, 0, "{d}");
}

#[test]
fn a_surface_node_pushed_under_the_skull_inverts_its_prisms() {
    let m = model();
    let mut s = m.rest_state();
    // Vertex 1 (nose tip) pushed 3 cm into the head, through all its layers.
    s.positions[1][2] -= 0.03;
    let d = defects(m, &s);
    assert!(d.inverted_prisms > 0, "{d}");
    assert!(!d.is_clean());
}

#[test]
fn face_reach_writes_the_table_the_matrix_and_its_heat_map() {
    let dir = temp("reach", "writes");
    let (ok, stdout, stderr) = run(&["face", "reach", "--out", dir.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    let table = std::fs::read_to_string(dir.join("au_reach.csv")).unwrap();
    let mut lines = table.lines();
    assert_eq!(
        lines.next(),
        Some("au,controls,landmark,displacement_mm,band_min_mm,band_max_mm,observed")
    );
    let rows: Vec<Vec<String>> = lines
        .map(|l| {
            let mut r = csv::ReaderBuilder::new()
                .has_headers(false)
                .from_reader(l.as_bytes());
            r.records()
                .next()
                .unwrap()
                .unwrap()
                .iter()
                .map(String::from)
                .collect()
        })
        .collect();
    let names: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    for au in facelab::observe::AU_NAMES {
        assert!(names.contains(&au), "{au} missing from {names:?}");
    }
    assert!(names.contains(&"AU01+02") && names.contains(&"jaw_max"));
    let row = |name: &str| rows.iter().find(|r| r[0] == name).unwrap();
    // Published bands where they exist, empty where none is.
    assert_eq!(
        (row("AU12")[4].as_str(), row("AU12")[5].as_str()),
        ("6", "13")
    );
    assert_eq!((row("AU14")[4].as_str(), row("AU14")[5].as_str()), ("", ""));
    // Every action moves its landmark, the jaw by centimetres.
    for r in &rows {
        let mm: f64 = r[3].parse().unwrap();
        assert!(mm > 0.1, "{} moved {mm} mm", r[0]);
    }
    assert!(row("jaw_max")[3].parse::<f64>().unwrap() > 10.0);
    // Every row lands in its band: facelab's chosen one where it gives one, else the published
    // one, both from `experiments/au_reach.csv` (the smile's widening included).
    let spec = std::fs::read_to_string(super::root().join("experiments/au_reach.csv")).unwrap();
    let bands: Vec<(String, f64, f64)> = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(spec.as_bytes())
        .records()
        .map(|r| {
            let r = r.unwrap();
            let pick = |a: usize, b: usize| {
                (!r[a].is_empty()).then(|| (r[a].parse().unwrap(), r[b].parse().unwrap()))
            };
            let (lo, hi) = pick(8, 9).or_else(|| pick(6, 7)).expect("a band");
            (r[0].to_string(), lo, hi)
        })
        .collect();
    assert_eq!(bands.len(), rows.len());
    for (name, lo, hi) in &bands {
        let mm: f64 = row(name)[3].parse().unwrap();
        assert!(
            (*lo..=*hi).contains(&mm),
            "{name} moved {mm} mm, band {lo}-{hi}"
        );
    }
    // A maximal smile widens the 49 mm mouth by 45-55%, as the real landmark data put it.
    let width: f64 = row("AU12_width")[3].parse().unwrap();
    assert!(
        (22.0..=27.0).contains(&width),
        "smile widens the mouth {width} mm"
    );
    assert!(stdout.contains("jaw_max"), "{stdout}");

    let matrix = std::fs::read_to_string(dir.join("muscle_au_matrix.csv")).unwrap();
    let header = matrix.lines().next().unwrap();
    assert_eq!(header.split(',').count(), 1 + facelab::observe::AU_COUNT);
    // 26 muscle pairs and four jaw inputs.
    assert_eq!(matrix.lines().count(), 1 + 26 + 4);
    let zygomaticus = matrix
        .lines()
        .find(|l| l.starts_with("zygomaticus_major,"))
        .unwrap();
    let au12: f64 = zygomaticus.split(',').nth(9).unwrap().parse().unwrap();
    assert!(au12 > 1.0, "zygomaticus major reads AU12 {au12}");
    let png = image::open(dir.join("muscle_au_matrix.png")).unwrap();
    assert!(png.width() > 800 && png.height() > 600);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_reach_table_is_named_with_its_line() {
    let dir = temp("reach", "bad");
    let table = dir.join("reach.csv");
    let good = std::fs::read_to_string(super::root().join("experiments/au_reach.csv")).unwrap();
    let bad = good.replace("zygomaticus_major=1;levator", "zygomaticus_majr=1;levator");
    std::fs::write(&table, bad).unwrap();
    let (ok, _, stderr) = run(&[
        "face",
        "reach",
        "--table",
        table.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(stderr.contains("reach.csv:"), "{stderr}");
    assert!(
        stderr.contains("did you mean `zygomaticus_major`"),
        "{stderr}"
    );
    assert!(!dir.join("au_reach.csv").exists(), "nothing half-written");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_gallery_refuses_a_face_whose_lips_pass_through_each_other() {
    use facelab::sim::{Activations, FaceModel, Workspace};
    use facelab::tools::face::valid_pose;
    // Without the lip contact, zygomaticus major with the lower half of orbicularis oris
    // pushes the lower lip 2 mm through the upper one near the corners.
    let mesh = facelab::io::mesh::read_obj(&facelab::io::Layout::here().mesh()).unwrap();
    let mut params = facelab::sim::FaceParams::default();
    params.tissue.lip_contact_stiffness = 0.0;
    let open = FaceModel::new(&mesh, params).unwrap();
    let mut a = Activations::neutral();
    for name in [
        "zygomaticus_major_left",
        "zygomaticus_major_right",
        "orbicularis_oris_lower_left",
        "orbicularis_oris_lower_right",
    ] {
        a.set(name, 1.0).unwrap();
    }
    let mut ws = Workspace::new(&open).unwrap();
    let err = valid_pose(&open, &a, &mut ws, "the test face").unwrap_err();
    let text = format!("{err:#}");
    assert!(
        text.contains("the test face") && text.contains("lip"),
        "{text}"
    );
    // With the contact (the default model) the same face is valid.
    let m = model();
    let mut ws = Workspace::new(m).unwrap();
    valid_pose(m, &a, &mut ws, "the test face").unwrap();
}

#[test]
fn gallery_writes_the_contact_sheet() {
    let dir = temp("reach", "gallery");
    let (ok, _, stderr) = run(&["gallery", "--out", dir.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    // Rest, six expressions and the 17 AUs, six to a row of 240 x 280 renders.
    let sheet = image::open(dir.join("contact_sheet.png")).unwrap();
    assert_eq!(sheet.width(), 6 * 240);
    assert_eq!(sheet.height(), 56 + 4 * (280 + 30));
    assert!(dir.join("single").join("jaw_rotation.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
