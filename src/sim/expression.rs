//! The six basic expressions and their muscle weight sets W_e (paper 4.2): the activations of
//! expression e at scale s are a_i = w_i * s. The weights themselves are data
//! (`experiments/expressions.csv`, read by `io::expressions`).

use std::fmt;
use std::str::FromStr;

use super::controls::{Activations, CONTROL_COUNT, JAW_SLIDE, JAW_TWIST};

#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Expression {
    Joy,
    Sadness,
    Anger,
    Fear,
    Disgust,
    Surprise,
}

impl Expression {
    /// In the paper's order.
    pub const ALL: [Expression; 6] = [
        Expression::Joy,
        Expression::Sadness,
        Expression::Anger,
        Expression::Fear,
        Expression::Disgust,
        Expression::Surprise,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Expression::Joy => "joy",
            Expression::Sadness => "sadness",
            Expression::Anger => "anger",
            Expression::Fear => "fear",
            Expression::Disgust => "disgust",
            Expression::Surprise => "surprise",
        }
    }
}

impl fmt::Display for Expression {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[derive(Debug, thiserror::Error, PartialEq)]
#[error("unknown expression `{0}` (expected one of joy, sadness, anger, fear, disgust, surprise)")]
pub struct UnknownExpression(pub String);

impl FromStr for Expression {
    type Err = UnknownExpression;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Expression::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| UnknownExpression(s.to_string()))
    }
}

/// W_e for the six expressions: per expression, a weight in [0, 1] per control (slide and twist
/// stay neutral and carry no weight).
#[derive(Clone, Debug, PartialEq)]
pub struct ExpressionWeights {
    weights: [[f64; CONTROL_COUNT]; 6],
}

impl Default for ExpressionWeights {
    fn default() -> Self {
        ExpressionWeights {
            weights: [[0.0; CONTROL_COUNT]; 6],
        }
    }
}

impl ExpressionWeights {
    pub fn set(&mut self, e: Expression, control: usize, weight: f64) {
        self.weights[e as usize][control] = weight;
    }

    pub fn weights(&self, e: Expression) -> &[f64; CONTROL_COUNT] {
        &self.weights[e as usize]
    }

    /// a = w_e * s (s in [0, 1]); slide and twist neutral.
    pub fn activations(&self, e: Expression, s: f64) -> Activations {
        let mut values = [0.0; CONTROL_COUNT];
        for (v, w) in values.iter_mut().zip(self.weights(e)) {
            *v = (w * s).clamp(0.0, 1.0);
        }
        values[JAW_SLIDE] = 0.5;
        values[JAW_TWIST] = 0.5;
        Activations::from_values(&values).expect("clamped to [0, 1]")
    }
}

impl ExpressionWeights {
    /// A training-style sample (paper 4.2): `w_e * s` with the jaw rotation drawn separately.
    pub fn sample(&self, e: Expression, s: f64, jaw_rotation: f64) -> Activations {
        let mut a = self.activations(e, s);
        a.set_index(super::controls::JAW_ROTATION, jaw_rotation.clamp(0.0, 1.0))
            .expect("clamped");
        a
    }
}
