//! The truth table: one registry of analyses, stating where each is valid. A *cell* is an analysis on a class of
//! shape (triangle mesh, tet mesh, point cloud in R³ or in Rⁿ, graph, polyline) under a boundary condition
//! (Neumann, Dirichlet, Dirichlet with given values), with elements of order 1 or 2, with or without
//! extrapolation. Every cell is either supported, and then checked against a closed form
//! (`tests/truth_table.rs` walks this table and fails on a supported cell without a check), or refused at submission
//! (`unsupported`, naming the analysis, the class and what would work), or cannot be asked at all (the request
//! has no field for it, and the strict request check refuses the field). The service (at submission and in
//! `GET /v1/analyses`), the CLI (before a run, and `kac analyses`), the viewer (which offers only what the shape
//! supports) and the README's table all read this one table.

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

use ShapeClass::{Graph, Polyline, TetMesh, TriangleMesh};

const ALL: &[ShapeClass] = &CLASSES;
const MESHES: &[ShapeClass] = &[TriangleMesh, TetMesh];
/// Where homogeneous Dirichlet conditions mean a Dirichlet problem: a mesh's or a curve's boundary, a graph's
/// given vertices. A point cloud's kernel Laplacian has no boundary term: fixing points does not discretize one.
const BOUNDED: &[ShapeClass] = &[TriangleMesh, TetMesh, Graph, Polyline];
const CLOUD_DIRICHLET: &str = "a point cloud's kernel Laplacian has no boundary term, so fixing points does not \
                               discretize a Dirichlet problem (mesh the cloud, or give values to `poisson`)";
const P2: &[ShapeClass] = &[TriangleMesh, TetMesh];
const NONE: &[ShapeClass] = &[];

/// An analysis over eigenpairs of the operator: every class, Dirichlet where it has a meaning, P2 on meshes.
const fn spectral(name: &'static str, summary: &'static str, accuracy: &'static str) -> Entry {
    Entry {
        name,
        summary,
        classes: ALL,
        classes_why: "",
        takes_operator: true,
        dirichlet: BOUNDED,
        dirichlet_why: CLOUD_DIRICHLET,
        takes_values: false,
        values: NONE,
        order2: P2,
        takes_extrapolate: false,
        extrapolate: NONE,
        methods: &[],
        accuracy,
    }
}

/// An analysis without an operator in its request (no boundary condition, no order).
const fn geometric(
    name: &'static str,
    summary: &'static str,
    classes: &'static [ShapeClass],
    classes_why: &'static str,
    accuracy: &'static str,
) -> Entry {
    Entry {
        name,
        summary,
        classes,
        classes_why,
        takes_operator: false,
        dirichlet: NONE,
        dirichlet_why: "",
        takes_values: false,
        values: NONE,
        order2: NONE,
        takes_extrapolate: false,
        extrapolate: NONE,
        methods: &[],
        accuracy,
    }
}

const TRUNCATED: &str = "exact for the k pairs computed; times or energies the k pairs cannot resolve are outside \
                         the default grids";

/// The registry, in the order of the `Analysis` type.
pub static REGISTRY: &[Entry] = &[
    Entry {
        takes_extrapolate: true,
        extrapolate: MESHES,
        ..spectral(
            "spectrum",
            "the k smallest eigenpairs of L φ = λ M φ (or every pair in a band), completeness proven",
            "residuals per pair; with `extrapolate` an error estimate per eigenvalue; `counting` clusters within \
             the solver's accuracy",
        )
    },
    spectral(
        "operator",
        "L and M as matrices, the unknowns' vertices, the \"no free lunch\" property report",
        "exact (the discrete operator itself)",
    ),
    spectral("hks", "heat kernel signature k_t(x, x) over a time grid", TRUNCATED),
    spectral("si-hks", "scale-invariant HKS: Fourier moduli of the HKS on a log-time grid", TRUNCATED),
    spectral("wks", "wave kernel signature over a log-energy grid", TRUNCATED),
    spectral("gps", "global point signature φ_i / √λ_i", "exact for the k pairs computed"),
    spectral(
        "shape-dna",
        "shape-DNA (normalized, reweighted eigenvalues) and Weyl's-law estimates",
        "Weyl estimates with calibrated uncertainties, omitted where unresolved (`weyl-estimate-omitted`) or \
         meaningless; `weyl-underresolved` warning",
    ),
    Entry {
        methods: &["spectral", "implicit"],
        ..spectral(
            "heat",
            "heat trace and heat kernel rows k_t(source, ·), spectral or backward Euler",
            "the heat trace's truncation bound per time",
        )
    },
    geometric(
        "geodesic",
        "geodesic distance from sources by the heat method, Varadhan's estimate beside it",
        &[TriangleMesh],
        "the heat method takes gradients on a surface's triangles",
        "Varadhan's discrepancy reported",
    ),
    geometric(
        "trees",
        "spanning trees of the edge graph (Kirchhoff), exact where it fits in 128 bits",
        &[TriangleMesh, TetMesh, Graph, Polyline],
        "a point cloud has no edges; build a graph first",
        "exact count when integer weights allow, else its logarithm",
    ),
    geometric(
        "mean-curvature",
        "mean curvature and normals from M⁻¹LX = 2Hn, angle-defect Gaussian curvature",
        &[TriangleMesh],
        "H is read from the cotan Laplacian of a surface's coordinates",
        "boundary vertices flagged",
    ),
    Entry {
        classes: &[TriangleMesh],
        classes_why: "the expansion 4πt·k_t(x,x) = 1 + tK/3 + O(t²) holds on surfaces: a graph or a curve has no \
                      Gaussian curvature, a tet mesh's kernel has a solid's expansion, and a point cloud's \
                      operator smooths at its own kernel time, which biases every time the window can use",
        dirichlet: NONE,
        dirichlet_why: "the expansion is the natural kernel's; a Dirichlet kernel loses heat through the boundary",
        ..spectral(
            "heat-curvature",
            "Gaussian curvature heard from the heat kernel's small-time expansion",
            "the fit's residual per vertex; the window kept below the shape's curvature scale 1/κ_max² \
             (`curvature_scale`: expansion bias ≤ 3 % on a sphere and a torus), `curvature-window-too-coarse` \
             warning when the mesh's resolution or the pairs do not allow that, `curvature-window-unresolved` \
             when the window's times are below the mesh's resolution",
        )
    },
    spectral("wave", "the wave equation by modal superposition, with its conserved energy", "energy drift"),
    spectral("schrodinger", "the Schrödinger equation, unitary in the eigenbasis, its conserved norm", "norm drift"),
    Entry {
        takes_values: true,
        values: ALL,
        ..spectral(
            "poisson",
            "Poisson's equation Δf = g, Neumann (compatible part) or Dirichlet (homogeneous or given values)",
            "the mean of g removed per component (Neumann) reported",
        )
    },
    Entry {
        methods: &["spectral", "implicit"],
        ..spectral(
            "diffuse",
            "heat diffusion of a function, spectral (with its truncation bound) or backward Euler",
            "truncation bound (spectral)",
        )
    },
    spectral("dirichlet-energy", "½ uᵀLu, uᵀMu and the Rayleigh quotient of a function", "exact (discrete)"),
    geometric(
        "gradient",
        "the gradient of a per-vertex function on each triangle or tetrahedron",
        MESHES,
        "P1 gradients live on a mesh's triangles or tetrahedra",
        "exact for linear functions",
    ),
    geometric(
        "divergence",
        "the divergence of a per-element vector field per vertex (integrated and pointwise)",
        MESHES,
        "P1 gradients live on a mesh's triangles or tetrahedra",
        "exact (discrete)",
    ),
    Entry {
        dirichlet: NONE,
        dirichlet_why: "a Laplacian eigenmap and the Fiedler vector are defined with natural conditions",
        ..spectral("embed", "Laplacian eigenmap / GPS coordinates, Fiedler vector and bisection", "exact (discrete)")
    },
    Entry {
        dirichlet: NONE,
        dirichlet_why: "smoothing takes a Neumann operator; give `fixed_boundary` to clamp the boundary",
        ..spectral(
            "smooth",
            "(M + αL) u = M ū: implicit fairing of the coordinates or of a function",
            "exact (discrete)",
        )
    },
    Entry {
        dirichlet: NONE,
        dirichlet_why: "interpolation fixes its own vertices (the given values); use a Neumann operator",
        ..spectral("interpolate", "harmonic interpolation of values, or semi-supervised labels", "exact (discrete)")
    },
];

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
