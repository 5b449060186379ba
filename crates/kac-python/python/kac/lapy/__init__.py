"""lapy's API on kac: ``TriaMesh``, ``TetMesh``, ``Solver`` and ``shapedna``, with lapy's signatures and results,
so that a lapy script runs with only its import changed (``from kac.lapy import TriaMesh, Solver`` or
``import kac.lapy as lapy``).

The matrices are the same (P1 finite elements: cotan stiffness, consistent or lumped mass; linear tetrahedra) and
the eigenpairs are the k smallest of L φ = λ M φ, ascending, M-orthonormal, computed by kac's solver, which checks
by Sylvester's inertia that none was missed. What differs (docs/python.md):

- kac validates the mesh first. A mesh lapy takes silently may be refused with a :class:`kac.KacError` naming the
  element and the rule (a face with an index out of range, a non-finite coordinate, a degenerate triangle whose
  cotangent is infinite: lapy's matrices then hold inf or NaN). Free vertices are kept (their rows are empty, as
  in lapy's matrices) and nothing is welded.
- ``aniso`` (curvature-anisotropic Laplace) is not implemented: ``Solver(..., aniso=…)`` raises
  NotImplementedError. ``use_cholmod`` is accepted and ignored (kac's own LDLᵀ factorization is used either way).
- ``Solver.eigs`` computes the k smallest eigenpairs: ``sigma`` at or below 0 with ``which="LM"`` (lapy's
  defaults) asks for exactly those; other values are refused rather than answered differently. ``v0`` and
  ``rng`` are accepted (kac's start is deterministic).
- Eigenvectors of a repeated eigenvalue span the same space as lapy's but may be another basis of it; each
  vector's sign is kac's (largest entry positive), not ARPACK's.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

import kac

__all__ = ["TriaMesh", "TetMesh", "Solver", "shapedna"]


class TriaMesh:
    """A triangle mesh: ``v`` (n × 3 float64) and ``t`` (m × 3 int, 0-based), as lapy's ``TriaMesh(v, t)``."""

    def __init__(self, v: Any, t: Any, fsinfo: Any = None) -> None:
        self.v = np.array(v, dtype=np.float64)
        self.t = np.array(t, dtype=np.int64)
        if self.v.ndim != 2 or self.t.ndim != 2 or self.t.shape[1] != 3:
            raise ValueError("TriaMesh takes vertices n × 3 (or n × 2) and triangles m × 3")
        if self.v.shape[1] == 2:
            self.v = np.column_stack([self.v, np.zeros(len(self.v))])
        self.fsinfo = fsinfo

    @classmethod
    def read_off(cls, filename: str) -> "TriaMesh":
        s = kac.read(filename, "off", weld="none")
        return cls(s.vertices, s.faces)

    @classmethod
    def read_vtk(cls, filename: str) -> "TriaMesh":
        s = kac.read(filename, "vtk", weld="none")
        return cls(s.vertices, s.faces)

    def _shape(self) -> "kac.Shape":
        return kac.shape(self.v, self.t, weld="none", keep_degenerate=True)

    def tria_areas(self) -> np.ndarray:
        a, b, c = self.v[self.t[:, 0]], self.v[self.t[:, 1]], self.v[self.t[:, 2]]
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    def area(self) -> float:
        return float(self.tria_areas().sum())

    def volume(self) -> float:
        """The enclosed volume (0 for an open mesh; lapy's: the mesh must be closed and oriented)."""
        if not self.is_closed():
            return 0.0
        a, b, c = self.v[self.t[:, 0]], self.v[self.t[:, 1]], self.v[self.t[:, 2]]
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    def _edges(self) -> np.ndarray:
        e = np.concatenate([self.t[:, [0, 1]], self.t[:, [1, 2]], self.t[:, [2, 0]]])
        return e

    def is_closed(self) -> bool:
        e = np.sort(self._edges(), axis=1)
        _, counts = np.unique(e, axis=0, return_counts=True)
        return bool(np.all(counts == 2))

    def is_oriented(self) -> bool:
        _, counts = np.unique(self._edges(), axis=0, return_counts=True)
        return bool(np.all(counts == 1))

    def euler(self) -> int:
        e = np.unique(np.sort(self._edges(), axis=1), axis=0)
        used = np.unique(self.t)
        return int(len(used) - len(e) + len(self.t))

    def vertex_areas(self) -> np.ndarray:
        areas = self.tria_areas() / 3.0
        out = np.zeros(len(self.v))
        for j in range(3):
            np.add.at(out, self.t[:, j], areas)
        return out


class TetMesh:
    """A tetrahedral mesh: ``v`` (n × 3) and ``t`` (m × 4, 0-based), as lapy's ``TetMesh(v, t)``."""

    def __init__(self, v: Any, t: Any) -> None:
        self.v = np.array(v, dtype=np.float64)
        self.t = np.array(t, dtype=np.int64)
        if self.v.ndim != 2 or self.v.shape[1] != 3 or self.t.ndim != 2 or self.t.shape[1] != 4:
            raise ValueError("TetMesh takes vertices n × 3 and tetrahedra m × 4")

    @classmethod
    def read_vtk(cls, filename: str) -> "TetMesh":
        s = kac.read(filename, "vtk", weld="none")
        return cls(s.vertices, s.tets)

    @classmethod
    def read_gmsh(cls, filename: str) -> "TetMesh":
        s = kac.read(filename, "msh", weld="none")
        return cls(s.vertices, s.tets)

    def _shape(self) -> "kac.Shape":
        return kac.shape(self.v, tets=self.t, weld="none", keep_degenerate=True)

    def boundary_tria(self, tetfunc: Optional[np.ndarray] = None) -> TriaMesh:
        """The boundary surface, its faces oriented outward."""
        v, t = self.v, self.t.copy()
        vol = np.einsum("ij,ij->i", v[t[:, 1]] - v[t[:, 0]], np.cross(v[t[:, 2]] - v[t[:, 0]], v[t[:, 3]] - v[t[:, 0]]))
        t[vol < 0] = t[vol < 0][:, [0, 2, 1, 3]]
        # The faces of a positively oriented tetrahedron (a, b, c, d), each seen from outside.
        faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 3, 2]], t[:, [0, 1, 3]], t[:, [0, 2, 1]]])
        key = np.sort(faces, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return TriaMesh(v, faces[counts[inverse.ravel()] == 1])

    def avg_edge_length(self) -> float:
        t = self.t
        e = np.concatenate([t[:, [0, 1]], t[:, [0, 2]], t[:, [0, 3]], t[:, [1, 2]], t[:, [1, 3]], t[:, [2, 3]]])
        e = np.unique(np.sort(e, axis=1), axis=0)
        return float(np.linalg.norm(self.v[e[:, 0]] - self.v[e[:, 1]], axis=1).mean())


class Solver:
    """lapy's FEM solver: ``stiffness`` (A) and ``mass`` (B) as SciPy sparse matrices, built at construction, and
    ``eigs`` for the smallest eigenpairs of A φ = λ B φ."""

    def __init__(
        self,
        geometry: Any,
        lump: bool = False,
        aniso: Any = None,
        aniso_smooth: int = 10,
        use_cholmod: bool = False,
        dtype: Any = np.float64,
    ) -> None:
        if aniso is not None:
            raise NotImplementedError("kac.lapy.Solver: the anisotropic Laplace (aniso) is not implemented")
        if np.dtype(dtype) != np.float64:
            raise NotImplementedError("kac.lapy.Solver: kac computes in float64 only")
        if not isinstance(geometry, (TriaMesh, TetMesh)):
            raise ValueError(f'Geometry type "{type(geometry).__name__}" unknown')
        self._shape = geometry._shape()
        self._mass = "lumped" if lump else "consistent"
        self.stiffness, self.mass = (m.tocsc() for m in kac.operator(self._shape, mass=self._mass))
        self.geotype = type(geometry)
        self.use_cholmod = use_cholmod

    def eigs(
        self,
        k: int = 10,
        sigma: float = -0.01,
        which: str = "LM",
        v0: Optional[np.ndarray] = None,
        mode: str = "normal",
        rng: Any = None,
    ) -> tuple:
        """The k smallest eigenvalues (ascending, (k,)) and their eigenvectors (n × k, B-orthonormal)."""
        if sigma > 0 or which != "LM" or mode != "normal":
            raise NotImplementedError(
                "kac.lapy.Solver.eigs computes the k smallest eigenpairs: sigma ≤ 0 with which='LM', mode='normal'"
            )
        values, vectors = kac.spectrum(self._shape, k=k, mass=self._mass)
        return values, vectors


from . import shapedna  # noqa: E402
