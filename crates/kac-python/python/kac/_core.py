"""The library's functions: shapes, spectra, operators, and any analysis of the registry by name."""


from __future__ import annotations

import json
import re
from typing import Any, Callable, Optional, Union

import numpy as np

from . import _kac
from ._kac import KacError
from ._kac import ValidatedShape as Shape

Progress = Optional[Callable[[str, int, int], Any]]
ShapeLike = Union[Shape, np.ndarray]


def read(path: str, format: Optional[str] = None, *, weld: str = "exact", keep_degenerate: bool = False) -> Shape:
    """Read and validate a shape file (OBJ, OFF, PLY, STL, glTF/GLB, Medit, Gmsh, VTK, XYZ/CSV, JSON).

    ``weld``: ``"exact"`` merges duplicate vertices (the default, as the CLI and the service do), ``"none"`` keeps
    them, a number merges within that distance. The returned :class:`Shape` has ``vertices`` (n × 3 float64),
    ``faces`` / ``tets`` / ``edges`` (int64, or None), ``kind``, ``id``, ``report`` (the validation report) and
    ``vertex_map`` (each input vertex's row, -1 where dropped).
    """
    return _kac.read(str(path), format, weld, keep_degenerate)


def shape(
    vertices: Any,
    faces: Any = None,
    *,
    tets: Any = None,
    edges: Any = None,
    weights: Any = None,
    graph: bool = False,
    weld: str = "none",
    keep_degenerate: bool = False,
) -> Shape:
    """A validated shape from arrays: ``vertices`` (n × 3; n × 2 is planar; n × d, d ≥ 4, a point cloud in Rᵈ)
    and at most one of ``faces`` (m × 3), ``tets`` (m × 4), ``edges`` (m × 2, a polyline, or a graph with
    ``graph=True`` or ``weights``); none: a point cloud. Indices are 0-based. Without welding (the default here)
    every row of the result's per-vertex arrays is the caller's vertex."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    if v.ndim != 2:
        raise _error("invalid-request", f"vertices must be a 2-D array, not {v.ndim}-D")

    def idx(a: Any) -> Optional[np.ndarray]:
        return None if a is None else np.ascontiguousarray(a, dtype=np.int64)

    w = None if weights is None else np.ascontiguousarray(weights, dtype=np.float64)
    return _kac.from_arrays(v, idx(faces), idx(tets), idx(edges), w, graph, weld, keep_degenerate)


def _error(code: str, detail: str) -> KacError:
    """A KacError raised by the Python half, with the same attributes as the native ones."""
    e = KacError(f"{code}: {detail}")
    e.code = code  # type: ignore[attr-defined]
    e.detail = detail  # type: ignore[attr-defined]
    e.extra = None  # type: ignore[attr-defined]
    return e


def _as_shape(s: ShapeLike, faces: Any = None) -> Shape:
    if isinstance(s, Shape):
        if faces is not None:
            raise _error("invalid-request", "faces are given with the shape already built")
        return s
    return shape(s, faces)


class Result(dict):  # type: ignore[type-arg]
    """An analysis' result: the summary's fields (as the CLI prints them) and ``arrays``, a dict of NumPy arrays
    (rows in the input's vertex numbering), with ``columns`` naming what each array's columns are (times, energies,
    eigenvalues) where they are numbers. Fields and arrays are also attributes (``r.eigenvalues``)."""

    arrays: dict
    columns: dict

    def __getattr__(self, name: str) -> Any:
        arrays = self.__dict__.get("arrays", {})
        if name in arrays:
            return arrays[name]
        if name in self:
            return self[name]
        raise AttributeError(name)


def _result(out: tuple) -> Result:
    summary, arrays = out
    r = Result(json.loads(summary))
    r.arrays = {name: a for name, a, _ in arrays}
    r.columns = {name: (None if c is None else np.asarray(c)) for name, _, c in arrays}
    return r


_DOC: Optional[dict] = None


def _schemas() -> dict:
    global _DOC
    if _DOC is None:
        _DOC = json.loads(_kac.openapi())
    return _DOC["components"]["schemas"]


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in re.split(r"[-_]", name))


def _resolve(schema: dict) -> dict:
    ref = schema.get("$ref")
    if ref is None:
        for alt in schema.get("oneOf", []) + schema.get("allOf", []):
            if "$ref" in alt:
                ref = alt["$ref"]
                break
    if ref is None:
        return schema
    return _schemas()[ref.rsplit("/", 1)[-1]]


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _route(schema_name: str, options: dict, fixed: dict) -> dict:
    """The request's JSON from keyword arguments: a field of the request goes at the top level; a field of one of
    its nested option objects (``options``, ``operator``, ``solver``) goes into that object, so that
    ``kac.hks(s, count=50, boundary="dirichlet", tol=1e-10)`` is ``{"options": {"count": 50}, "operator":
    {"boundary": "dirichlet"}, "solver": {"tol": 1e-10}}``. ``operator="robust"`` names the operator's kind; a dict
    gives a nested object whole. What no part of the request declares is refused with the names it takes."""
    schema = _schemas()[schema_name]
    props = schema.get("properties", {})
    nested = {
        key: set(_resolve(p).get("properties", {}))
        for key, p in props.items()
        if _resolve(p).get("type") == "object" and _resolve(p).get("properties")
    }
    request: dict = dict(fixed)
    for key, value in options.items():
        value = _plain(value)
        if key in nested and not isinstance(value, dict):
            # `operator="cotan"`: the kind inside the operator object.
            if key in nested[key]:
                request.setdefault(key, {})[key] = value
                continue
        if key in props:
            if key in nested and isinstance(value, dict):
                request.setdefault(key, {}).update(value)
            else:
                request[key] = value
            continue
        owners = [n for n in ("options", "operator", "solver") if n in nested and key in nested[n]]
        owners += [n for n in nested if key in nested[n] and n not in owners]
        if not owners:
            accepted = sorted(set(props) | set().union(*nested.values()) if nested else set(props))
            raise _error(
                "invalid-request",
                f"{key!r} is not an option of this request; it takes: {', '.join(a for a in accepted if a != 'analysis')}",
            )
        request.setdefault(owners[0], {})[key] = value
    return request


def analyze(
    name: str, s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """Runs the analysis ``name`` of the registry (``kac.analyses()``) on a shape (a :class:`Shape`, or vertices
    with ``faces``), with its options as keyword arguments (the CLI's and the service's names and defaults)."""
    schema = f"{_camel(name)}Analysis"
    if schema not in _schemas():
        raise _error("invalid-request", f"no analysis {name!r}; one of: {', '.join(a['name'] for a in analyses())}")
    request = _route(schema, options, {"analysis": name})
    return _result(_kac.run(_as_shape(s, faces), json.dumps(request), threads, progress))


def spectrum(
    s: ShapeLike,
    faces: Any = None,
    k: int = 10,
    *,
    threads: int = 0,
    progress: Progress = None,
    report: bool = False,
    **options: Any,
) -> Any:
    """The k smallest eigenpairs of L φ = λ M φ: ``(eigenvalues, eigenvectors)``, eigenvalues ascending (k,),
    eigenvectors n × k (rows: the input's vertices), M-orthonormal. Complete: Sylvester's inertia checks that no
    eigenvalue below the last was missed, or the call fails with ``incomplete-spectrum``. Options as
    ``kac spectrum`` takes them: ``operator`` (cotan, robust, …), ``mass`` (consistent, lumped, voronoi),
    ``boundary`` (neumann, dirichlet), ``order`` (1, 2), ``tol``, ``band``, …. With ``report=True`` the solver's
    report (residuals, completeness, timings, warnings) comes third."""
    r = analyze("spectrum", s, faces, threads=threads, progress=progress, k=k, eigenvectors=True, **options)
    values = np.asarray(r["eigenvalues"], dtype=np.float64)
    vectors = r.arrays.get("eigenvectors")
    if report:
        return values, vectors, r
    return values, vectors


def operator(s: ShapeLike, faces: Any = None, *, threads: int = 0, **options: Any) -> tuple:
    """The operator's matrices ``(L, M)`` as ``scipy.sparse.csr_matrix`` (SciPy needed), rows and columns in the
    input's vertex numbering for order 1 (unknowns of dropped vertices are empty rows); for order 2 in the
    operator's unknowns (vertices, then edges). L is positive semidefinite (Δ = −∇·∇)."""
    try:
        import scipy.sparse as sp
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("kac.operator returns SciPy matrices: pip install scipy") from e
    shape_ = _as_shape(s, faces)
    r = analyze("operator", shape_, threads=threads, matrices=True, report=False, **options)
    unknowns = r.arrays["unknown_vertices"].astype(np.int64)
    order1 = unknowns.shape[1] == 1
    n = shape_.input_vertices if order1 else len(unknowns)
    index = unknowns[:, 0] if order1 else np.arange(len(unknowns))

    def full(name: str) -> Any:
        t = r.arrays[name]
        rows, cols, vals = index[t[:, 0].astype(np.int64)], index[t[:, 1].astype(np.int64)], t[:, 2]
        off = rows != cols
        a = sp.coo_matrix(
            (np.concatenate([vals, vals[off]]), (np.concatenate([rows, cols[off]]), np.concatenate([cols, rows[off]]))),
            shape=(n, n),
        )
        return a.tocsr()

    return full("stiffness"), full("mass")


def correspondence(
    source: ShapeLike, target: ShapeLike, *, threads: int = 0, progress: Progress = None, **options: Any
) -> Result:
    """Which vertex of ``target`` each vertex of ``source`` is (functional maps refined by ZoomOut): the result's
    ``source_to_target`` is an int array (n_source,), ``target_to_source`` the other way, with the costs and the
    summary (map quality, warnings). Options as ``kac correspondence`` takes them (fit_k, refine_k, landmarks,
    partial, …)."""
    request = _route("CorrespondenceRequest", options, {})
    request.pop("source_id", None)
    request.pop("target_id", None)
    r = _result(_kac.correspond(_as_shape(source), _as_shape(target), json.dumps(request), threads, progress))
    for name in ("source_to_target", "target_to_source"):
        if name in r.arrays:
            r.arrays[name] = r.arrays[name][:, 0].astype(np.int64)
    return r


def compare(shapes: list, *, threads: int = 0, progress: Progress = None, **options: Any) -> Result:
    """Distances between shapes by their fingerprints (as ``POST /v1/compare``; ``descriptor="fused"`` by default, or
    one family: ``"shape-dna"``, ``"heat-distribution"``, ``"gps-d2"``): ``distances`` (a matrix, in the order
    given), each family's in ``families``, each shape's ``nearest``, and ``failures`` (the shapes that could not be
    fingerprinted, with their codes)."""
    request = _route("CompareRequest", options, {})
    request.pop("shape_ids", None)
    built = [_as_shape(s) for s in shapes]
    r = _result(_kac.compare(built, json.dumps(request), threads, progress))
    # A failure's `status` is the service's HTTP status for its code; in process there is none, and its `code`
    # says what happened.
    for f in r.get("failures", []):
        f.pop("status", None)
    return r


def analyses() -> list:
    """The registry: every analysis with the shape classes, boundary conditions and orders it supports."""
    return json.loads(_kac.analyses())["analyses"]


def codes() -> dict:
    """Every stable problem code with its description (a :class:`KacError`'s ``code`` is one of them)."""
    return dict(_kac.codes())
