"""Planar frame finite elements: the beam element and the assembly of a frame model.

:mod:`analysis.fe.beam` holds the 2-D Euler-Bernoulli frame element (3 DOFs per node:
``u_x, u_y, r_z``) and the section properties; :mod:`analysis.fe.assembly` the frame
description, the mesh and the assembly into affine mass and stiffness forms with exact
parameter derivatives.
"""

from __future__ import annotations

from .assembly import (
    DIRECTIONS,
    FrameSpec,
    Joint,
    LinearStructure,
    LumpedMass,
    Material,
    Member,
    SpecError,
    Spring,
    build_structure,
    mesh_members,
)
from .beam import Section, mass_matrix, rotation_matrix, stiffness_matrix

__all__ = [
    "DIRECTIONS",
    "FrameSpec",
    "Joint",
    "LinearStructure",
    "LumpedMass",
    "Material",
    "Member",
    "Section",
    "SpecError",
    "Spring",
    "build_structure",
    "mass_matrix",
    "mesh_members",
    "rotation_matrix",
    "stiffness_matrix",
]
