//! The persisted caption index: unique icon captions with their MiniLM embeddings, the icons
//! named by each, and the icon sets they come from.
//!
//! On disk (a directory written by [`IconIndex::save`]):
//! - `index.json`: `{"version", "packages_sha256", "dim", "packages": [PinnedPackage],
//!   "captions": [..], "icons": [[package, name, caption], ..]}`
//! - `embeddings.f32`: little-endian f32 `[captions, dim]`, each row L2-normalised
//! - `sets/<set>-<version>.json`: each package's iconify `icons.json`

use super::iconify;
use super::install::PinnedPackage;
use super::{RetrievalError, is_held_out};
use crate::image::Image;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Format version of `index.json`.
pub const INDEX_VERSION: u32 = 1;

/// One icon the sampler started from: enough for a designer to find it and its licence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IconRef {
    /// The iconify set (`twemoji`), its npm version and SPDX licence.
    pub set: String,
    pub version: String,
    pub license: String,
    /// The icon's name in the set, and the caption derived from it.
    pub name: String,
    pub caption: String,
}

/// A retrieved icon and the cosine similarity of its caption to the query.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hit {
    #[serde(flatten)]
    pub icon: IconRef,
    pub similarity: f32,
}

#[derive(Clone, Serialize, Deserialize)]
struct IndexFile {
    version: u32,
    packages_sha256: String,
    dim: usize,
    packages: Vec<PinnedPackage>,
    captions: Vec<String>,
    /// `(package index, icon name, caption index)`.
    icons: Vec<(usize, String, usize)>,
}

/// The caption index.
///
/// Invariants (checked by [`IconIndex::new`] and [`IconIndex::load`]): `embeddings.len() ==
/// captions.len() * dim`, every icon's package and caption index is in range, no package is a
/// held-out set, and `by_caption[c]` lists the icons named `captions[c]`.
#[derive(Debug, Clone)]
pub struct IconIndex {
    dir: PathBuf,
    file: IndexFile,
    embeddings: Vec<f32>,
    by_caption: Vec<Vec<usize>>,
}

impl std::fmt::Debug for IndexFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IndexFile")
            .field("captions", &self.captions.len())
            .field("icons", &self.icons.len())
            .finish_non_exhaustive()
    }
}

impl IconIndex {
    /// Builds an index in memory; `dir` is where [`IconIndex::save`] writes it and where the
    /// icon sets are read from (`sets/`).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        dir: PathBuf,
        packages_sha256: String,
        packages: Vec<PinnedPackage>,
        captions: Vec<String>,
        icons: Vec<(usize, String, usize)>,
        dim: usize,
        embeddings: Vec<f32>,
    ) -> Result<Self, RetrievalError> {
        let file = IndexFile {
            version: INDEX_VERSION,
            packages_sha256,
            dim,
            packages,
            captions,
            icons,
        };
        Self::checked(dir, file, embeddings)
    }

    fn checked(
        dir: PathBuf,
        file: IndexFile,
        embeddings: Vec<f32>,
    ) -> Result<Self, RetrievalError> {
        let bad = |r: String| RetrievalError::file(&dir.join("index.json"), r);
        if file.version != INDEX_VERSION {
            return Err(bad(format!(
                "index version {} (this build reads {INDEX_VERSION})",
                file.version
            )));
        }
        if file.dim == 0 || embeddings.len() != file.captions.len() * file.dim {
            return Err(bad(format!(
                "{} embedding values for {} captions of dimension {}",
                embeddings.len(),
                file.captions.len(),
                file.dim
            )));
        }
        if let Some(p) = file.packages.iter().find(|p| is_held_out(&p.set)) {
            return Err(bad(format!("{} is held out for evaluation", p.set)));
        }
        let mut by_caption = vec![Vec::new(); file.captions.len()];
        for (i, (p, name, c)) in file.icons.iter().enumerate() {
            if *p >= file.packages.len() || *c >= file.captions.len() {
                return Err(bad(format!("icon {name}: package or caption out of range")));
            }
            by_caption[*c].push(i);
        }
        Ok(IconIndex {
            dir,
            file,
            embeddings,
            by_caption,
        })
    }

    /// Reads an index written by [`IconIndex::save`]; `packages_sha256` must match the model's
    /// pinned packages (else the index is stale).
    pub fn load(dir: &Path, packages_sha256: &str) -> Result<Self, RetrievalError> {
        let path = dir.join("index.json");
        let text = std::fs::read_to_string(&path)
            .map_err(|e| RetrievalError::Unavailable(format!("{}: {e}", path.display())))?;
        let file: IndexFile =
            serde_json::from_str(&text).map_err(|e| RetrievalError::file(&path, e))?;
        if file.packages_sha256 != packages_sha256 {
            return Err(RetrievalError::Unavailable(format!(
                "{} was built for other icon sets than the model pins",
                path.display()
            )));
        }
        let epath = dir.join("embeddings.f32");
        let bytes = std::fs::read(&epath).map_err(|e| RetrievalError::file(&epath, e))?;
        if bytes.len() % 4 != 0 {
            return Err(RetrievalError::file(
                &epath,
                "length is not a multiple of 4",
            ));
        }
        let embeddings = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Self::checked(dir.to_path_buf(), file, embeddings)
    }

    /// Writes `index.json` and `embeddings.f32` into the index directory.
    pub fn save(&self) -> Result<(), RetrievalError> {
        std::fs::create_dir_all(&self.dir).map_err(|e| RetrievalError::file(&self.dir, e))?;
        let bytes: Vec<u8> = self
            .embeddings
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let epath = self.dir.join("embeddings.f32");
        std::fs::write(&epath, bytes).map_err(|e| RetrievalError::file(&epath, e))?;
        let path = self.dir.join("index.json");
        let text = serde_json::to_string(&self.file).map_err(|e| RetrievalError::file(&path, e))?;
        // index.json last: its presence marks a complete index
        std::fs::write(&path, text).map_err(|e| RetrievalError::file(&path, e))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }
    pub fn dim(&self) -> usize {
        self.file.dim
    }
    pub fn captions(&self) -> &[String] {
        &self.file.captions
    }
    pub fn icon_count(&self) -> usize {
        self.file.icons.len()
    }

    /// Leaves the icons of `sets` out of every search (their captions stay, drawn by the other
    /// sets; a caption left without icons is never a hit). Other names are ignored.
    pub fn exclude_sets(&mut self, sets: &[String]) {
        let out: Vec<bool> = self
            .file
            .packages
            .iter()
            .map(|p| sets.contains(&p.set))
            .collect();
        let icons = &self.file.icons;
        for list in &mut self.by_caption {
            list.retain(|&i| !out[icons[i].0]);
        }
    }

    fn icon_ref(&self, i: usize) -> IconRef {
        let (p, name, c) = &self.file.icons[i];
        let pkg = &self.file.packages[*p];
        IconRef {
            set: pkg.set.clone(),
            version: pkg.version.clone(),
            license: pkg.license.clone(),
            name: name.clone(),
            caption: self.file.captions[*c].clone(),
        }
    }

    /// Up to `n` icons whose captions are nearest (cosine) to `query` (an L2-normalised
    /// embedding of the index's dimension), best first: at most `per_caption` icons of each
    /// caption, chosen from its icons starting at an offset given by `seed` (so another seed
    /// retrieves another drawing of the same subject).
    pub fn nearest(
        &self,
        query: &[f32],
        n: usize,
        per_caption: usize,
        seed: u64,
    ) -> Result<Vec<Hit>, RetrievalError> {
        let d = self.file.dim;
        if query.len() != d {
            return Err(RetrievalError::Embed(format!(
                "query has {} values, the index {d}",
                query.len()
            )));
        }
        let mut sims: Vec<(usize, f32)> = self
            .embeddings
            .chunks_exact(d)
            .enumerate()
            .filter(|(c, _)| !self.by_caption[*c].is_empty())
            .map(|(c, e)| (c, e.iter().zip(query).map(|(a, b)| a * b).sum::<f32>()))
            .filter(|(_, s)| s.is_finite())
            .collect();
        sims.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let mut out = Vec::with_capacity(n);
        for (c, sim) in sims {
            if out.len() >= n {
                break;
            }
            let icons = &self.by_caption[c];
            let start = (seed % icons.len() as u64) as usize;
            for k in 0..per_caption.max(1).min(icons.len()) {
                if out.len() >= n {
                    break;
                }
                out.push(Hit {
                    icon: self.icon_ref(icons[(start + k) % icons.len()]),
                    similarity: sim,
                });
            }
        }
        Ok(out)
    }

    /// Renders a retrieved icon at `size` px, opaque over white.
    pub fn render(&self, icon: &IconRef, size: u32) -> Result<Image, RetrievalError> {
        let err = |reason: String| RetrievalError::Icon {
            set: icon.set.clone(),
            name: icon.name.clone(),
            reason,
        };
        let path = set_path(&self.dir, &icon.set, &icon.version);
        let text = std::fs::read_to_string(&path).map_err(|e| RetrievalError::file(&path, e))?;
        let svg = iconify::icons(&text)
            .map_err(|e| err(e.to_string()))?
            .into_iter()
            .find(|i| i.name == icon.name)
            .ok_or_else(|| err("not in its set".into()))?;
        iconify::render_image(&svg.svg, size).map_err(|e| err(e.to_string()))
    }
}

/// Where an index keeps the `icons.json` of a package.
pub fn set_path(dir: &Path, set: &str, version: &str) -> PathBuf {
    dir.join("sets").join(format!("{set}-{version}.json"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pkg(set: &str) -> PinnedPackage {
        PinnedPackage {
            set: set.into(),
            version: "1.0.0".into(),
            license: "MIT".into(),
            sha256: "0".repeat(64),
            tarball: String::new(),
        }
    }

    fn toy(dir: PathBuf) -> IconIndex {
        // captions on three axes; "red heart" has two icons, one in each set
        let captions = vec!["red heart".into(), "sun".into(), "car".into()];
        let emb = vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let icons = vec![
            (0, "red-heart".into(), 0),
            (1, "heart-red".into(), 0),
            (0, "sun".into(), 1),
            (1, "car".into(), 2),
        ];
        IconIndex::new(
            dir,
            "abc".into(),
            vec![pkg("a"), pkg("b")],
            captions,
            icons,
            3,
            emb,
        )
        .unwrap()
    }

    #[test]
    fn nearest_ranks_captions_and_rotates_icons_by_seed() {
        let idx = toy(PathBuf::from("/nonexistent"));
        let q = [0.8f32, 0.6, 0.0];
        let hits = idx.nearest(&q, 3, 1, 0).unwrap();
        let names: Vec<&str> = hits.iter().map(|h| h.icon.name.as_str()).collect();
        assert_eq!(names, ["red-heart", "sun", "car"]);
        assert!((hits[0].similarity - 0.8).abs() < 1e-6);
        assert_eq!(hits[0].icon.caption, "red heart");
        assert_eq!(hits[0].icon.set, "a");
        // another seed: the other drawing of the same caption
        assert_eq!(idx.nearest(&q, 1, 1, 1).unwrap()[0].icon.name, "heart-red");
        // two per caption
        let two = idx.nearest(&q, 2, 2, 0).unwrap();
        assert_eq!(two[0].icon.caption, two[1].icon.caption);
        assert!(idx.nearest(&[1.0, 0.0], 1, 1, 0).is_err());
    }

    #[test]
    fn an_excluded_set_is_never_retrieved() {
        let mut idx = toy(PathBuf::from("/nonexistent"));
        idx.exclude_sets(&["a".into(), "no-such-set".into()]);
        let q = [0.8f32, 0.6, 0.0];
        // "red heart" keeps set b's drawing for every seed; "sun" (only in a) is never a hit
        for seed in 0..3 {
            let hits = idx.nearest(&q, 3, 2, seed).unwrap();
            let names: Vec<&str> = hits.iter().map(|h| h.icon.name.as_str()).collect();
            assert_eq!(names, ["heart-red", "car"]);
            assert!(hits.iter().all(|h| h.icon.set == "b"));
        }
    }

    #[test]
    fn save_load_round_trip_and_staleness() {
        let dir = std::env::temp_dir().join(format!("vf-index-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let idx = toy(dir.clone());
        idx.save().unwrap();
        let back = IconIndex::load(&dir, "abc").unwrap();
        assert_eq!(back.captions(), idx.captions());
        assert_eq!(back.icon_count(), 4);
        assert_eq!(back.embeddings, idx.embeddings);
        assert!(matches!(
            IconIndex::load(&dir, "other"),
            Err(RetrievalError::Unavailable(_))
        ));
        std::fs::write(dir.join("embeddings.f32"), [0u8; 8]).unwrap();
        assert!(IconIndex::load(&dir, "abc").is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn held_out_sets_and_bad_shapes_are_refused() {
        let d = PathBuf::from("/x");
        let held = IconIndex::new(
            d.clone(),
            "s".into(),
            vec![pkg("openmoji")],
            vec!["a".into()],
            vec![(0, "a".into(), 0)],
            1,
            vec![1.0],
        );
        assert!(held.is_err());
        let short = IconIndex::new(
            d,
            "s".into(),
            vec![pkg("a")],
            vec!["a".into()],
            vec![],
            2,
            vec![1.0],
        );
        assert!(short.is_err());
    }
}
