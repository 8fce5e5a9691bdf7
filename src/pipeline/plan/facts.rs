//! What the executor knows about its model before loading it ([`ModelFacts`]).

use super::EncoderChoice;
use crate::models::stable_diffusion::ModelHints;

/// What the executor knows about its model before loading it.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFacts {
    /// What the model is: the model directory's name, or the test teacher (never a path).
    pub name: String,
    pub hints: ModelHints,
    /// The configured SDS encoder.
    pub encoder_choice: EncoderChoice,
    /// A TAESD encoder was found for this model.
    pub taesd_found: bool,
}

impl ModelFacts {
    /// A model without a directory of its own (the test teacher, a custom executor): the
    /// paper's hints, the VAE, no TAESD.
    pub fn paper(name: impl Into<String>) -> Self {
        ModelFacts {
            name: name.into(),
            hints: ModelHints::default(),
            encoder_choice: EncoderChoice::Vae,
            taesd_found: false,
        }
    }

    /// The SDS encoder a run uses, `prefer_taesd` being its preset's wish.
    pub fn encoder(&self, prefer_taesd: bool) -> EncoderChoice {
        match self.encoder_choice {
            EncoderChoice::Auto if prefer_taesd && self.taesd_found => EncoderChoice::Taesd,
            EncoderChoice::Auto => EncoderChoice::Vae,
            fixed => fixed,
        }
    }
}
