//! The real-data table's pages: `realfaces.md` per file and route with the per-AU pooled
//! errors, and a sweep's per-cell comparison.

use super::{FileRow, Route, SMILE_AU12};
use crate::observe::{AU_COUNT, AU_NAMES};
use crate::report::table::{Table, TableRow};
use crate::spec::Spec;
use crate::transfer::inverter::AU_PRIOR;

fn f4(v: f64) -> String {
    if v.is_nan() {
        "-".into()
    } else {
        format!("{v:.4}")
    }
}

fn f2(v: f64) -> String {
    if v.is_nan() {
        "-".into()
    } else {
        format!("{v:.2}")
    }
}

/// Frame-weighted per-AU MSE of a set of rows.
fn pooled(rows: &[&FileRow]) -> [f64; AU_COUNT] {
    let n: usize = rows.iter().map(|r| r.frames).sum();
    std::array::from_fn(|k| {
        rows.iter().map(|r| r.mse[k] * r.frames as f64).sum::<f64>() / n.max(1) as f64
    })
}

/// `paper-tables/realfaces.md`: per file and route, and per AU pooled over the files.
pub fn markdown(rows: &[FileRow], spec: &Spec) -> String {
    let seeds: Vec<String> = spec.seeds.iter().map(u64::to_string).collect();
    let first = spec.seeds[0];
    let mut md = format!(
        "# Real faces: transfer error on real OpenFace files\n\n\
         Each file of `{}` (under `{}`; not in the repository) is transferred frame by frame \
         onto the model by three routes: through the unified network (dataset family `{}`, \
         seed{} {}), unnormalized and normalized ({} onto the training data's range, per \
         file), and by the AU-space fit (`au_fit`, `facelab transfer`'s default for OpenFace \
         files: the activations whose face the observer reads as the frame's AUs, through the \
         linear basis with a prior of {AU_PRIOR} per squared activation, corrected {} times \
         through the nonlinear face; no network, so one row per file). The \
         measure compares **OpenFace's AUs in the file** with **our observer's reading of the \
         transferred face** (`{}`){}: per-AU MSE on the 0-1 scale (AU / 5). The network never \
         saw these people; the observer's readout was fitted on them (its leave-one-person-out \
         validation is in the README).{}\n\n",
        spec.realfaces.files,
        spec.realfaces
            .data
            .as_deref()
            .unwrap_or("../shared/realdata"),
        spec.dataset.family.name(),
        if seeds.len() > 1 { "s" } else { "" },
        seeds.join(", "),
        spec.table2_normalization.name(),
        spec.inversion.refinements,
        spec.calibration,
        if spec.reads_on_openface_scale() {
            ", both on OpenFace's scale after the fit"
        } else {
            ""
        },
        if spec.realfaces.frame_stride > 1 {
            format!(
                " Every {}th used frame of each file is transferred.",
                spec.realfaces.frame_stride
            )
        } else {
            String::new()
        }
    );
    md.push_str(&format!(
        "Targets: mean MSE <= 0.01 per file, every AU <= 0.03; a real smile (AU12 >= {SMILE_AU12} \
         in the file) transfers to AU12 within 0.5.\n\n"
    ));
    md.push_str(&format!("## Per file (seed {first})\n\n"));
    let mut t = Table::labelled(&[
        "file",
        "person",
        "setting",
        "frames (skipped)",
        "mean MSE",
        "worst AU (MSE)",
        "AUs > 0.03",
        "smile frames, AU12 abs. error",
        "brow-raise frames, AU01 / AU02 abs. error",
    ]);
    for r in rows.iter().filter(|r| r.seed == first) {
        let worst = (0..AU_COUNT)
            .max_by(|&a, &b| r.mse[a].total_cmp(&r.mse[b]))
            .expect("17 AUs");
        t.push(TableRow::new(vec![
            r.file.clone(),
            r.person.clone(),
            r.route.name().to_string(),
            format!("{} ({})", r.frames, r.skipped),
            f4(r.mean()),
            format!("{} ({})", AU_NAMES[worst], f4(r.mse[worst])),
            r.mse.iter().filter(|&&m| m > 0.03).count().to_string(),
            format!("{}, {}", r.smile.0, f2(r.smile.1)),
            format!("{}, {} / {}", r.brow.0, f2(r.brow.1), f2(r.brow.2)),
        ]));
    }
    md.push_str(&t.markdown());
    md.push_str(&format!(
        "\n## Per AU, pooled over the files (frame-weighted, seed{} {})\n\n",
        if seeds.len() > 1 { "s" } else { "" },
        seeds.join(", ")
    ));
    let header: Vec<&str> = ["setting", "mean"].into_iter().chain(AU_NAMES).collect();
    let mut t = Table::labelled(&header);
    for route in Route::ALL {
        let of: Vec<&FileRow> = rows.iter().filter(|r| r.route == route).collect();
        if of.is_empty() {
            continue;
        }
        let p = pooled(&of);
        let cells = [route.name().to_string(), f4(crate::stats::mean(&p))];
        t.push(TableRow::new(cells.into_iter().chain(p.map(f4)).collect()));
    }
    md.push_str(&t.markdown());
    md
}

/// A sweep's real-data comparison (e.g. the family ablation): per file and setting, each
/// cell's mean MSE (first seed), then the pooled mean per cell.
pub fn sweep_markdown(cells: &[(String, Vec<FileRow>)]) -> String {
    let md = String::from("\n## Real faces: mean AU MSE per file (first seed)\n\n");
    let names = cells.iter().map(|(name, _)| name.as_str());
    let header: Vec<&str> = ["file", "setting"].into_iter().chain(names).collect();
    let mut t = Table::labelled(&header);
    let Some((_, first)) = cells.first() else {
        return md + &t.markdown();
    };
    let seed = first.first().map(|r| r.seed).unwrap_or(1);
    for r in first.iter().filter(|r| r.seed == seed) {
        let means = cells.iter().map(|(_, rows)| {
            let v = rows
                .iter()
                .find(|x| x.seed == seed && x.file == r.file && x.route == r.route)
                .map(FileRow::mean)
                .unwrap_or(f64::NAN);
            f4(v)
        });
        let label = [r.file.clone(), r.route.name().to_string()];
        t.push(TableRow::new(label.into_iter().chain(means).collect()));
    }
    for route in Route::ALL {
        if !first.iter().any(|r| r.route == route) {
            continue;
        }
        let means = cells.iter().map(|(_, rows)| {
            let of: Vec<&FileRow> = rows.iter().filter(|r| r.route == route).collect();
            f4(crate::stats::mean(&pooled(&of)))
        });
        let label = ["pooled".to_string(), route.name().to_string()];
        t.push(TableRow::new(label.into_iter().chain(means).collect()));
    }
    md + &t.markdown()
}
