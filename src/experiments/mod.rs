//! The registered experiments, one folder or file each with its model, stages and report:
//! the tables and figures a spec's `tables` list asks for. The run machinery (`crate::run`)
//! runs them through [`REGISTRY`] and names none of them.

pub mod headpose;
pub mod inversion;
pub mod photos;
pub mod pose_transfer;
pub mod realfaces;
pub mod table1;
pub mod table2;

use std::rc::Rc;

use crate::run::cell::{CellRun, Experiment, Registry, Sweep};

/// Every experiment a run can hold, in the order a cell runs them: an experiment comes after
/// those whose products it reads (the inversion and the pose transfer read Table 2's cohorts,
/// the pose transfer the head-neck experiment's voluntary network). A new experiment is a
/// new file and a line here.
const EXPERIMENTS: &[&dyn Experiment] = &[
    &headpose::Headpose,
    &table1::Table1,
    &table2::Table2,
    &inversion::Inversion,
    &pose_transfer::PoseTransfer,
    &realfaces::Realfaces,
    &photos::Photos,
];

/// The registry a run is handed ([`crate::run::RunOptions::registry`]).
pub const REGISTRY: Registry = Registry(EXPERIMENTS, || Box::<Products>::default());

/// What the experiments of one cell hand each other and the sweep's summary, each set by
/// the experiment that makes it.
#[derive(Default)]
pub(crate) struct Products {
    /// Table 1's rows.
    pub(crate) table1: Option<Rc<table1::Table1Rows>>,
    /// Table 2's cohorts, transfers and rows: the inversion table and the pose transfer run on
    /// them.
    pub(crate) table2: Option<Rc<table2::Table2Result>>,
    /// The head-neck experiment's voluntary network: the pose transfer drives the neck with it.
    pub(crate) voluntary: Option<Rc<headpose::VoluntaryWeights>>,
    /// The real-faces table's rows.
    pub(crate) realfaces: Option<Rc<realfaces::RealfacesRows>>,
}

impl Products {
    /// A cell's products.
    pub(crate) fn of<'c>(cx: &'c mut CellRun) -> &'c mut Products {
        cx.products
            .downcast_mut()
            .expect("a cell's products are the registry's")
    }

    /// The cells of a sweep whose products hold what `pick` takes, with their names.
    pub(crate) fn each<T>(
        sweep: &Sweep,
        pick: impl Fn(&Products) -> Option<Rc<T>>,
    ) -> Vec<(String, Rc<T>)> {
        sweep
            .products::<Products>()
            .into_iter()
            .filter_map(|(name, p)| Some((name.to_string(), pick(p)?)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A table a spec may list runs: every name `spec` accepts is one experiment's.
    #[test]
    fn every_table_a_spec_accepts_is_one_registered_experiment() {
        for table in crate::spec::Table::ALL {
            let n = EXPERIMENTS
                .iter()
                .filter(|e| e.table() == Some(table))
                .count();
            assert_eq!(n, 1, "{table:?}: {n} experiments");
            let e = EXPERIMENTS
                .iter()
                .find(|e| e.table() == Some(table))
                .unwrap();
            assert_eq!(
                e.name(),
                table.name(),
                "an experiment is named after its table"
            );
        }
        // Each experiment comes after every experiment whose table's products it reads.
        for (i, e) in EXPERIMENTS.iter().enumerate() {
            for t in e.reads() {
                let at = EXPERIMENTS
                    .iter()
                    .position(|x| x.table() == Some(t))
                    .unwrap();
                assert!(at < i, "{} reads {t:?}, made after it", e.name());
            }
        }
        let mut names: Vec<&str> = EXPERIMENTS.iter().map(|e| e.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(
            names.len(),
            EXPERIMENTS.len(),
            "two experiments share a name"
        );
    }
}
