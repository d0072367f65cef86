//! How a transfer's frames become activations: the network, the landmark fit or the AU fit,
//! and which one `facelab transfer` takes for an input when none is asked for.

use std::path::Path;

use anyhow::Result;

/// How a picture's expression becomes activations.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TransferMethod {
    /// The run's unified network on the AUs facelab's observer reads (Zeng et al.'s path).
    Network,
    /// The landmark-space fit (Choe et al.'s eq. 10 with the box, through the linear basis):
    /// the activations that move the model's 68 landmarks as the person's moved from the
    /// neutral face. The default for pictures: on the committed real pictures it keeps more
    /// of what MediaPipe sees and adds nothing it does not (`paper-tables/photos.md`). An
    /// OpenFace file takes it with its 3D landmarks (neutral: the per-landmark median of its
    /// rows); there it is not better than the network on the whole, so it is not the default.
    #[default]
    Landmarks,
    /// The AU-space fit (the inversion table's `aus_refined` with a prior toward rest): the
    /// activations whose face facelab's observer reads as the input's AUs, through the
    /// linear basis over the box, corrected through the nonlinear face. An AU beyond the
    /// face's reach takes its muscles to their bound, where the network extrapolates.
    Aus,
}

impl TransferMethod {
    /// The method `facelab transfer` uses for `input` when none is asked for: the AU fit for
    /// an OpenFace file, the landmark fit for pictures.
    pub fn for_input(input: &Path, asked: Option<TransferMethod>) -> Result<TransferMethod> {
        use crate::transfer::pictures::{input_kind, InputKind};
        Ok(match asked {
            Some(m) => m,
            None if input_kind(input)? == InputKind::OpenFace => TransferMethod::Aus,
            None => TransferMethod::Landmarks,
        })
    }

    /// What the method does, for a user.
    pub fn describe(self) -> &'static str {
        match self {
            TransferMethod::Network => "the run's unified network on the AUs",
            TransferMethod::Landmarks => "the landmark-space fit, corrected through the face",
            TransferMethod::Aus => "the AU-space fit, corrected through the face",
        }
    }

    /// Its `--method` value.
    pub fn name(self) -> &'static str {
        match self {
            TransferMethod::Network => "network",
            TransferMethod::Landmarks => "landmarks",
            TransferMethod::Aus => "aus",
        }
    }

    pub fn parse(s: &str) -> Option<TransferMethod> {
        [
            TransferMethod::Network,
            TransferMethod::Landmarks,
            TransferMethod::Aus,
        ]
        .into_iter()
        .find(|m| m.name() == s)
    }
}
