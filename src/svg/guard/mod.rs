//! Bounds on untrusted SVG text, checked before usvg builds any geometry.
//!
//! [`super::parse_usvg`] is the crate's one SVG entry point (HTTP submissions, previews, the
//! worker, `render`, `vectorize`, evaluation, retrieval); it runs [`parse`] with
//! [`SvgLimits::DEFAULT`], so the CLI and the server refuse the same inputs. In order:
//! 1. at most [`SvgLimits::max_bytes`] of text;
//! 2. DTD entities internal and not parameter entities (external ones are refused), expanding to
//!    at most `max_bytes` in all; an entity whose text refers to other entities (the start of a
//!    billion laughs) has its text dropped, with a warning. Illustrator's
//!    `<!ENTITY ns_svg "http://…">` lines and entities holding markup are fine;
//! 3. at most [`SvgLimits::max_nodes`] XML nodes (elements, text, comments: roxmltree stops
//!    parsing there);
//! 4. at most [`SvgLimits::max_path_numbers`] numbers in all `d` and `points` attributes, and
//!    every number of an attribute usvg reads, a `style` attribute or a `<style>` sheet finite
//!    and within ±[`SvgLimits::max_number`] (numbers inside `url(…)` and quoted strings, ids,
//!    names and hex colours are not numbers);
//! 5. once `<use>`, `href` and `url(#…)` references and markers are expanded (as usvg and resvg
//!    expand them): at most [`SvgLimits::max_expanded`] elements, nesting at most
//!    [`SvgLimits::max_depth`] deep, at most [`SvgLimits::max_layers`] clip-path, mask, filter
//!    and pattern uses (each costs the renderer a layer). A reference cycle is broken where it
//!    closes, as usvg breaks it: that `href` is dropped, that `url(#…)` becomes `none`, with a
//!    warning, and the text is checked again (at most [`MAX_REPAIRS`] times); a marker inside
//!    its own drawing is passed over, as usvg passes it over (nothing to repair);
//! 6. after conversion, the drawing's layer bounding box (strokes and filter regions included,
//!    through every transform) and every pattern tile within ±[`SvgLimits::max_coord_ratio`] ×
//!    the canvas size.
//!
//! Every check is linear in the input (references are memoised), so refusing an SVG costs no
//! more than reading it.

use resvg::usvg;
use resvg::usvg::roxmltree::{self, Node, NodeId};
use std::collections::{HashMap, HashSet};
use std::ops::Range;

mod numbers;
use numbers::{in_range, scan_numbers};

/// Most repairs (dropped entity texts and cycle links) one document gets before it is refused.
pub const MAX_REPAIRS: usize = 32;

const SVG_NS: &str = "http://www.w3.org/2000/svg";
const XLINK: &str = "http://www.w3.org/1999/xlink";

/// Limits on one SVG document. Invariant: every field is positive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SvgLimits {
    /// Bytes of SVG text, and bytes of entity text once expanded.
    pub max_bytes: usize,
    /// XML nodes as parsed (elements, text, comments).
    pub max_nodes: u32,
    /// Elements once references and markers are expanded.
    pub max_expanded: u64,
    /// Nesting depth once references are expanded (the root is depth 1).
    pub max_depth: usize,
    /// Clip-path, mask, filter and pattern uses once references are expanded.
    pub max_layers: u64,
    /// Numbers in all `d` and `points` attributes together.
    pub max_path_numbers: usize,
    /// Largest magnitude of any number in attributes and style sheets.
    pub max_number: f64,
    /// The converted drawing must lie within ± this × the canvas size.
    pub max_coord_ratio: f64,
}

impl SvgLimits {
    /// The limits every entry point uses (stated in docs/SERVICE.md).
    pub const DEFAULT: SvgLimits = SvgLimits {
        max_bytes: 16 << 20,
        max_nodes: 500_000,
        max_expanded: 500_000,
        max_depth: 128,
        max_layers: 10_000,
        max_path_numbers: 2_000_000,
        max_number: 1e7,
        max_coord_ratio: 64.0,
    };
}

impl Default for SvgLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why untrusted SVG text was refused: which bound of [`SvgLimits`] it passed, or why it does
/// not parse. Messages read after "the SVG …" ("is 3000000 bytes; at most …").
#[derive(Debug, thiserror::Error)]
pub enum SvgRejected {
    #[error("is {bytes} bytes; at most {max} allowed")]
    TooLarge { bytes: usize, max: usize },
    #[error("declares a parameter entity, which is not allowed")]
    ParameterEntity,
    #[error("has a malformed entity declaration")]
    MalformedEntity,
    #[error("declares the external entity {0:?}, which is not allowed")]
    ExternalEntity(String),
    #[error("expands entities to more than {max} bytes")]
    EntityExpansion { max: usize },
    #[error("has more than {max} XML nodes")]
    TooManyNodes { max: u32 },
    /// Not well-formed XML.
    #[error("{0}")]
    Xml(#[source] roxmltree::Error),
    /// Well-formed, but usvg cannot convert it.
    #[error("{0}")]
    Usvg(#[source] usvg::Error),
    #[error("has {count} path numbers; at most {max} allowed")]
    PathNumbers { count: usize, max: usize },
    #[error("<{tag}> {attr} has the number {value}, outside ±{max}")]
    Number {
        tag: String,
        attr: String,
        value: f64,
        max: f64,
    },
    #[error("nests elements (through references) more than {max} deep")]
    TooDeep { max: usize },
    #[error("needs more than {max} repairs (reference cycles, entities referring to entities)")]
    Cycle { max: usize },
    #[error("has a reference cycle or entity written so that it cannot be repaired")]
    Unrepairable,
    #[error("expands (through references and markers) to more than {max} elements")]
    TooManyElements { max: u64 },
    #[error("uses clip paths, masks, filters or patterns more than {max} times")]
    TooManyLayers { max: u64 },
    #[error("draws as far as {at} px, outside ±{range} px ({ratio} × the canvas size)")]
    TooFar { at: f64, range: f64, ratio: f64 },
    #[error("has a pattern tile of {side} px, over {range} px")]
    PatternTile { side: f64, range: f64 },
}

/// A converted SVG and what the guard changed so that it could be drawn.
pub struct Parsed {
    pub tree: usvg::Tree,
    /// One sentence per repair (a dropped entity text, a broken reference cycle).
    pub warnings: Vec<String>,
}

/// One change to the text: `range` becomes `with`.
struct Repair {
    range: Range<usize>,
    with: &'static str,
    warning: String,
}

/// Parses `text` within `limits`, then converts it with usvg (`opts`), repairing what usvg
/// would repair (see the module docs) and saying what it did.
pub fn parse_repaired(
    text: &str,
    limits: &SvgLimits,
    opts: &usvg::Options,
) -> Result<Parsed, SvgRejected> {
    if text.len() > limits.max_bytes {
        return Err(SvgRejected::TooLarge {
            bytes: text.len(),
            max: limits.max_bytes,
        });
    }
    let mut text = std::borrow::Cow::Borrowed(text);
    let mut warnings = Vec::new();
    for _ in 0..=MAX_REPAIRS {
        let repair = match check_entities(&text, limits.max_bytes)? {
            Some(r) => r,
            None => match convert(&text, limits, opts)? {
                Ok(tree) => return Ok(Parsed { tree, warnings }),
                Err(r) => r,
            },
        };
        // A range that does not name the link in the text (an attribute written through an
        // entity or a character reference) cannot be repaired.
        let names_link = text
            .get(repair.range.clone())
            .is_some_and(|t| match repair.with {
                "none" => t.starts_with("url("),
                "" => t.contains("href") || !t.contains('<'),
                _ => false,
            });
        if !names_link {
            return Err(SvgRejected::Unrepairable);
        }
        let mut fixed = String::with_capacity(text.len());
        fixed.push_str(&text[..repair.range.start]);
        fixed.push_str(repair.with);
        fixed.push_str(&text[repair.range.end..]);
        text = std::borrow::Cow::Owned(fixed);
        warnings.push(repair.warning);
    }
    Err(SvgRejected::Cycle { max: MAX_REPAIRS })
}

/// Steps 3–6 on text whose entities passed: the tree, or the repair a reference cycle needs.
fn convert(
    text: &str,
    limits: &SvgLimits,
    opts: &usvg::Options,
) -> Result<Result<usvg::Tree, Repair>, SvgRejected> {
    let xml = roxmltree::ParsingOptions {
        allow_dtd: true,
        nodes_limit: limits.max_nodes,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(text, xml).map_err(|e| match e {
        roxmltree::Error::NodesLimitReached => SvgRejected::TooManyNodes {
            max: limits.max_nodes,
        },
        e => SvgRejected::Xml(e),
    })?;
    if let Some(repair) = check_document(&doc, limits)? {
        return Ok(Err(repair));
    }
    let tree = usvg::Tree::from_xmltree(&doc, opts).map_err(SvgRejected::Usvg)?;
    check_extent(&tree, limits)?;
    Ok(Ok(tree))
}

/// Step 2: every `<!ENTITY` is an internal general entity, and all uses together expand to at
/// most `max_bytes`. The first entity whose text refers to other entities comes back as the
/// repair that empties its text.
fn check_entities(text: &str, max_bytes: usize) -> Result<Option<Repair>, SvgRejected> {
    let mut total = 0usize;
    let mut rest = text;
    while let Some(p) = rest.find("<!ENTITY") {
        rest = rest[p + "<!ENTITY".len()..].trim_start();
        if rest.starts_with('%') {
            return Err(SvgRejected::ParameterEntity);
        }
        let name_end = rest
            .find(|c: char| c.is_whitespace())
            .ok_or(SvgRejected::MalformedEntity)?;
        let name = &rest[..name_end];
        rest = rest[name_end..].trim_start();
        let Some(quote) = rest.chars().next().filter(|c| *c == '"' || *c == '\'') else {
            return Err(SvgRejected::ExternalEntity(name.to_string()));
        };
        let body = &rest[1..];
        let end = body.find(quote).ok_or(SvgRejected::MalformedEntity)?;
        let value = &body[..end];
        if value.contains('&') || value.contains('%') {
            let start = text.len() - body.len();
            return Ok(Some(Repair {
                range: start..start + end,
                with: "",
                warning: format!("entity {name:?} refers to other entities: its text was dropped"),
            }));
        }
        let uses = text.matches(&format!("&{name};")).count();
        total = total.saturating_add(uses.saturating_mul(value.len()));
        if total > max_bytes {
            return Err(SvgRejected::EntityExpansion { max: max_bytes });
        }
        rest = &body[end..];
    }
    Ok(None)
}

/// Steps 4–5, on the parsed XML; the repair of the first reference cycle found, if any.
fn check_document(
    doc: &roxmltree::Document,
    limits: &SvgLimits,
) -> Result<Option<Repair>, SvgRejected> {
    let mut ids: HashMap<&str, Node> = HashMap::new();
    let mut path_numbers = 0usize;
    let mut uses_markers = false;
    let mut sheet_refs = Vec::new();
    for node in doc.descendants().filter(Node::is_element) {
        // usvg keeps the first element of an id, in document order.
        if let Some(id) = node.attribute("id") {
            ids.entry(id).or_insert(node);
        }
        if !svg_element(node) {
            continue;
        }
        let tag = node.tag_name().name();
        for a in node.attributes().filter(|a| read_by_usvg(a.namespace())) {
            let name = a.name();
            if skipped(name) {
                continue;
            }
            uses_markers |= name.starts_with("marker") || a.value().contains("marker");
            let path_like = name == "d" || name == "points";
            let n = scan_numbers(a.value(), path_like, |v| in_range(v, limits, tag, name))?;
            if path_like {
                path_numbers = path_numbers.saturating_add(n);
            }
        }
        if tag == "style" {
            for t in node.children().filter_map(|c| c.text()) {
                scan_numbers(t, false, |v| in_range(v, limits, tag, "sheet"))?;
                uses_markers |= t.contains("marker");
                sheet_refs.extend(url_ids(t).map(str::to_string));
            }
        }
    }
    if path_numbers > limits.max_path_numbers {
        return Err(SvgRejected::PathNumbers {
            count: path_numbers,
            max: limits.max_path_numbers,
        });
    }
    // Sheet rules may apply to any element: every element is charged each sheet reference.
    let sheet_targets: Vec<Node> = sheet_refs
        .iter()
        .filter_map(|id| ids.get(id.as_str()).copied())
        .collect();
    let mut e = Expansion {
        ids: &ids,
        sheet_targets,
        memo: HashMap::new(),
        own: HashMap::new(),
        visiting: HashSet::new(),
        markers: Vec::new(),
        skipped_markers: 0,
        limits,
        marker_cost: 0,
        cycle: None,
    };
    let result = (|| {
        if uses_markers {
            let markers: Vec<Node> = doc
                .descendants()
                .filter(|n| n.is_element() && n.tag_name().name() == "marker")
                .collect();
            for m in markers {
                let c = e.in_marker(m, 1)?;
                e.marker_cost = e.marker_cost.max(c.elements);
            }
        }
        e.cost(doc.root_element(), 1).map(|_| ())
    })();
    match (result, e.cycle.take()) {
        (Err(SvgRejected::Cycle { .. }), Some(repair)) => Ok(Some(repair)),
        (r, _) => r.map(|()| None),
    }
}

/// How an element refers to another.
#[derive(Clone)]
enum Link {
    /// Its `href` attribute (this byte range of the text).
    Href(Range<usize>),
    /// A `url(#…)` at this byte range of the text.
    Url(Range<usize>),
    /// A rule of a `<style>` sheet.
    Sheet,
}

/// Whether `link` is an `href` by which `from` inherits attributes and content from `to`, both
/// paint servers or filters of the same family (usvg resolves a ring of these itself).
fn inherits_by_href(from: Node, to: Node, link: &Link) -> bool {
    let family = |n: Node| match n.tag_name().name() {
        "linearGradient" | "radialGradient" => Some(0),
        "pattern" => Some(1),
        "filter" => Some(2),
        _ => None,
    };
    matches!(link, Link::Href(_)) && family(from).is_some() && family(from) == family(to)
}

/// `<tag id="…">` for warnings.
fn describe(node: Node) -> String {
    match node.attribute("id") {
        Some(id) => format!("<{} id={id:?}>", node.tag_name().name()),
        None => format!("<{}>", node.tag_name().name()),
    }
}

/// The repair that drops `link` from `from` to `to`, which closes a reference cycle.
fn break_cycle(from: Node, to: Node, link: &Link) -> Option<Repair> {
    let (range, with) = match link {
        Link::Href(r) => (r.clone(), ""),
        Link::Url(r) => (r.clone(), "none"),
        Link::Sheet => return None,
    };
    let to = if from == to {
        "itself".to_string()
    } else {
        format!("{}, which refers back to it", describe(to))
    };
    Some(Repair {
        range,
        with,
        warning: format!(
            "{} refers to {to} (a reference cycle): that reference was dropped",
            describe(from)
        ),
    })
}

/// Elements usvg reads: the SVG namespace, or none (a file without `xmlns`).
fn svg_element(node: Node) -> bool {
    node.tag_name().namespace().is_none_or(|ns| ns == SVG_NS)
}

/// Attribute namespaces usvg reads (editor namespaces such as `inkscape:` it ignores).
fn read_by_usvg(ns: Option<&str>) -> bool {
    ns.is_none_or(|ns| ns == SVG_NS || ns == XLINK)
}

/// Attributes whose text is no geometry (names and links).
fn skipped(name: &str) -> bool {
    matches!(
        name,
        "id" | "class" | "href" | "font-family" | "version" | "baseProfile" | "lang" | "title"
    ) || name.starts_with("data-")
        || name.starts_with("aria-")
}

/// The ids of the `url(#id)` references in `s`.
fn url_ids(s: &str) -> impl Iterator<Item = &str> {
    url_refs(s).map(|(_, id)| id)
}

/// The `url(#id)` references in `s`: the byte range of each `url(…)` and its id.
fn url_refs(s: &str) -> impl Iterator<Item = (Range<usize>, &str)> {
    s.match_indices("url(").filter_map(move |(p, _)| {
        let inner = &s[p + 4..];
        let close = inner.find(')')?;
        let inner = &inner[..close];
        let inner = inner.trim().trim_matches(|c| c == '"' || c == '\'').trim();
        Some((p..p + 4 + close + 1, inner.strip_prefix('#')?))
    })
}

/// The element an `href` names (usvg: the plain attribute first, then `xlink:href`), and the
/// attribute's byte range.
fn href_target<'a, 'i>(
    node: Node<'a, 'i>,
    ids: &HashMap<&str, Node<'a, 'i>>,
) -> Option<(Node<'a, 'i>, Link)> {
    // roxmltree's `attribute("href")` matches the local name in any namespace: look for the
    // unprefixed one explicitly, as usvg does.
    let attr = node
        .attributes()
        .find(|a| a.namespace().is_none() && a.name() == "href")
        .or_else(|| {
            node.attributes()
                .find(|a| a.namespace() == Some(XLINK) && a.name() == "href")
        })?;
    let target = ids.get(attr.value().trim().strip_prefix('#')?.trim())?;
    Some((*target, Link::Href(attr.range())))
}

/// The vertices a marker is drawn at on `node` (0 for elements that carry no markers).
fn vertices(node: Node) -> u64 {
    if !svg_element(node) {
        return 0;
    }
    match node.tag_name().name() {
        "path" | "polygon" | "polyline" => {
            let d = node.attribute("d").or_else(|| node.attribute("points"));
            d.map_or(0, |d| {
                scan_numbers(d, true, |_| Ok(())).unwrap_or(0) as u64 / 2 + 1
            })
        }
        "line" | "rect" | "circle" | "ellipse" => 5,
        _ => 0,
    }
}

/// What one element costs once its references are expanded.
#[derive(Clone, Copy, Debug, Default)]
struct Cost {
    elements: u64,
    layers: u64,
    /// Nesting below and including this element.
    height: usize,
}

/// Counts elements, layers and depth with references expanded, memoised per element.
struct Expansion<'d, 'a, 'i> {
    ids: &'d HashMap<&'a str, Node<'a, 'i>>,
    sheet_targets: Vec<Node<'a, 'i>>,
    memo: HashMap<NodeId, Cost>,
    /// Each element's own references and marker vertices ([`Expansion::own`]).
    own: HashMap<NodeId, (Vec<(Node<'a, 'i>, Link)>, u64)>,
    visiting: HashSet<NodeId>,
    /// The markers being drawn, outermost first (usvg's `parent_markers`).
    markers: Vec<NodeId>,
    /// How many marker references were passed over because that marker was being drawn: a
    /// cost computed while this grew depends on the markers around it and is not memoised.
    skipped_markers: usize,
    limits: &'d SvgLimits,
    /// Elements of the largest marker, charged per vertex of every drawn shape.
    marker_cost: u64,
    /// The repair of the cycle [`SvgRejected::Cycle`] reports.
    cycle: Option<Repair>,
}

impl<'a, 'i> Expansion<'_, 'a, 'i> {
    fn cost(&mut self, node: Node<'a, 'i>, depth: usize) -> Result<Cost, SvgRejected> {
        let l = self.limits;
        let deep = || SvgRejected::TooDeep { max: l.max_depth };
        if let Some(&c) = self.memo.get(&node.id()) {
            if depth + c.height - 1 > l.max_depth {
                return Err(deep());
            }
            return Ok(c);
        }
        if depth > l.max_depth {
            return Err(deep());
        }
        let cycle = || SvgRejected::Cycle { max: MAX_REPAIRS };
        if !self.visiting.insert(node.id()) {
            return Err(cycle());
        }
        let mut c = Cost {
            elements: 1,
            layers: 0,
            height: 1,
        };
        let (refs, vertices) = self.own(node);
        c.elements = c
            .elements
            .saturating_add(vertices.saturating_mul(self.marker_cost));
        let skipped_before = self.skipped_markers;
        for (r, link) in refs {
            let rc = if matches!(link, Link::Url(_)) && r.tag_name().name() == "marker" {
                // usvg draws a marker's content anew at every vertex and, inside it, passes
                // over a marker already being drawn (not a cycle to repair). The reference is
                // charged as one element, so a walk without memo stays within the limit.
                if self.markers.contains(&r.id()) {
                    self.skipped_markers += 1;
                    Cost {
                        elements: 1,
                        layers: 0,
                        height: 0,
                    }
                } else {
                    self.in_marker(r, depth + 1)?
                }
            } else {
                if self.visiting.contains(&r.id()) {
                    if inherits_by_href(node, r, &link) {
                        // usvg follows such a chain from each element only until it comes
                        // back to that element: every element keeps what the rest of the ring
                        // gives it.
                        continue;
                    }
                    self.cycle = break_cycle(node, r, &link);
                    return Err(cycle());
                }
                self.cost(r, depth + 1)?
            };
            let layer = matches!(
                r.tag_name().name(),
                "clipPath" | "mask" | "filter" | "pattern"
            );
            c.elements = c.elements.saturating_add(rc.elements);
            c.layers = c.layers.saturating_add(rc.layers + u64::from(layer));
            c.height = c.height.max(rc.height + 1);
            self.within(&c)?;
        }
        for child in node.children().filter(Node::is_element) {
            let rc = self.cost(child, depth + 1)?;
            c.elements = c.elements.saturating_add(rc.elements);
            c.layers = c.layers.saturating_add(rc.layers);
            c.height = c.height.max(rc.height + 1);
            self.within(&c)?;
        }
        self.within(&c)?;
        self.visiting.remove(&node.id());
        if self.skipped_markers == skipped_before {
            self.memo.insert(node.id(), c);
        }
        Ok(c)
    }

    /// The cost of marker `m` drawn where a shape refers to it: its content is a new instance
    /// (the elements on the way to the shape are not its ancestors), and inside it `m` and the
    /// markers around it are passed over, as usvg does. Without memoised reuse such nesting is
    /// walked in full, so the work stays within the element limit it is checked against.
    fn in_marker(&mut self, m: Node<'a, 'i>, depth: usize) -> Result<Cost, SvgRejected> {
        let outer = std::mem::take(&mut self.visiting);
        self.markers.push(m.id());
        let c = self.cost(m, depth);
        self.markers.pop();
        self.visiting = outer;
        c
    }

    /// The elements `node` refers to, and how, and the vertices a marker is drawn at on it
    /// (its own attributes are read once per element, however often a marker redraws it).
    fn own(&mut self, node: Node<'a, 'i>) -> (Vec<(Node<'a, 'i>, Link)>, u64) {
        let (mut refs, vertices) = match self.own.get(&node.id()) {
            Some(o) => o.clone(),
            None => {
                let o = (self.attribute_refs(node), vertices(node));
                self.own.insert(node.id(), o.clone());
                o
            }
        };
        // A sheet's rule charges every element; it need not apply to its own target (usvg
        // breaks cycles through sheets itself).
        refs.extend(
            self.sheet_targets
                .iter()
                .filter(|t| !self.visiting.contains(&t.id()))
                .map(|t| (*t, Link::Sheet)),
        );
        (refs, vertices)
    }

    /// The `href` and `url(#…)` references of `node`'s own attributes.
    fn attribute_refs(&self, node: Node<'a, 'i>) -> Vec<(Node<'a, 'i>, Link)> {
        let mut refs: Vec<(Node<'a, 'i>, Link)> = href_target(node, self.ids).into_iter().collect();
        if !svg_element(node) {
            return refs;
        }
        for a in node.attributes().filter(|a| read_by_usvg(a.namespace())) {
            let at = a.range_value().start;
            refs.extend(url_refs(a.value()).filter_map(|(r, id)| {
                let target = self.ids.get(id)?;
                Some((*target, Link::Url(at + r.start..at + r.end)))
            }));
        }
        refs
    }

    fn within(&self, c: &Cost) -> Result<(), SvgRejected> {
        let l = self.limits;
        if c.elements > l.max_expanded {
            return Err(SvgRejected::TooManyElements {
                max: l.max_expanded,
            });
        }
        if c.layers > l.max_layers {
            return Err(SvgRejected::TooManyLayers { max: l.max_layers });
        }
        Ok(())
    }
}

/// Step 6: the converted drawing and its pattern tiles stay near the canvas.
fn check_extent(tree: &usvg::Tree, limits: &SvgLimits) -> Result<(), SvgRejected> {
    let size = tree.size();
    let range = limits.max_coord_ratio * f64::from(size.width().max(size.height()));
    let b = tree.root().abs_layer_bounding_box();
    let far = [b.left(), b.top(), b.right(), b.bottom()]
        .into_iter()
        .map(f64::from)
        .find(|v| !v.is_finite() || v.abs() > range);
    if let Some(v) = far {
        return Err(SvgRejected::TooFar {
            at: v,
            range,
            ratio: limits.max_coord_ratio,
        });
    }
    pattern_tiles(tree.root(), range)
}

fn pattern_tiles(g: &usvg::Group, range: f64) -> Result<(), SvgRejected> {
    for node in g.children() {
        match node {
            usvg::Node::Group(child) => pattern_tiles(child, range)?,
            usvg::Node::Path(p) => {
                let paints = [p.fill().map(|f| f.paint()), p.stroke().map(|s| s.paint())];
                for paint in paints.into_iter().flatten() {
                    if let usvg::Paint::Pattern(pat) = paint {
                        let (sx, sy) = p.abs_transform().pre_concat(pat.transform()).get_scale();
                        let r = pat.rect();
                        let side = f64::from(r.width() * sx).max(f64::from(r.height() * sy));
                        if !side.is_finite() || side > range {
                            return Err(SvgRejected::PatternTile { side, range });
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
