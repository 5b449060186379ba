//! The registry's entries, one per analysis in the order of the `Analysis` type (`request.rs`): where each
//! analysis is valid. See `super::registry` for what the table means and how it is read.

use super::registry::{Entry, ShapeClass, CLASSES};

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
        classes: &[TriangleMesh, TetMesh, ShapeClass::CloudR3, ShapeClass::CloudRn, Polyline],
        classes_why: "its families are distributions over the shape scaled to unit measure, which a graph does not \
                      have (compare graphs by their spectrum)",
        // Retrieval compares shapes by their free vibrations with linear elements, the operator lapy's recipe uses
        // and the benchmark measured; a family is only ever compared within itself.
        dirichlet: NONE,
        dirichlet_why: "a retrieval fingerprint is of the free (Neumann) shape, whose families the search index \
                        compares; use shape-dna for Dirichlet spectra",
        order2: NONE,
        ..spectral(
            "fingerprint",
            "retrieval fingerprint: scale-invariant shape-DNA, heat distribution and GPS D2, each a search family",
            "exact for the k pairs computed; the heat distribution's smallest time is resolved to about e^-3 by 50 \
             pairs, GPS D2 samples 400 points",
        )
    },
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
