//! Where facelab's files are: the checkout its data files come from (the face mesh, the
//! expression, FACS, calibration and reach tables, the committed specs and runs), the results
//! folder a run writes, and the real-data folder. One value, [`Layout`], is found once by the
//! command line (or by a test, in the checkout it runs in) and handed down: to a spec when it
//! is loaded, which resolves its data-file keys to typed paths ([`DataFile`]) with it, and to
//! the commands that read data files without a spec.
//!
//! A data file named relative to the checkout is found, in order: as given from the working
//! folder; under the checkout; else in the copy compiled into the binary ([`super::embedded`],
//! written out once to the user's cache folder). So an installed `facelab` runs from any
//! folder, and the binary reads nothing from where it was built.

use std::path::{Path, PathBuf};

use super::calibration::DEFAULT_CALIBRATION;
use super::embedded;
use super::expressions::DEFAULT_EXPRESSIONS;
use super::facs::{DEFAULT_AU_MUSCLES, DEFAULT_EXPRESSION_AUS};
use super::mesh::DEFAULT_MESH;
use super::observer_fit::{DEFAULT_READOUT, DEFAULT_READOUT_INPUTS};
use super::reach::DEFAULT_REACH;

/// Where the real OpenFace files are looked for when a spec or `--data` does not say: beside
/// the checkout (they are never part of it: their licences do not let the project carry them).
pub const REALDATA_FOLDER: &str = "../shared/realdata";

/// Whether `dir` is a facelab checkout (or a copy of its data): it holds `experiments/` and
/// `assets/face/`.
fn is_root(dir: &Path) -> bool {
    dir.join("experiments").is_dir() && dir.join("assets/face").is_dir()
}

/// The first of `start` and its ancestors that is a checkout (`experiments/` and
/// `assets/face/`).
pub fn find_root(start: &Path) -> Option<PathBuf> {
    let start = std::path::absolute(start).ok()?;
    start
        .ancestors()
        .find(|d| is_root(d))
        .map(Path::to_path_buf)
}

/// Where facelab's files are (module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The checkout data files resolve against, if any.
    checkout: Option<PathBuf>,
    /// Whether the working folder is inside that checkout.
    inside: bool,
}

impl Layout {
    /// The layout of a process: the checkout that holds the working folder, else the one that
    /// holds `anchor` (a spec or run folder named on the command line), else none (the
    /// binary's built-in files).
    pub fn find(anchor: Option<&Path>) -> Layout {
        let working = std::env::current_dir().ok().and_then(|d| find_root(&d));
        let inside = working.is_some();
        let checkout = working.or_else(|| anchor.and_then(|a| find_root(a.parent().unwrap_or(a))));
        Layout { checkout, inside }
    }

    /// The layout of the working folder's checkout: what a test or a library caller inside a
    /// checkout uses.
    pub fn here() -> Layout {
        Layout::find(None)
    }

    /// The checkout, if there is one.
    pub fn checkout(&self) -> Option<&Path> {
        self.checkout.as_deref()
    }

    /// A data file or folder of the checkout (`rel` from its root, or absolute): as given if
    /// it exists from the working folder, else under the checkout, else the binary's built-in
    /// copy. When it is nowhere the path is returned as given, and the error that reads it
    /// names it.
    pub fn file(&self, rel: impl AsRef<Path>) -> PathBuf {
        let local = rel.as_ref().to_path_buf();
        if local.exists() || local.is_absolute() {
            return local;
        }
        if let Some(path) = self
            .checkout
            .as_ref()
            .map(|root| root.join(&local))
            .filter(|p| p.exists())
        {
            return path;
        }
        let Some(text) = local.to_str() else {
            return local;
        };
        match embedded::materialize(text) {
            Some(Ok(path)) => path,
            Some(Err(e)) => {
                eprintln!("warning: the built-in copy of {text} could not be written out: {e}");
                local
            }
            None => local,
        }
    }

    /// A data file a spec or a command names, as written and where it was found.
    pub fn data_file(&self, name: &str) -> DataFile {
        DataFile {
            path: self.file(name),
            name: name.to_string(),
        }
    }

    /// The results folder: the default `results` means the checkout's `results/` when the
    /// working folder is inside a checkout (so a run from a subfolder writes where a run from
    /// the root does); anything else is taken as given, relative to the working folder. A
    /// run's published tables and figures go beside it (`paper-tables/`, `figures/`).
    pub fn results(&self, given: PathBuf) -> PathBuf {
        match &self.checkout {
            Some(root) if self.inside && given == Path::new("results") => root.join("results"),
            _ => given,
        }
    }

    /// The real-data folder when nothing names one: `../shared/realdata` of the working
    /// folder, else beside the checkout.
    pub fn realdata(&self) -> PathBuf {
        let local = PathBuf::from(REALDATA_FOLDER);
        match &self.checkout {
            Some(root) if !local.exists() => root.join(REALDATA_FOLDER),
            _ => local,
        }
    }

    /// The face's base mesh.
    pub fn mesh(&self) -> PathBuf {
        self.file(DEFAULT_MESH)
    }

    /// The expression weights.
    pub fn expressions(&self) -> PathBuf {
        self.file(DEFAULT_EXPRESSIONS)
    }

    /// The FACS maps: expression -> AUs, and AU -> muscles.
    pub fn facs(&self) -> (PathBuf, PathBuf) {
        (
            self.file(DEFAULT_EXPRESSION_AUS),
            self.file(DEFAULT_AU_MUSCLES),
        )
    }

    /// The model-anchored AU calibration (the gains).
    pub fn calibration(&self) -> PathBuf {
        self.file(DEFAULT_CALIBRATION)
    }

    /// The readout fitted to OpenFace on real faces.
    pub fn readout(&self) -> PathBuf {
        self.file(DEFAULT_READOUT)
    }

    /// Which inputs each AU's fitted readout may read.
    pub fn readout_inputs(&self) -> PathBuf {
        self.file(DEFAULT_READOUT_INPUTS)
    }

    /// The range-of-motion table.
    pub fn reach(&self) -> PathBuf {
        self.file(DEFAULT_REACH)
    }
}

/// A data file named by a spec key (`observer.calibration = "experiments/au_observer_fit.csv"`),
/// resolved when the spec is loaded: its name as written (what a run's `spec.toml`, its cache
/// keys and its tables record) and the path it was found at (what is read).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DataFile {
    pub name: String,
    pub path: PathBuf,
}

impl std::fmt::Display for DataFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

impl PartialEq<&str> for DataFile {
    fn eq(&self, other: &&str) -> bool {
        self.name == *other
    }
}

/// Recorded by its name: a run's keys do not depend on where the checkout is.
impl serde::Serialize for DataFile {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_data_file_resolves_in_the_checkout_and_records_its_name() {
        let layout = Layout::here();
        let root = layout
            .checkout()
            .expect("the tests run in a checkout")
            .to_path_buf();
        let f = layout.data_file("experiments/expressions.csv");
        assert!(f.path.is_file(), "{}", f.path.display());
        assert_eq!(f.to_string(), "experiments/expressions.csv");
        assert_eq!(
            toml::Value::try_from(&f).unwrap(),
            toml::Value::String("experiments/expressions.csv".into())
        );
        // From a folder that is no checkout, the same layout finds the same file.
        let elsewhere = Layout {
            checkout: Some(root.clone()),
            inside: false,
        };
        assert_eq!(
            std::fs::read(elsewhere.mesh()).unwrap(),
            std::fs::read(root.join(DEFAULT_MESH)).unwrap()
        );
        // Without a checkout: the working folder's copy, else the built-in one (the same bytes).
        let none = Layout {
            checkout: None,
            inside: false,
        };
        let obj = none.file("assets/face/canonical_face.obj");
        assert_eq!(
            std::fs::read(obj).unwrap(),
            std::fs::read(root.join(DEFAULT_MESH)).unwrap()
        );
        // Nowhere: returned as given, for the reader's error to name.
        assert_eq!(
            none.file("experiments/no_such_file.csv"),
            PathBuf::from("experiments/no_such_file.csv")
        );
    }
}
