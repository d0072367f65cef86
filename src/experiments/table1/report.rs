//! Table 1 in the registry (its Markdown, LaTeX and figures), and the record every training
//! writes whatever the spec's tables: `table1.csv` and `curves.csv` in the run folder, a
//! sweep's Table 1 summary across its cells.

use crate::experiments::table1;
use crate::experiments::Products;
use crate::io::rows::{self, num, CsvRow};
use crate::learn::Curves;
use crate::report::table::{Table, TableRow};
use crate::run::cell::networks::{Network, Row, ORDER};
use crate::run::cell::{CellRun, Experiment, Networks, Plan, Sweep};
use crate::spec::Spec;
use crate::stats;
use anyhow::Result;
use std::path::Path;
use std::rc::Rc;

/// Table 1: the paper table and figures of the cell's networks (whose record every run that
/// trains writes, `record`).
pub(crate) struct Table1;

impl Experiment for Table1 {
    fn name(&self) -> &'static str {
        "table1"
    }

    fn table(&self) -> Option<crate::spec::Table> {
        Some(crate::spec::Table::Table1)
    }

    /// Its units are the networks', which every plan that trains lists first.
    fn plan(&self, _plan: &mut Plan) -> Result<()> {
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let n = cx.networks()?;
        let md = table1_markdown(&n.rows, cx.spec, n.samples.len());
        cx.table("table1.md", &md)?;
        cx.table("table1.tex", &table1_tex(&n.rows))?;
        if let Some(dir) = cx.figures("table1") {
            table1_figures(&dir, &n.curves, &n.rows)?;
        }
        Ok(())
    }

    fn finish_cell(&self, cx: &mut CellRun) -> Result<()> {
        match cx.trained() {
            Some(n) => record(cx, &n),
            None => Ok(()),
        }
    }

    fn sweep(&self, sweep: &mut Sweep) -> Result<()> {
        sweep_record(sweep)
    }
}

/// A cell's Table 1 rows, kept for the sweep's summary.
pub(crate) struct Table1Rows(Vec<Row>);

/// What every cell that trained writes, whichever tables it has: each seed's held-out test of
/// every network (`table1.csv`), the learning curves, and, for a single-cell spec, the first
/// seed's unified network and the training AUs' statistics (`facelab transfer --model`).
fn record(cx: &mut CellRun, n: &Networks) -> Result<()> {
    cx.output("table1.csv", table1_csv(&n.rows))?;
    cx.output("curves.csv", all_curves_csv(&n.curves))?;
    if cx.publishes() {
        let unified = &n.nets[&(cx.spec.seeds[0], Network::Unified)];
        cx.output("unified.safetensors", unified.to_safetensors()?)?;
        cx.output("training_aus.csv", training_aus_csv(&n.samples))?;
    }
    Products::of(cx).table1 = Some(Rc::new(Table1Rows(n.rows.clone())));
    Ok(())
}

/// A sweep's Table 1 over its cells: `<experiment>.csv`, the summary's first part, a figure.
fn sweep_record(sweep: &mut Sweep) -> Result<()> {
    let rows: Vec<(String, Vec<Row>)> = Products::each(sweep, |p| p.table1.clone())
        .into_iter()
        .map(|(name, r)| (name, r.0.clone()))
        .collect();
    sweep
        .markdown
        .push_str(&sweep_markdown(sweep.experiment, &rows));
    let csv = format!("{}.csv", sweep.experiment);
    sweep.output(&csv, sweep_csv(&rows))?;
    sweep_figure(&sweep.figures(), &rows)
}

/// A line of a run's `curves.csv`: a network of a seed at one epoch.
#[derive(serde::Serialize, serde::Deserialize)]
struct NetworkCurveLine {
    seed: u64,
    network: String,
    epoch: usize,
    #[serde(serialize_with = "num::shortest")]
    train_mse: f64,
    #[serde(serialize_with = "num::shortest")]
    test_mse: f64,
}

impl CsvRow for NetworkCurveLine {}

/// Every network's curves: `seed,network,epoch,train_mse,test_mse`.
fn all_curves_csv(curves: &[((u64, Network), Curves)]) -> String {
    let mut lines = Vec::new();
    for ((seed, network), c) in curves {
        for (i, (&train_mse, &test_mse)) in c.train.iter().zip(&c.test).enumerate() {
            lines.push(NetworkCurveLine {
                seed: *seed,
                network: network.name(),
                epoch: i + 1,
                train_mse,
                test_mse,
            });
        }
    }
    rows::to_csv(&lines)
}

/// A line of `training_aus.csv`: one AU over all training pairs.
#[derive(serde::Serialize, serde::Deserialize)]
struct TrainingAuLine {
    au: String,
    #[serde(serialize_with = "num::shortest")]
    min: f64,
    #[serde(serialize_with = "num::shortest")]
    max: f64,
    #[serde(serialize_with = "num::shortest")]
    mean: f64,
    #[serde(serialize_with = "num::shortest")]
    sd: f64,
}

impl CsvRow for TrainingAuLine {}

/// Per AU: min, max, mean and SD over all training pairs (what Table 2 normalizes onto).
fn training_aus_csv(samples: &[crate::dataset::Sample]) -> String {
    let lines: Vec<TrainingAuLine> = crate::observe::AU_NAMES
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let v: Vec<f64> = samples.iter().map(|s| s.aus[k]).collect();
            let (mean, sd) = stats::mean_sd(&v);
            let (min, max) = stats::min_max(&v);
            TrainingAuLine {
                au: name.to_string(),
                min,
                max,
                mean,
                sd,
            }
        })
        .collect();
    rows::to_csv(&lines)
}

/// A line of `table1.csv`: a seed (or `mean`, `ci95`), the six per-expression networks' test
/// MSE, `all`, and the unified network's MSE per expression.
#[derive(serde::Serialize, serde::Deserialize)]
struct Table1Line {
    seed: String,
    #[serde(serialize_with = "num::sci_each::<6, _>")]
    #[serde(deserialize_with = "num::all::deserialize")]
    values: [f64; 13],
}

impl CsvRow for Table1Line {
    fn header() -> Vec<String> {
        let names = ORDER.iter().map(|e| e.to_string());
        std::iter::once("seed".to_string())
            .chain(names.clone())
            .chain(std::iter::once("all".to_string()))
            .chain(names.map(|n| format!("unified_{n}")))
            .collect()
    }
}

/// `seed,joy,...,disgust,all,unified_joy,...` rows, then `mean` and `ci95`.
fn table1_csv(rows: &[Row]) -> String {
    let flat: Vec<[f64; 13]> = rows
        .iter()
        .map(|r| {
            let mut v = [0.0; 13];
            v[..6].copy_from_slice(&r.per_expression);
            v[6] = r.all;
            v[7..].copy_from_slice(&r.unified_restricted);
            v
        })
        .collect();
    let mut lines: Vec<Table1Line> = rows
        .iter()
        .zip(&flat)
        .map(|(r, v)| Table1Line {
            seed: r.seed.to_string(),
            values: *v,
        })
        .collect();
    let column = |j: usize| flat.iter().map(|v| v[j]).collect::<Vec<_>>();
    lines.push(Table1Line {
        seed: "mean".into(),
        values: std::array::from_fn(|j| stats::mean(&column(j))),
    });
    lines.push(Table1Line {
        seed: "ci95".into(),
        values: std::array::from_fn(|j| stats::ci95(&column(j))),
    });
    rows::to_csv(&lines)
}

fn summary(rows: &[Row]) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
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

fn paired_cell((m, c, excludes_zero): (f64, f64, bool), dagger: &str) -> String {
    format!(
        "{m:+.1e} ± {c:.1e}{}",
        if excludes_zero { dagger } else { "" }
    )
}

fn table1_markdown(rows: &[Row], spec: &Spec, samples: usize) -> String {
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
    out.push_str(&table1_table(rows).markdown());
    out.push_str(
        "\nThe unified row scores the unified network on each expression's test pairs and only that expression's network outputs, the like-for-like comparison with the facelab row. The paired row is, per seed, the per-expression network's MSE minus the unified network's on those pairs, as mean ± 95% interval over seeds; † marks an interval that excludes 0 (negative: the per-expression network is better, positive: the unified one). The seeds vary the networks' initialization and batch order only; the dataset is the same for every seed.\n",
    );
    out
}

/// Table 1 as one table: the paper's row, ours, the ratio, the unified network on the same
/// pairs and outputs, and the paired difference over seeds.
fn table1_table(rows: &[Row]) -> Table {
    let (mean, ci, umean, uci) = summary(rows);
    let header = std::iter::once(String::new())
        .chain(
            ORDER
                .iter()
                .map(|e| format!("MSE_{}", capitalize(e.name()))),
        )
        .chain(std::iter::once("MSE_All".into()))
        .collect();
    let mut t = Table::new(header);
    t.caption = Some("Table 1: per-expression networks vs one unified network (test MSE)".into());
    let row = |label: &str, cells: Vec<String>| {
        TableRow::new(std::iter::once(label.to_string()).chain(cells).collect())
    };
    let interval = |(m, c): (&f64, &f64)| format!("{m:.2e} ± {c:.1e}");
    t.push(row(
        "Zeng et al.",
        table1::PAPER.iter().map(|v| format!("{v:.6}")).collect(),
    ));
    t.push(row("facelab", mean.iter().zip(&ci).map(interval).collect()));
    t.push(row(
        "facelab / paper",
        mean.iter()
            .zip(&table1::PAPER)
            .map(|(m, p)| format!("{:.2e}", m / p))
            .collect(),
    ));
    let unified = umean.iter().zip(&uci).map(interval);
    t.push(row(
        "unified network, same pairs and outputs",
        unified.chain([interval((&mean[6], &ci[6]))]).collect(),
    ));
    let paired = table1::paired(rows)
        .into_iter()
        .map(|p| paired_cell(p, " †"));
    t.push(row(
        "per-expression - unified, paired over seeds",
        paired.chain([String::new()]).collect(),
    ));
    t
}

fn table1_tex(rows: &[Row]) -> String {
    table1_table(rows).latex()
}

fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

fn table1_figures(dir: &Path, curves: &[((u64, Network), Curves)], rows: &[Row]) -> Result<()> {
    use crate::report::figures::{grouped_bars, log_curves, Series, PALETTE};
    let first_seed = curves.first().map(|((s, _), _)| *s).unwrap_or(1);
    let mut series = Vec::new();
    for (i, ((seed, network), c)) in curves.iter().enumerate() {
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
    let (mean, _, _, _) = summary(rows);
    let cats: Vec<String> = ORDER
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
pub(crate) fn sweep_labels(names: &[&str]) -> (String, Vec<String>) {
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

fn sweep_figure(dir: &Path, rows: &[(String, Vec<Row>)]) -> Result<()> {
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

/// A line of a sweep's CSV: a cell and its Table 1 summary over seeds.
#[derive(serde::Serialize, serde::Deserialize)]
struct SweepLine {
    cell: String,
    #[serde(serialize_with = "num::sci::<6, _>")]
    mse_all_mean: f64,
    #[serde(serialize_with = "num::sci::<6, _>")]
    mse_all_ci95: f64,
    #[serde(serialize_with = "num::sci::<6, _>")]
    mse_per_expression_mean: f64,
}

impl CsvRow for SweepLine {
    const QUOTE_TEXT: bool = true;
}

fn sweep_csv(rows: &[(String, Vec<Row>)]) -> String {
    let lines: Vec<SweepLine> = rows
        .iter()
        .map(|(name, r)| {
            let all: Vec<f64> = r.iter().map(|x| x.all).collect();
            let per: Vec<f64> = r.iter().map(|x| stats::mean(&x.per_expression)).collect();
            SweepLine {
                cell: name.clone(),
                mse_all_mean: stats::mean(&all),
                mse_all_ci95: stats::ci95(&all),
                mse_per_expression_mean: stats::mean(&per),
            }
        })
        .collect();
    rows::to_csv(&lines)
}

fn sweep_markdown(experiment: &str, rows: &[(String, Vec<Row>)]) -> String {
    let out = format!("# {experiment}: Table 1 over a sweep\n\n");
    let mut t = Table::labelled(&["cell", "MSE_All (unified)", "mean of per-expression MSEs"]);
    for (name, r) in rows {
        let all: Vec<f64> = r.iter().map(|x| x.all).collect();
        let per: Vec<f64> = r.iter().map(|x| stats::mean(&x.per_expression)).collect();
        t.push(TableRow::new(vec![
            name.clone(),
            format!("{:.2e} ± {:.1e}", stats::mean(&all), stats::ci95(&all)),
            format!("{:.2e} ± {:.1e}", stats::mean(&per), stats::ci95(&per)),
        ]));
    }
    out + &t.markdown()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every committed sweep CSV is written again by `SweepLine` byte for byte (quoted cell
    /// names, six-digit exponents), except that a cell name holding quotes (a string-valued
    /// key, `dataset.family="broad"`) is now escaped as CSV requires: the files written before
    /// left those quotes bare, which no CSV reader reads back as the name.
    #[test]
    fn committed_sweep_csvs_are_written_again_by_their_row_type() {
        let results = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("results");
        let mut seen = 0;
        for experiment in std::fs::read_dir(&results).unwrap() {
            let dir = experiment.unwrap().path();
            let name = dir.file_name().unwrap().to_string_lossy().to_string();
            let csv = dir.join("latest").join(format!("{name}.csv"));
            let Ok(text) = std::fs::read_to_string(&csv) else {
                continue;
            };
            // A sweep's summary (a single-cell experiment may have a file of its name too).
            if text.lines().next() != Some(SweepLine::header().join(",").as_str()) {
                continue;
            }
            for line in text.lines().skip(1) {
                // `"<cell name>",mean,ci95,per_expression_mean`, read by hand: the name may
                // hold bare quotes.
                let mut parts = line.rsplitn(4, ',');
                let mut num = || parts.next().unwrap().parse::<f64>().unwrap();
                let (per, ci, mean) = (num(), num(), num());
                let quoted = parts.next().unwrap();
                let cell = quoted[1..quoted.len() - 1].to_string();
                let row = SweepLine {
                    cell: cell.clone(),
                    mse_all_mean: mean,
                    mse_all_ci95: ci,
                    mse_per_expression_mean: per,
                };
                let written = rows::to_csv(std::slice::from_ref(&row));
                let escaped = format!("\"{}\"", cell.replace('"', "\"\""));
                let expected = line.replacen(quoted, &escaped, 1);
                assert_eq!(
                    written.lines().nth(1),
                    Some(expected.as_str()),
                    "{}",
                    csv.display()
                );
                let back: Vec<SweepLine> = rows::from_csv(&written, "w.csv").unwrap();
                assert_eq!(back[0].cell, cell);
            }
            seen += 1;
        }
        assert!(seen >= 8, "only {seen} committed sweeps");
    }
}
