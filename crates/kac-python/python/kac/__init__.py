"""kac: can you hear the shape of a drum? Spectral shape analysis, NumPy in and out.

The library of the kac service, in process: read and validate shapes, build Laplace operators, compute the k
smallest eigenpairs of L φ = λ M φ, and run every analysis of the registry (heat kernel and diffusion, HKS, SI-HKS,
WKS, GPS, shape-DNA, Weyl estimates, geodesics, curvature, PDEs, correspondence), with the same requests, option
names and defaults as the CLI (``kac hks --help``) and the service (``POST /v1/jobs``).

Sign convention (one everywhere): Δ = −∇·∇ is positive semidefinite and L is its weak form (the stiffness matrix,
L ⪰ 0; libigl's ``cotmatrix`` is −L). The eigenproblem is L φ = λ M φ with M the mass matrix; eigenvalues ascend
and eigenvectors are M-orthonormal (φᵀ M φ = I). The heat equation is ∂u/∂t = −Δu.

Every computation releases the GIL; Ctrl-C (KeyboardInterrupt) stops it within a fraction of a second; a
``progress`` callable, when given, is called as ``progress(phase, converged, wanted)``. Failures and refusals
raise :class:`KacError` with kac's stable ``code`` (the service's problem codes).

``kac.lapy`` keeps lapy's API (``TriaMesh``, ``TetMesh``, ``Solver``, ``shapedna``); ``kac.Client`` talks to a
kac service over HTTP.
"""

from . import _kac
from ._analyses import *  # noqa: F401,F403  (one function per analysis of the registry)
from ._analyses import __all__ as _analysis_names
from ._core import (
    KacError,
    Result,
    Shape,
    analyses,
    analyze,
    codes,
    compare,
    correspondence,
    operator,
    read,
    shape,
    spectrum,
)
from .client import Client

__version__: str = _kac.__version__

__all__ = [
    "KacError",
    "Shape",
    "Result",
    "read",
    "shape",
    "spectrum",
    "operator",
    "analyze",
    "correspondence",
    "compare",
    "analyses",
    "codes",
    "Client",
    *_analysis_names,
]
