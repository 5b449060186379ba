//! The truth table: one registry of analyses, stating where each is valid. A *cell* is an analysis on a class of
//! shape (triangle mesh, tet mesh, point cloud in R³ or in Rⁿ, graph, polyline) under a boundary condition
//! (Neumann, Dirichlet, Dirichlet with given values), with elements of order 1 or 2, with or without
//! extrapolation. Every cell is either supported, and then checked against a closed form
//! (`tests/truth_table.rs` walks this table and fails on a supported cell without a check), or refused at submission
//! (`unsupported`, naming the analysis, the class and what would work), or cannot be asked at all (the request
//! has no field for it, and the strict request check refuses the field). The service (at submission and in
//! `GET /v1/analyses`), the CLI (before a run, and `kac analyses`), the viewer (which offers only what the shape
//! supports) and the README's table all read this one table.

/// The registry table lives beside the requests (`request.rs`); it is read here, and named here as before.
pub use super::entries::REGISTRY;
use super::*;

/// The classes of shape the truth table distinguishes: a point cloud's class depends on its ambient dimension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ShapeClass {
    TriangleMesh,
    TetMesh,
    /// A point cloud in R³ (a sampled surface).
    CloudR3,
    /// A point cloud in Rⁿ, n ≥ 4 (a sampled manifold of estimated dimension).
    CloudRn,
    Graph,
    Polyline,
}

pub const CLASSES: [ShapeClass; 6] = [
    ShapeClass::TriangleMesh,
    ShapeClass::TetMesh,
    ShapeClass::CloudR3,
    ShapeClass::CloudRn,
    ShapeClass::Graph,
    ShapeClass::Polyline,
];

impl ShapeClass {
    pub fn of(shape: &Shape) -> ShapeClass {
        match shape {
            Shape::TriangleMesh(_) => ShapeClass::TriangleMesh,
            Shape::TetMesh(_) => ShapeClass::TetMesh,
            Shape::PointCloud(c) if c.ambient.is_some() => ShapeClass::CloudRn,
            Shape::PointCloud(_) => ShapeClass::CloudR3,
            Shape::Graph(_) => ShapeClass::Graph,
            Shape::Polyline(_) => ShapeClass::Polyline,
        }
    }
    pub fn as_str(self) -> &'static str {
        match self {
            ShapeClass::TriangleMesh => "triangle_mesh",
            ShapeClass::TetMesh => "tet_mesh",
            ShapeClass::CloudR3 => "cloud_r3",
            ShapeClass::CloudRn => "cloud_rn",
            ShapeClass::Graph => "graph",
            ShapeClass::Polyline => "polyline",
        }
    }
    /// Words for messages and the README.
    pub fn label(self) -> &'static str {
        match self {
            ShapeClass::TriangleMesh => "triangle mesh",
            ShapeClass::TetMesh => "tet mesh",
            ShapeClass::CloudR3 => "point cloud in R³",
            ShapeClass::CloudRn => "point cloud in Rⁿ",
            ShapeClass::Graph => "graph",
            ShapeClass::Polyline => "polyline",
        }
    }
}

/// The boundary condition of a cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Condition {
    /// Natural conditions (and closed shapes).
    Neumann,
    /// Homogeneous Dirichlet: the operator's `boundary: dirichlet` on the shape's boundary or on
    /// `dirichlet_vertices`.
    Dirichlet,
    /// Dirichlet with given values (Poisson's `dirichlet_values`).
    DirichletValues,
}

pub const CONDITIONS: [Condition; 3] = [Condition::Neumann, Condition::Dirichlet, Condition::DirichletValues];

impl Condition {
    pub fn as_str(self) -> &'static str {
        match self {
            Condition::Neumann => "neumann",
            Condition::Dirichlet => "dirichlet",
            Condition::DirichletValues => "dirichlet-values",
        }
    }
}

/// One cell of the truth table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Cell {
    pub analysis: &'static str,
    pub class: ShapeClass,
    pub condition: Condition,
    pub order: u8,
    pub extrapolate: bool,
}

impl std::fmt::Display for Cell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} on a {}, {}, order {}{}",
            self.analysis,
            self.class.label(),
            self.condition.as_str(),
            self.order,
            if self.extrapolate { ", extrapolated" } else { "" }
        )
    }
}

/// What the registry says of a cell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Status {
    Supported,
    /// Refused at submission (`unsupported`) with this reason.
    Refused(String),
    /// The request has no field that could ask for it (this field is refused by the strict request check).
    NotExpressible(&'static str),
}

/// Where one analysis is valid. `classes` it applies to at all; of those, where homogeneous Dirichlet conditions,
/// given Dirichlet values, quadratic elements and extrapolation are supported (empty: refused everywhere, when
/// the request can ask for them). The reasons name why the rest is refused.
#[derive(Debug, Clone, Serialize)]
pub struct Entry {
    pub name: &'static str,
    /// One line: what the analysis computes.
    pub summary: &'static str,
    pub classes: &'static [ShapeClass],
    /// Why the other classes are refused.
    pub classes_why: &'static str,
    /// Whether the request has an `operator` (boundary condition and order).
    pub takes_operator: bool,
    pub dirichlet: &'static [ShapeClass],
    pub dirichlet_why: &'static str,
    /// Whether the request has given Dirichlet values (`dirichlet_values`).
    pub takes_values: bool,
    pub values: &'static [ShapeClass],
    pub order2: &'static [ShapeClass],
    /// Whether the request has `extrapolate`.
    pub takes_extrapolate: bool,
    pub extrapolate: &'static [ShapeClass],
    /// Methods the request may choose (`method`), each checked by the walk; empty: one method.
    pub methods: &'static [&'static str],
    /// What the result states about how approximate it is (estimates, warnings).
    pub accuracy: &'static str,
}

/// The point-cloud normalizations every analysis with an operator takes on clouds (`operator.normalization`),
/// each checked by the walk against the sphere's and the torus' spectra.
pub const CLOUD_NORMALIZATIONS: &[&str] = &["symmetric", "chapter"];

/// The registry's entry of an analysis.
pub fn entry(name: &str) -> Option<&'static Entry> {
    REGISTRY.iter().find(|e| e.name == name)
}

fn names(classes: &[ShapeClass]) -> String {
    let n: Vec<&str> = classes.iter().map(|c| c.label()).collect();
    match n.len() {
        0 => "nothing".into(),
        1 => n[0].into(),
        _ => format!("{} and {}", n[..n.len() - 1].join(", "), n[n.len() - 1]),
    }
}

/// What the registry says of a cell.
pub fn status(cell: &Cell) -> Status {
    let Some(e) = entry(cell.analysis) else {
        return Status::Refused(format!("{} is not an analysis", cell.analysis));
    };
    // What the request cannot ask for at all comes first: no class makes it askable.
    if cell.extrapolate && !e.takes_extrapolate {
        return Status::NotExpressible("extrapolate");
    }
    if cell.condition == Condition::DirichletValues && !e.takes_values {
        return Status::NotExpressible("dirichlet_values");
    }
    if (cell.condition == Condition::Dirichlet || cell.order != 1) && !e.takes_operator {
        return Status::NotExpressible("operator");
    }
    let class = cell.class;
    if !e.classes.contains(&class) {
        return Status::Refused(format!(
            "{} applies to {}, not a {}: {}",
            e.name,
            names(e.classes),
            class.label(),
            e.classes_why
        ));
    }
    match cell.condition {
        Condition::Neumann => {}
        Condition::Dirichlet if !e.dirichlet.contains(&class) => {
            let on = if e.dirichlet.is_empty() {
                "only with Neumann conditions".to_string()
            } else {
                format!("with Dirichlet conditions on {} only", names(e.dirichlet))
            };
            return Status::Refused(format!("{} on a {} runs {on}: {}", e.name, class.label(), e.dirichlet_why));
        }
        Condition::DirichletValues if !e.values.contains(&class) => {
            return Status::Refused(format!("{} takes Dirichlet values on {} only", e.name, names(e.values)))
        }
        _ => {}
    }
    if cell.order == 2 && !e.order2.contains(&class) {
        return Status::Refused(format!(
            "order 2 (quadratic elements) exists for cotan on triangle meshes and tet meshes, not on a {}; \
             {} on a {} runs with order 1",
            class.label(),
            e.name,
            class.label()
        ));
    }
    if cell.extrapolate && !e.extrapolate.contains(&class) {
        return Status::Refused(format!(
            "extrapolation refines the mesh's elements: {} on {} only, not on a {}",
            e.name,
            names(e.extrapolate),
            class.label()
        ));
    }
    Status::Supported
}

/// Every cell of the table: analysis × class × condition × order × extrapolate.
pub fn cells() -> impl Iterator<Item = Cell> {
    REGISTRY.iter().flat_map(|e| {
        CLASSES.into_iter().flat_map(move |class| {
            CONDITIONS.into_iter().flat_map(move |condition| {
                [1u8, 2].into_iter().flat_map(move |order| {
                    [false, true].into_iter().map(move |extrapolate| Cell {
                        analysis: e.name,
                        class,
                        condition,
                        order,
                        extrapolate,
                    })
                })
            })
        })
    })
}

impl Analysis {
    /// Whether the operator eliminates vertices (homogeneous Dirichlet on the boundary or on given vertices), as
    /// `operator_options` builds it.
    fn eliminates_vertices(&self) -> bool {
        self.operator_spec().is_some_and(|s| s.boundary == BoundarySpec::Dirichlet || s.dirichlet_vertices.is_some())
    }

    /// The cell of the truth table this request asks for on this shape.
    pub fn cell(&self, shape: &Shape) -> Cell {
        let spec = self.operator_spec();
        let dirichlet = self.eliminates_vertices();
        let condition = match self {
            Analysis::Poisson { dirichlet_values: Some(_), .. } => Condition::DirichletValues,
            _ if dirichlet => Condition::Dirichlet,
            _ => Condition::Neumann,
        };
        Cell {
            analysis: self.name(),
            class: ShapeClass::of(shape),
            condition,
            order: spec.map_or(1, |s| s.order),
            extrapolate: matches!(self, Analysis::Spectrum { extrapolate: true, .. }),
        }
    }

    /// Whether the registry supports this request on this shape: checked at submission (the service) and before
    /// a run (the CLI); a refused cell is 422 `unsupported`, naming the analysis, the class and what would work,
    /// and is never computed.
    pub fn supported(&self, shape: &Shape) -> Result<(), AnalysisError> {
        let cell = self.cell(shape);
        if !(1..=2).contains(&cell.order) {
            // Not a cell: an order that does not exist is the operator's `invalid-parameter`.
            return Ok(());
        }
        // Given values on top of eliminated vertices (Poisson with both) need the Dirichlet cell too.
        if cell.condition == Condition::DirichletValues && self.eliminates_vertices() {
            if let Status::Refused(why) = status(&Cell { condition: Condition::Dirichlet, ..cell }) {
                return Err(AnalysisError::Unsupported(why));
            }
        }
        match status(&cell) {
            Status::Supported => Ok(()),
            Status::Refused(why) => Err(AnalysisError::Unsupported(why)),
            Status::NotExpressible(field) => {
                Err(AnalysisError::Unsupported(format!("{} has no `{field}`", self.name())))
            }
        }
    }
}

/// Where one analysis is valid (a row of the truth table).
#[derive(Serialize, utoipa::ToSchema)]
pub struct AnalysisSupport {
    pub name: String,
    pub summary: String,
    /// The classes of shape it applies to.
    pub classes: Vec<ShapeClass>,
    /// Whether the request has an `operator` (boundary condition and order).
    pub takes_operator: bool,
    /// Classes where homogeneous Dirichlet conditions are supported.
    pub dirichlet: Vec<ShapeClass>,
    /// Classes where given Dirichlet values are supported (`dirichlet_values`).
    pub dirichlet_values: Vec<ShapeClass>,
    /// Classes where order 2 (quadratic elements) is supported.
    pub order2: Vec<ShapeClass>,
    /// Classes where `extrapolate` is supported.
    pub extrapolate: Vec<ShapeClass>,
    /// Methods the request may choose (`method`); empty: one.
    pub methods: Vec<String>,
    /// What the result says about how approximate it is.
    pub accuracy: String,
    /// With `shape_id`: whether it applies to the shape's class (with Neumann conditions and order 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub applies: Option<bool>,
    /// With `shape_id`, where it does not apply: why, and what would.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// The truth table.
#[derive(Serialize, utoipa::ToSchema)]
pub struct AnalysesTable {
    /// With `shape_id`: the shape's class.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub class: Option<ShapeClass>,
    pub analyses: Vec<AnalysisSupport>,
}

fn row(e: &Entry, class: Option<ShapeClass>) -> AnalysisSupport {
    let status = class.map(|class| {
        status(&Cell { analysis: e.name, class, condition: Condition::Neumann, order: 1, extrapolate: false })
    });
    let reason = match &status {
        Some(Status::Refused(why)) => Some(why.clone()),
        _ => None,
    };
    AnalysisSupport {
        name: e.name.into(),
        summary: e.summary.into(),
        classes: e.classes.to_vec(),
        takes_operator: e.takes_operator,
        dirichlet: if e.takes_operator { within(e, e.dirichlet) } else { vec![] },
        dirichlet_values: within(e, e.values),
        order2: if e.takes_operator { within(e, e.order2) } else { vec![] },
        extrapolate: within(e, e.extrapolate),
        methods: e.methods.iter().map(|m| m.to_string()).collect(),
        accuracy: e.accuracy.into(),
        applies: status.map(|s| s == Status::Supported),
        reason,
    }
}

/// The classes of a list that the analysis applies to at all (a column of the table names no other).
fn within(e: &Entry, list: &[ShapeClass]) -> Vec<ShapeClass> {
    list.iter().copied().filter(|c| e.classes.contains(c)).collect()
}

/// The truth table (`GET /v1/analyses`, `kac analyses`); with a class, which analyses apply to it.
pub fn table(class: Option<ShapeClass>) -> AnalysesTable {
    AnalysesTable { class, analyses: REGISTRY.iter().map(|e| row(e, class)).collect() }
}

/// The README's table of analyses, generated from the registry (a test keeps the README's copy current).
pub fn markdown_table() -> String {
    let mut s = String::from(
        "| analysis | what it computes | shapes | Dirichlet | order 2 | extrapolate | how approximate |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let short = |c: &[ShapeClass], e: &Entry| -> String {
        let c = within(e, c);
        if c.is_empty() {
            return "—".into();
        }
        if c.len() == CLASSES.len() {
            return "all".into();
        }
        c.iter().map(|c| c.label()).collect::<Vec<_>>().join(", ")
    };
    for e in REGISTRY {
        let dirichlet = match (e.takes_operator, e.takes_values) {
            (false, _) => "—".to_string(),
            (true, false) => short(e.dirichlet, e),
            (true, true) => format!("{}; values: {}", short(e.dirichlet, e), short(e.values, e)),
        };
        s.push_str(&format!(
            "| `{}` | {} | {} | {} | {} | {} | {} |\n",
            e.name,
            e.summary,
            short(e.classes, e),
            dirichlet,
            if e.takes_operator { short(e.order2, e) } else { "—".into() },
            if e.takes_extrapolate { short(e.extrapolate, e) } else { "—".into() },
            e.accuracy
        ));
    }
    s
}
