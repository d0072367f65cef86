//! `facelab face reach | judge | sweep`: the face's range of motion, what MediaPipe reads on
//! it, and its validity over every muscle, pair and expression.

use facelab::judge::{groups, GROUP_LABELS};
use facelab::tools::face::face_judge;
use facelab::tools::reach::{write_reach, write_sweep};

use super::Context;
use crate::cli::FaceCommand;

pub fn run(what: FaceCommand, cx: &Context) -> anyhow::Result<()> {
    match what {
        FaceCommand::Reach {
            face,
            table,
            calibration,
            out,
        } => {
            let table = table.unwrap_or_else(|| cx.layout.reach());
            let calibration = calibration.unwrap_or_else(|| cx.layout.calibration());
            let (rows, written) =
                write_reach(&face.source(&cx.layout), &table, &calibration, &out)?;
            println!("row\tdisplacement_mm\ttarget_mm\tobserved");
            for r in &rows {
                let target = r
                    .row
                    .target()
                    .map_or("-".to_string(), |(a, b)| format!("{a}-{b}"));
                let chosen = if r.row.chosen.is_some() {
                    " chosen"
                } else {
                    ""
                };
                let mark = if r.in_target() { "" } else { "  (outside)" };
                println!(
                    "{}\t{:.2}\t{target}{chosen}\t{:.2}{mark}",
                    r.row.row, r.displacement_mm, r.observed
                );
            }
            for path in written {
                eprintln!("wrote {}", path.display());
            }
        }
        FaceCommand::Judge { face, out } => {
            let (lines, written) = face_judge(&cx.layout, &face.source(&cx.layout), &out)?;
            println!("case\treading\t{}", GROUP_LABELS.join("\t"));
            for l in &lines {
                let cells: Vec<String> = match &l.scores {
                    Some(s) => groups(s).iter().map(|v| format!("{v:.2}")).collect(),
                    None => vec!["-".into(); GROUP_LABELS.len()],
                };
                println!("{}\t{}\t{}", l.case, l.reading.name(), cells.join("\t"));
            }
            for path in written {
                eprintln!("wrote {}", path.display());
            }
        }
        FaceCommand::Sweep { face, out } => {
            let lines = write_sweep(&face.source(&cx.layout), &out)?;
            for kind in ["single", "pair", "expression"] {
                let of_kind: Vec<_> = lines.iter().filter(|l| l.kind == kind).collect();
                let converged = of_kind.iter().filter(|l| l.converged).count();
                let valid = of_kind.iter().filter(|l| l.is_valid()).count();
                let mut iterations: Vec<f64> =
                    of_kind.iter().map(|l| l.iterations as f64).collect();
                println!(
                    "{kind}: {} cases, {converged} converged, {valid} valid; iterations median {}",
                    of_kind.len(),
                    facelab::stats::median(&mut iterations)
                );
            }
            for l in lines.iter().filter(|l| !l.is_valid()) {
                println!(
                    "invalid: {} ({} inverted, {} folded, {} lip / {} lid crossings; lips {} mm, \
                     lids {} mm) {}",
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
    }
    Ok(())
}
