//! Retrieval for the sampler (after RDM and kNN-Diffusion): a caption index over the icons the
//! embedded prior was trained on, so that some of the K samples start from the icons whose names
//! are nearest to the caption (SDEdit in [`crate::stages::sample::sample_and_rerank`]).
//!
//! The model directory pins the icon sets (`retrieval/packages.json`: npm package, version,
//! licence, tarball sha256). `vectorfusion setup` ([`install`]) fetches each tarball (or takes it
//! from `VF_ICONS_DIR`), checks its sha256, keeps its `icons.json`, names every icon as the
//! training data does ([`names`]) and embeds the unique names with MiniLM (mean-pooled,
//! L2-normalised, as IconClip's text tower) into a cache directory ([`RetrievalLocations`]).
//! [`IconIndex::load`] reads it back; a stale or missing index is a clear error, and the
//! pipeline then samples from noise only.
//!
//! | file | what |
//! |---|---|
//! | [`names`] | captions from icon names (shared with `examples/icon_dataset.rs`) |
//! | [`iconify`] | iconify JSON sets → standalone SVGs → rendered images |
//! | [`index`] | the persisted index, nearest-caption search, icon rendering |
//! | [`install`](mod@install) | pinned packages, fetch + checksum, index build |

pub mod iconify;
pub mod index;
pub mod install;
pub mod names;

pub use index::{Hit, IconIndex, IconRef};
pub use install::{PinnedPackage, RetrievalLocations, install, pinned_packages};

/// Icon sets held out for evaluation: never trained on, never retrieved from.
pub const HELD_OUT_SETS: &[&str] = &["fluent-emoji", "openmoji"];

/// Whether `set` is one of [`HELD_OUT_SETS`] (any `fluent-emoji*` set included).
pub fn is_held_out(set: &str) -> bool {
    HELD_OUT_SETS.iter().any(|h| set.starts_with(h))
}

/// Errors of the retrieval layer.
#[derive(Debug, thiserror::Error)]
pub enum RetrievalError {
    /// No usable index: not installed, stale, or the model pins no icon sets.
    #[error("retrieval index not available: {0} (run `vectorfusion setup`)")]
    Unavailable(String),
    #[error("{path}: {reason}")]
    File { path: String, reason: String },
    #[error("icon set {set}: {reason}")]
    Package { set: String, reason: String },
    #[error("text embedding: {0}")]
    Embed(String),
    /// The text encoder failed while embedding captions.
    #[error("text embedding: {0}")]
    Encoder(#[source] crate::models::bert::BertError),
    #[error("icon {set}:{name}: {reason}")]
    Icon {
        set: String,
        name: String,
        reason: String,
    },
}

impl RetrievalError {
    pub(crate) fn file(path: &std::path::Path, reason: impl std::fmt::Display) -> Self {
        RetrievalError::File {
            path: path.display().to_string(),
            reason: reason.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn held_out_sets_are_recognised() {
        for s in [
            "fluent-emoji",
            "fluent-emoji-flat",
            "fluent-emoji-high-contrast",
            "openmoji",
        ] {
            assert!(super::is_held_out(s), "{s}");
        }
        assert!(!super::is_held_out("twemoji"));
    }
}
