//! Table 1's CSV, markdown, LaTeX and figures, and the sweep summary across cells.

use crate::experiments::table1::{self, Network, Row};
use crate::spec::Spec;
use crate::stats;
use anyhow::Result;
use std::path::Path;

use super::*;

pub(super) fn fmt(v: f64) -> String {
    format!("{v:.6e}")
}

/// `seed,joy,...,disgust,all,unified_joy,...` rows, then `mean` and `ci95`.
pub(super) fn table1_csv(rows: &[Row]) -> String {
    let names: Vec<String> = table1::ORDER.iter().map(|e| e.to_string()).collect();
    let mut out = format!(
        "seed,{},all,{}\n",
        names.join(","),
        names
            .iter()
            .map(|n| format!("unified_{n}"))
            .collect::<Vec<_>>()
            .join(",")
    );
    let line = |label: String, v: &[f64]| {
        format!(
            "{label},{}\n",
            v.iter().map(|x| fmt(*x)).collect::<Vec<_>>().join(",")
        )
    };
    let flat: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            r.per_expression
                .iter()
                .chain(std::iter::once(&r.all))
                .chain(&r.unified_restricted)
                .copied()
                .collect()
        })
        .collect();
    for (r, v) in rows.iter().zip(&flat) {
        out.push_str(&line(r.seed.to_string(), v));
    }
    let column = |j: usize| flat.iter().map(|v| v[j]).collect::<Vec<_>>();
    let means: Vec<f64> = (0..13).map(|j| stats::mean(&column(j))).collect();
    let cis: Vec<f64> = (0..13).map(|j| stats::ci95(&column(j))).collect();
    out.push_str(&line("mean".into(), &means));
    out.push_str(&line("ci95".into(), &cis));
    out
}

pub(super) fn summary(rows: &[Row]) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let col = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).collect::<Vec<_>>();
    let mut mean = Vec::new();
    let mut ci = Vec::new();
    let mut umean = Vec::new();
    let mut uci = Vec::new();
    for k in 0..6 {
        let v = col(&|r| r.per_expression[k]);
        mean.push(stats::mean(&v));
        ci.push(stats::ci95(&v));
        let u = col(&|r| r.unified_restricted[k]);
        umean.push(stats::mean(&u));
        uci.push(stats::ci95(&u));
    }
    let all = col(&|r| r.all);
    mean.push(stats::mean(&all));
    ci.push(stats::ci95(&all));
    (mean, ci, umean, uci)
}

pub(super) fn paired_cell((m, c, excludes_zero): (f64, f64, bool), dagger: &str) -> String {
    format!(
        "{m:+.1e} ± {c:.1e}{}",
        if excludes_zero { dagger } else { "" }
    )
}

pub(super) fn table1_markdown(rows: &[Row], spec: &Spec, samples: usize) -> String {
    let (mean, ci, umean, uci) = summary(rows);
    let heads: Vec<String> = table1::ORDER
        .iter()
        .map(|e| format!("MSE_{}", capitalize(e.name())))
        .chain(std::iter::once("MSE_All".into()))
        .collect();
    let mut out =
        String::from("# Table 1: per-expression networks vs one unified network (test MSE)\n\n");
    out.push_str(&format!(
        "facelab: {} seeds ({}), {} pairs ({} per expression, {:.0}% held out), network {} x {} ReLU, Adam lr {}, batch {}, {} epochs, normalization {}. Mean ± 95% interval over seeds.\n\n",
        rows.len(),
        spec.seeds.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", "),
        samples,
        spec.dataset.pairs_per_expression,
        spec.dataset.test_fraction * 100.0,
        spec.model.layers,
        spec.model.width,
        spec.train.learning_rate,
        spec.train.batch_size,
        spec.train.epochs,
        spec.train.normalization.name(),
    ));
    out.push_str(&format!("| | {} |\n", heads.join(" | ")));
    out.push_str(&format!("|---|{}\n", "---|".repeat(7)));
    out.push_str(&format!(
        "| Zeng et al. | {} |\n",
        table1::PAPER
            .iter()
            .map(|v| format!("{v:.6}"))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(&format!(
        "| facelab | {} |\n",
        mean.iter()
            .zip(&ci)
            .map(|(m, c)| format!("{m:.2e} ± {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(&format!(
        "| facelab / paper | {} |\n",
        mean.iter()
            .zip(&table1::PAPER)
            .map(|(m, p)| format!("{:.2e}", m / p))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(&format!(
        "| unified network, same pairs and outputs | {} | {:.2e} ± {:.1e} |\n",
        umean
            .iter()
            .zip(&uci)
            .map(|(m, c)| format!("{m:.2e} ± {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" | "),
        mean[6],
        ci[6]
    ));
    out.push_str(&format!(
        "| per-expression - unified, paired over seeds | {} | |\n",
        table1::paired(rows)
            .into_iter()
            .map(|p| paired_cell(p, " †"))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(
        "\nThe unified row scores the unified network on each expression's test pairs and only that expression's network outputs, the like-for-like comparison with the facelab row. The paired row is, per seed, the per-expression network's MSE minus the unified network's on those pairs, as mean ± 95% interval over seeds; † marks an interval that excludes 0 (negative: the per-expression network is better, positive: the unified one). The seeds vary the networks' initialization and batch order only; the dataset is the same for every seed.\n",
    );
    out
}

pub(super) fn table1_tex(rows: &[Row]) -> String {
    let (mean, ci, umean, uci) = summary(rows);
    let mut out = String::from(
        "\\begin{tabular}{lrrrrrrr}\n\\hline\n & Joy & Sadness & Fear & Anger & Surprise & Disgust & All \\\\\n\\hline\n",
    );
    out.push_str(&format!(
        "Zeng et al. & {} \\\\\n",
        table1::PAPER
            .iter()
            .map(|v| format!("{v:.6}"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str(&format!(
        "facelab & {} \\\\\n",
        mean.iter()
            .zip(&ci)
            .map(|(m, c)| format!("{m:.2e} $\\pm$ {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str(&format!(
        "unified, same outputs & {} & \\\\\n",
        umean
            .iter()
            .zip(&uci)
            .map(|(m, c)| format!("{m:.2e} $\\pm$ {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str(&format!(
        "per-expression $-$ unified (paired) & {} & \\\\\n",
        table1::paired(rows)
            .into_iter()
            .map(|p| paired_cell(p, "$^\\dagger$").replace('±', "$\\pm$"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str("\\hline\n\\end{tabular}\n");
    out
}

pub(super) fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

pub(super) fn table1_figures(dir: &Path, result: &CellResult) -> Result<()> {
    use crate::report::figures::{grouped_bars, log_curves, Series, PALETTE};
    let first_seed = result.curves.first().map(|((s, _), _)| *s).unwrap_or(1);
    let mut series = Vec::new();
    for (i, ((seed, network), c)) in result.curves.iter().enumerate() {
        if *seed != first_seed {
            continue;
        }
        let color = PALETTE[i % PALETTE.len()];
        series.push(Series {
            label: format!("{} test", network.name()),
            values: c.test.clone(),
            color,
            dashed: false,
        });
        if *network == Network::Unified {
            series.push(Series {
                label: "unified train".into(),
                values: c.train.clone(),
                color,
                dashed: true,
            });
        }
    }
    log_curves(
        &dir.join("loss_curves.png"),
        &format!("Training curves (seed {first_seed})"),
        "MSE",
        &series,
    )?;
    let (mean, _, _, _) = summary(&result.rows);
    let cats: Vec<String> = table1::ORDER
        .iter()
        .map(|e| capitalize(e.name()))
        .chain(std::iter::once("All".into()))
        .collect();
    grouped_bars(
        &dir.join("table1_bars.png"),
        "Table 1: test MSE",
        "MSE",
        &cats,
        &[
            ("Zeng et al.".into(), PALETTE[5], table1::PAPER.to_vec()),
            ("facelab (mean over seeds)".into(), PALETTE[1], mean),
        ],
    )
}

/// Bars of MSE_All and the mean per-expression MSE for each cell, labelled by its values.
/// A sweep's swept keys (`a / b`) and each cell's values (`1/2`), from cell names `a=1,b=2`.
pub(super) fn sweep_labels(names: &[&str]) -> (String, Vec<String>) {
    let part = |name: &str, value: bool| -> String {
        name.split(',')
            .map(|kv| {
                kv.split_once('=')
                    .map_or(kv, |(k, v)| if value { v } else { k })
                    .to_string()
            })
            .collect::<Vec<_>>()
            .join(if value { "/" } else { " / " })
    };
    let keys = names.first().map(|n| part(n, false)).unwrap_or_default();
    (keys, names.iter().map(|n| part(n, true)).collect())
}

pub(super) fn sweep_figure(dir: &Path, rows: &[(String, Vec<Row>)]) -> Result<()> {
    use crate::report::figures::{grouped_bars, PALETTE};
    let names: Vec<&str> = rows.iter().map(|(n, _)| n.as_str()).collect();
    let (keys, labels) = sweep_labels(&names);
    let all: Vec<f64> = rows
        .iter()
        .map(|(_, r)| stats::mean(&r.iter().map(|x| x.all).collect::<Vec<_>>()))
        .collect();
    let per: Vec<f64> = rows
        .iter()
        .map(|(_, r)| {
            stats::mean(
                &r.iter()
                    .map(|x| stats::mean(&x.per_expression))
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    grouped_bars(
        &dir.join("sweep.png"),
        &format!("Test MSE by {keys}"),
        "MSE (mean over seeds)",
        &labels,
        &[
            ("unified, MSE_All".into(), PALETTE[0], all),
            ("per-expression networks, mean".into(), PALETTE[1], per),
        ],
    )
}

pub(super) fn sweep_csv(rows: &[(String, Vec<Row>)]) -> String {
    let mut out = String::from("cell,mse_all_mean,mse_all_ci95,mse_per_expression_mean\n");
    for (name, r) in rows {
        let all: Vec<f64> = r.iter().map(|x| x.all).collect();
        let per: Vec<f64> = r.iter().map(|x| stats::mean(&x.per_expression)).collect();
        out.push_str(&format!(
            "\"{name}\",{},{},{}\n",
            fmt(stats::mean(&all)),
            fmt(stats::ci95(&all)),
            fmt(stats::mean(&per))
        ));
    }
    out
}

pub(super) fn sweep_markdown(experiment: &str, rows: &[(String, Vec<Row>)]) -> String {
    let mut out = format!(
        "# {experiment}: Table 1 over a sweep\n\n| cell | MSE_All (unified) | mean of per-expression MSEs |\n|---|---|---|\n"
    );
    for (name, r) in rows {
        let all: Vec<f64> = r.iter().map(|x| x.all).collect();
        let per: Vec<f64> = r.iter().map(|x| stats::mean(&x.per_expression)).collect();
        out.push_str(&format!(
            "| {name} | {:.2e} ± {:.1e} | {:.2e} ± {:.1e} |\n",
            stats::mean(&all),
            stats::ci95(&all),
            stats::mean(&per),
            stats::ci95(&per)
        ));
    }
    out
}
