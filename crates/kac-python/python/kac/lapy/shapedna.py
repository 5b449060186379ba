"""lapy.shapedna on kac: ``compute_shapedna``, ``normalize_ev``, ``reweight_ev`` and ``compute_distance`` with
lapy's signatures and results."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import Solver, TetMesh, TriaMesh

__all__ = ["compute_shapedna", "normalize_ev", "reweight_ev", "compute_distance"]


def compute_shapedna(
    geom: Any, k: int = 50, lump: bool = False, aniso: Any = None, aniso_smooth: int = 10, use_cholmod: bool = False
) -> dict:
    fem = Solver(geom, lump=lump, aniso=aniso, aniso_smooth=aniso_smooth, use_cholmod=use_cholmod)
    evals, evecs = fem.eigs(k=k)
    return {
        "Refine": 0,
        "Degree": 1,
        "Dimension": 2 if isinstance(geom, TriaMesh) else 3,
        "Elements": len(geom.t),
        "DoF": len(geom.v),
        "NumEW": k,
        "Eigenvalues": evals,
        "Eigenvectors": evecs,
    }

def normalize_ev(geom: Any, evals: np.ndarray, method: str = "geometry") -> np.ndarray:
    def positive(value: float, name: str) -> float:
        if value <= 0:
            raise ValueError(f"{name} must be positive for normalization")
        return value

    def boundary_volume() -> float:
        bnd = geom.boundary_tria()
        return positive(bnd.volume(), "boundary volume")

    if method == "surface":
        return evals * positive(geom.area(), "area")
    if method == "volume":
        if isinstance(geom, TriaMesh):
            return evals * positive(geom.volume(), "volume") ** (2.0 / 3.0)
        if isinstance(geom, TetMesh):
            return evals * boundary_volume() ** (2.0 / 3.0)
        raise ValueError("Unsupported geometry type for volume normalization")
    if method == "geometry":
        if isinstance(geom, TriaMesh):
            return evals * positive(geom.area(), "area")
        if isinstance(geom, TetMesh):
            return evals * boundary_volume() ** (2.0 / 3.0)
        raise ValueError("Unsupported geometry type for geometry normalization")
    raise ValueError(f"Unknown normalization method: {method}")

def reweight_ev(evals: np.ndarray) -> np.ndarray:
    return evals / np.arange(1, len(evals) + 1)

def compute_distance(ev1: np.ndarray, ev2: np.ndarray, dist: str = "euc") -> float:
    if dist != "euc":
        raise ValueError(f"Distance metric {dist} is not implemented.")
    return float(np.linalg.norm(np.asarray(ev1) - np.asarray(ev2)))
