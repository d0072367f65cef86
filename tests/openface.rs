//! OpenFace CSV files: every header variant reads the same values, our writer round-trips
//! byte for byte, and bad files fail with the file, line and column.

use std::path::Path;

use facelab::io::openface::{openface_bytes, parse_openface, OpenFaceError, OpenFaceFile};
use facelab::observe::AU_NAMES;

fn au_header(sep: &str) -> String {
    AU_NAMES
        .iter()
        .map(|a| format!("{a}_r"))
        .collect::<Vec<_>>()
        .join(sep)
}

fn au_values(base: f64, sep: &str) -> String {
    (0..17)
        .map(|k| format!("{:.2}", base + 0.1 * k as f64))
        .collect::<Vec<_>>()
        .join(sep)
}

fn parse(text: &str) -> Result<OpenFaceFile, OpenFaceError> {
    parse_openface(text.as_bytes().to_vec(), Path::new("fixture.csv"))
}

/// Three frames, the second failed, in OpenFace 2.2's layout.
fn v22() -> String {
    format!(
        "frame,face_id,timestamp,confidence,success,pose_Tx,pose_Ty,pose_Tz,pose_Rx,pose_Ry,pose_Rz,{}\n\
         1,0,0.000,0.98,1,1.0,2.0,300.0,0.100,-0.200,0.030,{}\n\
         2,0,0.033,0.10,0,0.0,0.0,0.0,0.000,0.000,0.000,{}\n\
         3,0,0.067,0.97,1,1.5,2.5,301.0,0.110,-0.210,0.040,{}\n",
        au_header(","),
        au_values(0.0, ","),
        au_values(9.0, ","),
        au_values(1.0, ","),
    )
}

#[test]
fn header_variants_read_the_same_values() {
    let a = parse(&v22()).unwrap();
    assert_eq!((a.rows.len(), a.skipped), (2, 1));
    assert_eq!(a.rows[1].frame, 3);
    assert_eq!(a.rows[1].line, 4);
    assert!((a.rows[1].aus[16] - 2.6).abs() < 1e-12);
    assert_eq!(a.rows[0].pose.unwrap()[4], -0.2);

    // OpenFace 2.0: ", " and no face_id.
    let b = parse(&format!(
        "frame, timestamp, confidence, success, {}\n1, 0.000, 0.98, 1, {}\n2, 0.033, 0.10, 0, {}\n3, 0.067, 0.97, 1, {}\n",
        au_header(", "),
        au_values(0.0, ", "),
        au_values(9.0, ", "),
        au_values(1.0, ", "),
    ))
    .unwrap();
    assert_eq!((b.rows.len(), b.skipped), (2, 1));
    assert!(!b.layout.face_id);
    for (x, y) in a.rows.iter().zip(&b.rows) {
        assert_eq!(x.aus, y.aus);
        assert_eq!(x.frame, y.frame);
    }

    // FaceLandmarkImg: `face, confidence` and no success column.
    let c = parse(&format!(
        "face, confidence, {}\n0, 0.98, {}\n1, 0.97, {}\n",
        au_header(", "),
        au_values(0.0, ", "),
        au_values(1.0, ", "),
    ))
    .unwrap();
    assert!(c.layout.image_mode);
    assert_eq!(c.rows.len(), 2);
    assert_eq!(c.rows[1].aus, a.rows[1].aus);
}

#[test]
fn our_writer_round_trips_byte_for_byte() {
    let file = parse(&v22()).unwrap();
    let bytes = openface_bytes(&file.rows);
    let again = parse_openface(bytes.clone(), Path::new("ours.csv")).unwrap();
    assert_eq!(again.rows.len(), 2);
    assert_eq!(openface_bytes(&again.rows), bytes);
    assert_eq!(again.rows[1].aus, file.rows[1].aus);
}

/// Frames made in memory read as their written file reads: `OpenFaceFile::from_rows` is
/// `parse_openface(openface_bytes(rows))` without the bytes, on the committed real file's rows
/// given extra digits (so every value is rounded as the writer rounds it), a frame with no
/// face, and the blocks present or absent.
#[test]
fn rows_made_in_memory_read_as_their_written_file() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/openface/py-feat/OpenFace_Test.csv");
    let file = facelab::io::openface::read_openface(&path).unwrap();
    let mut rows: Vec<_> = file.rows.iter().take(12).cloned().collect();
    for (i, r) in rows.iter_mut().enumerate() {
        let wiggle = |v: f64, k: usize| v + 0.001_234_567 * ((i * 31 + k * 7) % 13) as f64 - 0.0071;
        r.aus = std::array::from_fn(|k| wiggle(r.aus[k], k));
        r.confidence = wiggle(r.confidence, 99);
        r.timestamp = r.timestamp.map(|t| wiggle(t, 98));
        if let Some(p) = r.pose.as_mut() {
            *p = std::array::from_fn(|k| wiggle(p[k], k + 40));
        }
        if let Some(l) = r.landmarks_3d.as_mut() {
            for (j, q) in l.iter_mut().enumerate() {
                *q = std::array::from_fn(|k| wiggle(q[k], j + k));
            }
        }
    }
    rows[3].success = false;
    rows[3].aus = [0.0; 17];
    let mut without_pose = rows.clone();
    without_pose[5].pose = None;
    for rows in [rows, without_pose] {
        let name = Path::new("frames.csv");
        let written = parse_openface(openface_bytes(&rows), name).unwrap();
        let made = OpenFaceFile::from_rows(name, &rows);
        assert_eq!(made, written);
        assert_eq!(made.skipped, 1);
    }
}

fn error(text: &str) -> String {
    parse(text).unwrap_err().to_string()
}

#[test]
fn bad_files_name_file_line_and_column() {
    let missing = error("frame,success,AU01_r\n1,1,0.5\n");
    assert!(
        missing.contains("fixture.csv:1") && missing.contains("AU02_r"),
        "{missing}"
    );

    let e = error(&v22().replace("3,0,0.067,0.97,1,1.5", "3,0,0.067,0.97,1,abc"));
    assert!(
        e.contains("fixture.csv:4") && e.contains("pose_Tx") && e.contains("abc"),
        "{e}"
    );

    let short = v22().replace("3,0,0.067,0.97,1,1.5,", "3,0,0.067,0.97,1,");
    let e = error(&short);
    assert!(
        e.contains("fixture.csv:4") && e.contains("27 cells") && e.contains("28 columns"),
        "{e}"
    );

    assert!(error("").contains("empty"));
    assert!(error("frame\tsuccess\n1\t1\n").contains("unknown separator"));

    let nan = v22().replacen("0.100,-0.200", "NaN,-0.200", 1);
    let e = error(&nan);
    assert!(e.contains("fixture.csv:2") && e.contains("pose_Rx"), "{e}");
}

#[test]
fn full_feature_extraction_file_reads_every_block() {
    use facelab::io::openface::full_header;
    let header = full_header();
    assert_eq!(header.len(), 714);
    let row = |frame: usize, success: u8| {
        let mut cells = vec![
            frame.to_string(),
            "0".into(),
            "0.0".into(),
            "0.9".into(),
            success.to_string(),
        ];
        cells.extend((5..header.len()).map(|i| format!("{:.1}", (i % 97) as f64 * 0.1)));
        cells.join(",")
    };
    let text = format!("{}\n{}\n{}\n", header.join(","), row(1, 1), row(2, 0));
    let file = parse(&text).unwrap();
    assert!(file.layout.pose && file.layout.landmarks_2d && file.layout.landmarks_3d);
    assert_eq!((file.rows.len(), file.skipped), (1, 1));
    let r = &file.rows[0];
    let at = |name: &str| {
        let i = header.iter().position(|h| h == name).unwrap();
        (i % 97) as f64 * 0.1
    };
    assert!((r.landmarks_3d.as_ref().unwrap()[30][2] - at("Z_30")).abs() < 1e-9);
    assert!((r.landmarks_2d.as_ref().unwrap()[5][1] - at("y_5")).abs() < 1e-9);
    assert!((r.pose.unwrap()[3] - at("pose_Rx")).abs() < 1e-9);
    assert!((r.aus[8] - at("AU12_r")).abs() < 1e-9);
}
