"""One function per analysis of the registry, written by tools/gen_analyses.py from the registry and the
requests' JSON Schemas (do not edit by hand; a test checks it is current)."""

from __future__ import annotations

from typing import Any

from ._core import Progress, Result, ShapeLike, analyze


def hks(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """heat kernel signature k_t(x, x) over a time grid.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact for the k pairs
    computed; times or energies the k pairs cannot resolve are outside the default grids

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``HksAnalysis``, ``kac hks --help``):

    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``options``: Its fields may be given directly: count, scale, times.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("hks", s, faces, threads=threads, progress=progress, **options)


def si_hks(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """scale-invariant HKS: Fourier moduli of the HKS on a log-time grid.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact for the k pairs
    computed; times or energies the k pairs cannot resolve are outside the default grids

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``SiHksAnalysis``, ``kac si-hks --help``):

    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``options``: Its fields may be given directly: alpha, frequencies, samples, tau_start, tau_step.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("si-hks", s, faces, threads=threads, progress=progress, **options)


def wks(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """wave kernel signature over a log-energy grid.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact for the k pairs
    computed; times or energies the k pairs cannot resolve are outside the default grids

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``WksAnalysis``, ``kac wks --help``):

    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``options``: Its fields may be given directly: count, energies, variance.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("wks", s, faces, threads=threads, progress=progress, **options)


def gps(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """global point signature φ_i / √λ_i.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact for the k pairs
    computed

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``GpsAnalysis``, ``kac gps --help``):

    - ``dimensions``
    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("gps", s, faces, threads=threads, progress=progress, **options)


def shape_dna(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """shape-DNA (normalized, reweighted eigenvalues) and Weyl's-law estimates.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: Weyl estimates with
    calibrated uncertainties, omitted where unresolved (`weyl-estimate-omitted`) or meaningless; `weyl-
    underresolved` warning

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``ShapeDnaAnalysis``, ``kac shape-dna --help``):

    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``options``: Its fields may be given directly: include_zero, k, normalization, reweighting.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("shape-dna", s, faces, threads=threads, progress=progress, **options)


def fingerprint(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """retrieval fingerprint: scale-invariant shape-DNA, heat distribution and GPS D2, each a search family.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, polyline. Accuracy: exact for the k pairs computed; the
    heat distribution's smallest time is resolved to about e^-3 by 50 pairs, GPS D2 samples 400 points

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``FingerprintAnalysis``, ``kac fingerprint --help``):

    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``options``: Its fields may be given directly: include_zero, k, normalization, reweighting.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("fingerprint", s, faces, threads=threads, progress=progress, **options)


def heat(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """heat trace and heat kernel rows k_t(source, ·), spectral or backward Euler.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: the heat trace's truncation
    bound per time

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``HeatAnalysis``, ``kac heat --help``):

    - ``k``
    - ``method``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.
    - ``sources``
    - ``steps``: Backward-Euler steps per time (implicit method).
    - ``times``: Default: the HKS time grid with 10 times.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("heat", s, faces, threads=threads, progress=progress, **options)


def geodesic(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """geodesic distance from sources by the heat method, Varadhan's estimate beside it.

    Applies to: triangle_mesh. Accuracy: Varadhan's discrepancy reported

    Options (the service's ``GeodesicAnalysis``, ``kac geodesic --help``):

    - ``options``: Its fields may be given directly: time_factor, varadhan_factor, varadhan_steps.
    - ``sources``

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("geodesic", s, faces, threads=threads, progress=progress, **options)


def trees(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """spanning trees of the edge graph (Kirchhoff), exact where it fits in 128 bits.

    Applies to: triangle_mesh, tet_mesh, graph, polyline. Accuracy: exact count when integer weights allow, else its
    logarithm

    Options (the service's ``TreesAnalysis``, ``kac trees --help``):


    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("trees", s, faces, threads=threads, progress=progress, **options)


def mean_curvature(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """mean curvature and normals from M⁻¹LX = 2Hn, angle-defect Gaussian curvature.

    Applies to: triangle_mesh. Accuracy: boundary vertices flagged

    Options (the service's ``MeanCurvatureAnalysis``, ``kac mean-curvature --help``):


    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("mean-curvature", s, faces, threads=threads, progress=progress, **options)


def heat_curvature(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """Gaussian curvature heard from the heat kernel's small-time expansion.

    Applies to: triangle_mesh. Accuracy: the fit's residual per vertex; the window kept below the shape's curvature
    scale 1/κ_max² (`curvature_scale`: expansion bias ≤ 3 % on a sphere and a torus), `curvature-window-too-coarse`
    warning when the mesh's resolution or the pairs do not allow that, `curvature-window-unresolved` when the
    window's times are below the mesh's resolution

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``HeatCurvatureAnalysis``, ``kac heat-curvature --help``):

    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.
    - ``times``: The window's times (default: 8 log-spaced from the larger of 4 ln 10 / λ_k and the mesh's
      resolution time, up to 4× that but kept at or below the curvature scale 1/κ_max², never less than 2×).

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("heat-curvature", s, faces, threads=threads, progress=progress, **options)


def wave(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """the wave equation by modal superposition, with its conserved energy.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: energy drift

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``WaveAnalysis``, ``kac wave --help``):

    - ``initial``: u₀ (or Re ψ₀) per vertex, in the upload's numbering.
    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.
    - ``source``: Or a bump at this vertex (upload numbering).
    - ``times``
    - ``velocity``: ∂u/∂t at t = 0, per vertex (upload numbering; default zero).
    - ``width``: The bump's width w (default: 5 % of the bounding box's diagonal).

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("wave", s, faces, threads=threads, progress=progress, **options)


def schrodinger(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """the Schrödinger equation, unitary in the eigenbasis, its conserved norm.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: norm drift

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``SchrodingerAnalysis``, ``kac schrodinger --help``):

    - ``initial``: u₀ (or Re ψ₀) per vertex, in the upload's numbering.
    - ``initial_imag``: The imaginary part of ψ₀, per vertex (upload numbering; default zero).
    - ``k``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.
    - ``source``: Or a bump at this vertex (upload numbering).
    - ``times``
    - ``width``: The bump's width w (default: 5 % of the bounding box's diagonal).

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("schrodinger", s, faces, threads=threads, progress=progress, **options)


def poisson(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """Poisson's equation Δf = g, Neumann (compatible part) or Dirichlet (homogeneous or given values).

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: the mean of g removed per
    component (Neumann) reported

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``PoissonAnalysis``, ``kac poisson --help``):

    - ``dirichlet_values``: f fixed at these vertices (upload numbering): `[[vertex, value], …]`; none: Neumann.
    - ``g``: g per vertex (upload numbering).
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("poisson", s, faces, threads=threads, progress=progress, **options)


def diffuse(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """heat diffusion of a function, spectral (with its truncation bound) or backward Euler.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: truncation bound (spectral)

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``DiffuseAnalysis``, ``kac diffuse --help``):

    - ``diffusivity``: The diffusivity α (default 1): u(t) is the unit-diffusivity solution at αt.
    - ``initial``: u₀ (or Re ψ₀) per vertex, in the upload's numbering.
    - ``k``
    - ``method``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.
    - ``source``: Or a bump at this vertex (upload numbering).
    - ``steps``: Backward-Euler steps per time (`implicit`).
    - ``times``
    - ``width``: The bump's width w (default: 5 % of the bounding box's diagonal).

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("diffuse", s, faces, threads=threads, progress=progress, **options)


def dirichlet_energy(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """½ uᵀLu, uᵀMu and the Rayleigh quotient of a function.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact (discrete)

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``DirichletEnergyAnalysis``, ``kac dirichlet-energy --help``):

    - ``function``: u per vertex (upload numbering); absent: the vertex coordinates, one energy each.
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("dirichlet-energy", s, faces, threads=threads, progress=progress, **options)


def gradient(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """the gradient of a per-vertex function on each triangle or tetrahedron.

    Applies to: triangle_mesh, tet_mesh. Accuracy: exact for linear functions

    Options (the service's ``GradientAnalysis``, ``kac gradient --help``):

    - ``function``: u per vertex (upload numbering).

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("gradient", s, faces, threads=threads, progress=progress, **options)


def divergence(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """the divergence of a per-element vector field per vertex (integrated and pointwise).

    Applies to: triangle_mesh, tet_mesh. Accuracy: exact (discrete)

    Options (the service's ``DivergenceAnalysis``, ``kac divergence --help``):

    - ``field``: One vector [x, y, z] per element of the validated mesh, in its order (as `gradient` returns them).
    - ``mass``

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("divergence", s, faces, threads=threads, progress=progress, **options)


def embed(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """Laplacian eigenmap / GPS coordinates, Fiedler vector and bisection.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact (discrete)

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``EmbedAnalysis``, ``kac embed --help``):

    - ``dimensions``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``scaling``
    - ``solver``: Its fields may be given directly: block, method, sigma, slices, subspace, tol, verify.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("embed", s, faces, threads=threads, progress=progress, **options)


def smooth(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """(M + αL) u = M ū: implicit fairing of the coordinates or of a function.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact (discrete)

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``SmoothAnalysis``, ``kac smooth --help``):

    - ``alpha``
    - ``fixed_boundary``: Keep ū on the shape's boundary (reproduces linear functions on flat meshes).
    - ``function``
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("smooth", s, faces, threads=threads, progress=progress, **options)


def interpolate(
    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """harmonic interpolation of values, or semi-supervised labels.

    Applies to: triangle_mesh, tet_mesh, cloud_r3, cloud_rn, graph, polyline. Accuracy: exact (discrete)

    Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues
    ascending, eigenvectors M-orthonormal.

    Options (the service's ``InterpolateAnalysis``, ``kac interpolate --help``):

    - ``labels``: [vertex, class] pairs (instead of values).
    - ``operator``: Its fields may be given directly: boundary, denoise, dirichlet_vertices, intrinsic_dimension,
      mass, midpoints, neighbourhood, neighbours, normalization, operator, order, radius, time.
    - ``values``: [vertex, value] pairs.

    Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices).
    """
    return analyze("interpolate", s, faces, threads=threads, progress=progress, **options)


__all__ = ["hks", "si_hks", "wks", "gps", "shape_dna", "fingerprint", "heat", "geodesic", "trees", "mean_curvature", "heat_curvature", "wave", "schrodinger", "poisson", "diffuse", "dirichlet_energy", "gradient", "divergence", "embed", "smooth", "interpolate"]
