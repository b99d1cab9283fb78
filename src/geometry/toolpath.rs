use super::Nurbs;

/// What a path element was in its source file. Every element is stored as a NURBS curve (arcs
/// exactly, as rational quadratics; lines and polylines as degree 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ElementKind {
    Nurbs,
    Arc,
    Polyline,
}

/// One element of a toolpath with its programmed feed.
#[derive(Clone, Debug, PartialEq)]
pub struct PathElement {
    pub kind: ElementKind,
    pub curve: Nurbs,
    /// Programmed feed (mm/s), if the source gives one.
    pub feed: Option<f64>,
    /// 1-based line in the source file where the element starts, if the format has lines.
    pub source_line: Option<usize>,
}

/// An ordered list of path elements to be run as one motion.
#[derive(Clone, Debug, PartialEq)]
pub struct Toolpath {
    pub elements: Vec<PathElement>,
}

impl Toolpath {
    /// A toolpath of one element: `curve` as a `kind`, with no programmed feed or source line.
    pub fn single(kind: ElementKind, curve: Nurbs) -> Self {
        Toolpath {
            elements: vec![PathElement {
                kind,
                curve,
                feed: None,
                source_line: None,
            }],
        }
    }

    /// Number of tool-tip coordinates (2 or 3); a path mixing 2-D and 3-D elements counts as 3-D.
    pub fn tip_dim(&self) -> usize {
        self.elements.iter().map(|e| e.curve.tip_dim()).max().unwrap_or(2)
    }
}
