//! Installing the retrieval index: the model's pinned icon sets (`retrieval/packages.json`),
//! fetched from the npm registry (or `VF_ICONS_DIR`), sha256-checked, named and embedded.

use super::index::{IconIndex, set_path};
use super::{RetrievalError, iconify, is_held_out, names};
use crate::models::bert::BertError;
use crate::models::bert::weights::{env_path, sha256_hex};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashSet};
use std::io::Read;
use std::path::{Path, PathBuf};

/// Environment variable naming a directory of the pinned tarballs (`iconify-json-SET-VER.tgz`,
/// as `npm pack` names them, or `SET-VER.tgz`), used before any download.
pub const ENV_ICONS_DIR: &str = "VF_ICONS_DIR";
/// Environment variable naming the index directory (overrides the cache location).
pub const ENV_INDEX_DIR: &str = "VF_RETRIEVAL_DIR";
/// Environment variable listing icon sets (comma-separated) that retrieval passes over: the
/// validation protocol's judge set (`docs/embedded/TRAINING.md`, "Validation").
pub const ENV_EXCLUDE_SETS: &str = "VF_RETRIEVAL_EXCLUDE_SETS";
/// The largest tarball accepted (the biggest pinned set is under 4 MB).
const MAX_TARBALL_BYTES: u64 = 64 << 20;
/// The largest `icons.json` accepted inside a tarball.
const MAX_ICONS_JSON_BYTES: u64 = 128 << 20;
/// MiniLM positions for caption embeddings (icon names are short; longer ones are truncated).
pub const CAPTION_TOKENS: usize = 32;

/// One pinned icon-set package.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PinnedPackage {
    /// The iconify set name (`@iconify-json/<set>`).
    pub set: String,
    pub version: String,
    /// SPDX licence of the set's icons.
    pub license: String,
    /// Lower-case hex sha256 of the npm tarball.
    pub sha256: String,
    /// Where the tarball is fetched from.
    pub tarball: String,
}

#[derive(Deserialize)]
struct PackagesFile {
    packages: Vec<PinnedPackage>,
}

/// The packages `model_dir/retrieval/packages.json` pins and the sha256 of that file (which
/// names the index built from them); `Ok(None)` when the model pins none.
pub fn pinned_packages(
    model_dir: &Path,
) -> Result<Option<(Vec<PinnedPackage>, String)>, RetrievalError> {
    let path = model_dir.join("retrieval").join("packages.json");
    if !path.is_file() {
        return Ok(None);
    }
    let bytes = std::fs::read(&path).map_err(|e| RetrievalError::file(&path, e))?;
    let f: PackagesFile =
        serde_json::from_slice(&bytes).map_err(|e| RetrievalError::file(&path, e))?;
    for p in &f.packages {
        if is_held_out(&p.set) {
            return Err(RetrievalError::file(
                &path,
                format!(
                    "{} is held out for evaluation and must not be retrieved from",
                    p.set
                ),
            ));
        }
        let ok = |s: &str| {
            !s.is_empty()
                && s.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-._".contains(c))
        };
        if !ok(&p.set) || !ok(&p.version) || p.sha256.len() != 64 {
            return Err(RetrievalError::file(
                &path,
                format!("bad entry for {:?}", p.set),
            ));
        }
    }
    Ok(Some((f.packages, sha256_hex(&bytes))))
}

/// Where indexes live: `VF_RETRIEVAL_DIR`, else `<cache>/vectorfusion/retrieval-<sha8>` (the
/// first 8 hex digits of the pinned `packages.json`), plus `VF_ICONS_DIR`, `VF_OFFLINE` and the
/// sets `VF_RETRIEVAL_EXCLUDE_SETS` leaves out of a loaded index.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RetrievalLocations {
    pub index_dir: Option<PathBuf>,
    pub cache: Option<PathBuf>,
    pub icons_dir: Option<PathBuf>,
    pub offline: bool,
    /// Icon sets [`RetrievalLocations::load`] leaves out (their icons are never retrieved).
    pub exclude_sets: Vec<String>,
}

impl RetrievalLocations {
    pub fn from_env() -> Self {
        let minilm = crate::models::bert::MiniLmLocations::from_env();
        Self {
            index_dir: env_path(ENV_INDEX_DIR),
            cache: minilm
                .cache
                .as_ref()
                .and_then(|c| c.parent().map(Path::to_path_buf)),
            icons_dir: env_path(ENV_ICONS_DIR),
            offline: minilm.offline,
            exclude_sets: std::env::var(ENV_EXCLUDE_SETS)
                .map(|v| comma_list(&v))
                .unwrap_or_default(),
        }
    }

    /// The index directory for packages whose `packages.json` has sha256 `sha`.
    pub fn dir_for(&self, sha: &str) -> Result<PathBuf, RetrievalError> {
        if let Some(d) = &self.index_dir {
            return Ok(d.clone());
        }
        let short = sha.get(..8).unwrap_or(sha);
        self.cache
            .as_ref()
            .map(|c| c.join(format!("retrieval-{short}")))
            .ok_or_else(|| {
                RetrievalError::Unavailable(
                    "no cache directory (set XDG_CACHE_HOME or HOME)".into(),
                )
            })
    }

    /// The installed index of `model_dir`'s pinned packages, without [`Self::exclude_sets`];
    /// `Ok(None)` when it pins none.
    pub fn load(&self, model_dir: &Path) -> Result<Option<IconIndex>, RetrievalError> {
        let Some((_, sha)) = pinned_packages(model_dir)? else {
            return Ok(None);
        };
        let mut index = IconIndex::load(&self.dir_for(&sha)?, &sha)?;
        index.exclude_sets(&self.exclude_sets);
        Ok(Some(index))
    }
}

/// The names of a comma-separated list (`"noto, noto-v1"`), trimmed, blanks dropped.
pub fn comma_list(v: &str) -> Vec<String> {
    v.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(String::from)
        .collect()
}

/// Why an npm tarball holds no readable `package/icons.json`.
#[derive(Debug, thiserror::Error)]
pub enum TarballError {
    #[error("not a tar.gz: {0}")]
    NotTarGz(#[source] std::io::Error),
    #[error("bad tar entry: {0}")]
    Entry(#[source] std::io::Error),
    #[error("package/icons.json: {0}")]
    IconsJson(#[source] std::io::Error),
    #[error("no package/icons.json in the tarball")]
    NoIconsJson,
}

/// `package/icons.json` of an npm tarball (gzip + tar).
pub fn icons_json_from_tgz(bytes: &[u8]) -> Result<String, TarballError> {
    let mut archive = tar::Archive::new(flate2::read::GzDecoder::new(bytes));
    for entry in archive.entries().map_err(TarballError::NotTarGz)? {
        let mut entry = entry.map_err(TarballError::Entry)?;
        let is_icons = entry
            .path()
            .map(|p| p == Path::new("package/icons.json"))
            .unwrap_or(false);
        if is_icons {
            let mut text = String::new();
            (&mut entry)
                .take(MAX_ICONS_JSON_BYTES)
                .read_to_string(&mut text)
                .map_err(TarballError::IconsJson)?;
            return Ok(text);
        }
    }
    Err(TarballError::NoIconsJson)
}

/// The tarball of `p`: from `VF_ICONS_DIR` when it is there, else downloaded (when allowed);
/// always checked against the pinned sha256.
fn fetch_tarball(
    p: &PinnedPackage,
    loc: &RetrievalLocations,
    allow_download: bool,
) -> Result<Vec<u8>, RetrievalError> {
    let err = |reason: String| RetrievalError::Package {
        set: p.set.clone(),
        reason,
    };
    let local = loc.icons_dir.as_ref().and_then(|d| {
        [
            format!("iconify-json-{}-{}.tgz", p.set, p.version),
            format!("{}-{}.tgz", p.set, p.version),
        ]
        .into_iter()
        .map(|n| d.join(n))
        .find(|f| f.is_file())
    });
    let bytes = match local {
        Some(f) => std::fs::read(&f).map_err(|e| RetrievalError::file(&f, e))?,
        None if !allow_download || loc.offline => {
            return Err(RetrievalError::Unavailable(format!(
                "icon set {} {} is not installed and downloads are off",
                p.set, p.version
            )));
        }
        None => {
            crate::fetch::download(&p.tarball, MAX_TARBALL_BYTES).map_err(|e| err(e.to_string()))?
        }
    };
    let got = sha256_hex(&bytes);
    if !got.eq_ignore_ascii_case(&p.sha256) {
        return Err(err(format!(
            "sha256 {got} does not match the pinned {} ({} bytes)",
            p.sha256,
            bytes.len()
        )));
    }
    Ok(bytes)
}

/// Embeds captions: L2-normalised vectors, one per caption, all of one dimension.
pub type Embedder<'a> = dyn FnMut(&[&str]) -> Result<Vec<Vec<f32>>, BertError> + 'a;

/// Installs (or finds) the index of `model_dir`'s pinned icon sets. `vocab` is the MiniLM
/// WordPiece vocabulary text (to split names without separators, as the training data does);
/// `embed` embeds captions. Fast when the index is already there.
pub fn install(
    model_dir: &Path,
    loc: &RetrievalLocations,
    allow_download: bool,
    vocab: &str,
    embed: &mut Embedder,
) -> Result<IconIndex, RetrievalError> {
    let Some((packages, sha)) = pinned_packages(model_dir)? else {
        return Err(RetrievalError::Unavailable(format!(
            "{} pins no icon sets (no retrieval/packages.json)",
            model_dir.display()
        )));
    };
    let dir = loc.dir_for(&sha)?;
    if let Ok(idx) = IconIndex::load(&dir, &sha) {
        return Ok(idx);
    }
    let vocab = names::vocab_words(vocab);
    let mut captions: BTreeMap<String, usize> = BTreeMap::new();
    let mut icons_raw: Vec<(usize, String, String)> = Vec::new();
    for (pi, p) in packages.iter().enumerate() {
        let text = set_text(p, &dir, loc, allow_download)?;
        let icons = iconify::icons(&text).map_err(|e| RetrievalError::Package {
            set: p.set.clone(),
            reason: e.to_string(),
        })?;
        let all: HashSet<&str> = icons.iter().map(|i| i.name.as_str()).collect();
        let seg = Some(&vocab).filter(|_| names::needs_segmentation(all.iter().copied()));
        for icon in &icons {
            let cap = names::caption(&icon.name, &all, seg);
            if cap.is_empty() {
                continue;
            }
            captions.entry(cap.clone()).or_insert(0);
            icons_raw.push((pi, icon.name.clone(), cap));
        }
    }
    // Captions in sorted order (each caption's number is its place in it).
    let list: Vec<String> = captions.keys().cloned().collect();
    for (i, c) in list.iter().enumerate() {
        captions.insert(c.clone(), i);
    }
    let (dim, embeddings) = embed_captions(&list, embed)?;
    let icons = icons_raw
        .into_iter()
        .map(|(p, name, cap)| (p, name, captions[&cap]))
        .collect();
    let idx = IconIndex::new(dir, sha, packages, list, icons, dim, embeddings)?;
    idx.save()?;
    Ok(idx)
}

/// The `icons.json` of `p`: kept in the index directory `dir`, else taken from its tarball
/// (and kept).
fn set_text(
    p: &PinnedPackage,
    dir: &Path,
    loc: &RetrievalLocations,
    allow_download: bool,
) -> Result<String, RetrievalError> {
    let path = set_path(dir, &p.set, &p.version);
    if let Ok(t) = std::fs::read_to_string(&path) {
        return Ok(t);
    }
    let bytes = fetch_tarball(p, loc, allow_download)?;
    let t = icons_json_from_tgz(&bytes).map_err(|e| RetrievalError::Package {
        set: p.set.clone(),
        reason: e.to_string(),
    })?;
    let parent = path.parent().unwrap_or(dir);
    std::fs::create_dir_all(parent).map_err(|e| RetrievalError::file(parent, e))?;
    std::fs::write(&path, &t).map_err(|e| RetrievalError::file(&path, e))?;
    Ok(t)
}

/// The embeddings of `list` (row `i` of caption `i`), embedded in batches of similar length
/// (cheaper to pad), and their dimension. Every embedding must be finite and of one size.
fn embed_captions(
    list: &[String],
    embed: &mut Embedder,
) -> Result<(usize, Vec<f32>), RetrievalError> {
    let mut order: Vec<usize> = (0..list.len()).collect();
    order.sort_by_key(|&i| (list[i].len(), i));
    let mut rows: Vec<Vec<f32>> = vec![Vec::new(); list.len()];
    let mut dim = 0usize;
    for chunk in order.chunks(64) {
        let refs: Vec<&str> = chunk.iter().map(|&i| list[i].as_str()).collect();
        let vecs = embed(&refs).map_err(RetrievalError::Encoder)?;
        if vecs.len() != chunk.len() {
            return Err(RetrievalError::Embed(format!(
                "{} embeddings for {} captions",
                vecs.len(),
                chunk.len()
            )));
        }
        for (&i, v) in chunk.iter().zip(vecs) {
            if dim == 0 {
                dim = v.len();
            }
            if v.len() != dim || v.iter().any(|x| !x.is_finite()) {
                return Err(RetrievalError::Embed(
                    "embeddings differ in size or are not finite".into(),
                ));
            }
            rows[i] = v;
        }
    }
    Ok((dim, rows.concat()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tarball with `package/icons.json` (and another file before it).
    fn tgz(icons_json: &str) -> Vec<u8> {
        let mut b = tar::Builder::new(flate2::write::GzEncoder::new(
            Vec::new(),
            flate2::Compression::fast(),
        ));
        for (name, body) in [
            ("package/package.json", "{}"),
            ("package/icons.json", icons_json),
        ] {
            let mut h = tar::Header::new_gnu();
            h.set_size(body.len() as u64);
            h.set_mode(0o644);
            h.set_cksum();
            b.append_data(&mut h, name, body.as_bytes()).unwrap();
        }
        b.into_inner().unwrap().finish().unwrap()
    }

    const SET: &str = r##"{"prefix":"t","width":16,"height":16,"icons":{
        "red-heart":{"body":"<circle cx=\"8\" cy=\"8\" r=\"6\" fill=\"#e00\"/>"},
        "red-heart-2":{"body":"<rect x=\"2\" y=\"2\" width=\"12\" height=\"12\" fill=\"#e00\"/>"},
        "sun":{"body":"<circle cx=\"8\" cy=\"8\" r=\"7\" fill=\"#fd0\"/>"}}}"##;

    /// A deterministic toy embedder: one axis per known word.
    fn toy_embed(texts: &[&str]) -> Result<Vec<Vec<f32>>, BertError> {
        Ok(texts
            .iter()
            .map(|t| {
                let mut v = [0.0f32; 3];
                for w in t.split(' ') {
                    match w {
                        "red" => v[0] += 1.0,
                        "heart" => v[1] += 1.0,
                        _ => v[2] += 1.0,
                    }
                }
                let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
                v.iter().map(|x| x / n).collect()
            })
            .collect())
    }

    #[test]
    fn excluded_sets_are_a_comma_separated_list() {
        assert_eq!(
            comma_list(" noto, noto-v1,,twemoji "),
            ["noto", "noto-v1", "twemoji"]
        );
        assert!(comma_list("").is_empty());
        assert!(comma_list(" , ").is_empty());
    }

    /// The index and icon directories under `root` (where [`model_with`] puts the tarball),
    /// with downloads off.
    fn offline_locations(root: &Path) -> RetrievalLocations {
        RetrievalLocations {
            index_dir: Some(root.join("index")),
            cache: None,
            icons_dir: Some(root.join("icons")),
            offline: true,
            exclude_sets: Vec::new(),
        }
    }

    fn model_with(set_tgz: &[u8], root: &Path) -> PathBuf {
        let model = root.join("model");
        std::fs::create_dir_all(model.join("retrieval")).unwrap();
        let pk = serde_json::json!({"packages": [{"set": "toy", "version": "1.0.0",
            "license": "MIT", "sha256": sha256_hex(set_tgz), "tarball": "http://127.0.0.1:9/none.tgz"}]});
        std::fs::write(model.join("retrieval/packages.json"), pk.to_string()).unwrap();
        let icons = root.join("icons");
        std::fs::create_dir_all(&icons).unwrap();
        std::fs::write(icons.join("iconify-json-toy-1.0.0.tgz"), set_tgz).unwrap();
        model
    }

    #[test]
    fn installs_from_a_local_tarball_and_retrieves_by_caption() {
        let root = std::env::temp_dir().join(format!("vf-retrieval-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let bytes = tgz(SET);
        assert_eq!(icons_json_from_tgz(&bytes).unwrap(), SET);
        let model = model_with(&bytes, &root);
        let loc = offline_locations(&root);
        let idx = install(&model, &loc, false, "", &mut toy_embed).unwrap();
        // red-heart-2 is a variant of red-heart: one caption, two icons
        assert_eq!(idx.captions(), ["red heart", "sun"]);
        assert_eq!(idx.icon_count(), 3);
        let q = toy_embed(&["a red heart"]).unwrap().remove(0);
        let hit = &idx.nearest(&q, 1, 1, 0).unwrap()[0];
        assert_eq!(
            (hit.icon.set.as_str(), hit.icon.license.as_str()),
            ("toy", "MIT")
        );
        assert_eq!(hit.icon.caption, "red heart");
        let img = idx.render(&hit.icon, 16).unwrap();
        let centre = img.pixel(8, 8);
        assert!(centre[0] > 0.8 && centre[1] < 0.1, "{centre:?}");
        // loads back through the locations; a second install does not rebuild
        assert_eq!(loc.load(&model).unwrap().unwrap().icon_count(), 3);
        let mut never = |_: &[&str]| -> Result<Vec<Vec<f32>>, BertError> {
            Err(BertError::Input("rebuilt".into()))
        };
        assert!(install(&model, &loc, false, "", &mut never).is_ok());
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_tampered_tarball_or_held_out_set_is_refused() {
        let root = std::env::temp_dir().join(format!("vf-retrieval-bad-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let model = model_with(&tgz(SET), &root);
        // replace the local tarball with other bytes: the checksum fails
        std::fs::write(root.join("icons/iconify-json-toy-1.0.0.tgz"), tgz("{}")).unwrap();
        let loc = offline_locations(&root);
        let e = install(&model, &loc, false, "", &mut toy_embed).unwrap_err();
        assert!(e.to_string().contains("sha256"), "{e}");
        // no tarball and downloads off: unavailable, not a panic or a hang
        std::fs::remove_file(root.join("icons/iconify-json-toy-1.0.0.tgz")).unwrap();
        let e = install(&model, &loc, false, "", &mut toy_embed).unwrap_err();
        assert!(matches!(e, RetrievalError::Unavailable(_)), "{e}");
        let pk = r#"{"packages":[{"set":"openmoji","version":"1.0.0","license":"x","sha256":"0000000000000000000000000000000000000000000000000000000000000000","tarball":""}]}"#;
        std::fs::write(model.join("retrieval/packages.json"), pk).unwrap();
        assert!(pinned_packages(&model).is_err());
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn the_embedded_model_pins_only_training_sets() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/vf-icon");
        let (pk, sha) = pinned_packages(&model).unwrap().expect("packages.json");
        assert!(pk.len() >= 8);
        assert_eq!(sha.len(), 64);
        assert!(
            pk.iter()
                .all(|p| p.tarball.starts_with("https://registry.npmjs.org/"))
        );
    }
}
