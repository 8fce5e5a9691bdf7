//! The vector stage's finish: what every SVG we write passes through before it leaves a run.
//!
//! | file | job |
//! |---|---|
//! | [`simple`] | simple outlines: find paths that cross themselves or fold into spikes, split them into simple pieces |
//! | [`check`] | editability counts of any SVG (self-intersecting, hidden, slivers, colours) |
//! | [`export`] | compact, exact SVG text (fewest decimals within a render tolerance) |
//! | [`palette`] | a small palette: k-means of the target, user palettes, snapping fills |

pub mod check;
pub mod export;
pub mod palette;
pub mod simple;
