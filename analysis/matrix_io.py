"""Import and export of linear mass, stiffness (and damping) matrices with their DOF map.

Formats
-------
``npz``
    One NumPy archive with arrays ``M``, ``K``, optional ``C``, ``dofs`` (labels
    ``"node/direction"``) and optional ``node_names`` / ``node_xy``.
``mat``
    One MATLAB file (``scipy.io.savemat``) with the same variables; sparse matrices are accepted
    on import.
``mtx``
    MatrixMarket files beside each other: for ``path = "dir/rig.mtx"`` the files
    ``dir/rig.M.mtx``, ``dir/rig.K.mtx``, optional ``dir/rig.C.mtx`` and the DOF map
    ``dir/rig.dofs.json`` (or ``.csv``). Files with other names are imported from a mapping
    ``{"M": ..., "K": ..., "C": ..., "dof_map": ...}``.

A DOF map is a list of labels ``"node/direction"`` (direction one of ``x, y, z, rx, ry, rz``);
as JSON either that list or ``{"dofs": [...], "node_xy": {node: [x, y]}}``, as CSV two
columns ``node,direction`` with that header.
"""

from __future__ import annotations

import csv
import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
import scipy.sparse

__all__ = [
    "FORMATS",
    "LinearPart",
    "dof_label",
    "export_linear",
    "import_linear",
    "parse_dof_label",
    "read_dof_map",
    "write_dof_map",
]

log = logging.getLogger(__name__)

FORMATS = ("npz", "mtx", "mat")
IMPORT_DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
Dof = tuple[str, str]


def dof_label(node: str, direction: str) -> str:
    """``"node/direction"``."""
    return f"{node}/{direction}"


def parse_dof_label(label: str) -> Dof:
    """Split ``"node/direction"`` (the last ``/`` separates) and check the direction."""
    node, sep, direction = str(label).strip().rpartition("/")
    if not sep or not node or direction not in IMPORT_DIRECTIONS:
        raise ValueError(
            f"bad DOF label {label!r}: expected 'node/direction' with direction in "
            f"{IMPORT_DIRECTIONS}"
        )
    return node, direction


@dataclass(frozen=True)
class LinearPart:
    """Linear matrices over labelled DOFs.

    Attributes
    ----------
    M, K : ndarray, shape (n, n)
        Mass [kg] and stiffness [N/m] (rotational DOFs in the consistent units).
    C : ndarray, shape (n, n) or None
        Viscous damping [N s/m], if provided.
    dofs : tuple of (node, direction), length n
    node_xy : dict
        Node coordinates [m] where known.
    """

    M: np.ndarray
    K: np.ndarray
    C: np.ndarray | None
    dofs: tuple[Dof, ...]
    node_xy: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.dofs)
        if len(set(self.dofs)) != n:
            raise ValueError("dofs: duplicate DOF labels")
        for name in ("M", "K", "C"):
            a = getattr(self, name)
            if a is None:
                continue
            a = np.array(a, dtype=float)
            if a.shape != (n, n):
                raise ValueError(f"{name}: shape {a.shape} does not match {n} DOFs")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name}: contains non-finite entries")
            scale = max(float(np.abs(a).max()), np.finfo(float).tiny)
            if np.abs(a - a.T).max() > 1e-9 * scale:
                raise ValueError(f"{name}: matrix is not symmetric")
            a = 0.5 * (a + a.T)
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "dofs", tuple((str(n_), str(d)) for n_, d in self.dofs))


def _infer_format(path: Path, fmt: str | None) -> str:
    fmt = fmt or path.suffix.lstrip(".").lower()
    if fmt not in FORMATS:
        raise ValueError(f"format: unknown matrix format {fmt!r} for {path}; expected {FORMATS}")
    return fmt


def _mtx_stem(path: Path) -> Path:
    return path.with_suffix("") if path.suffix.lower() == ".mtx" else path


def _as_part(source: Any) -> LinearPart:
    if isinstance(source, LinearPart):
        return source
    if hasattr(source, "assemble"):
        source = source.assemble()
    return LinearPart(
        M=source.M, K=source.K, C=source.C, dofs=source.dofs, node_xy=dict(source.node_xy)
    )


def write_dof_map(
    path: str | Path, dofs: tuple[Dof, ...], node_xy: Mapping[str, tuple[float, float]] = {}
) -> None:
    """Write a DOF map as JSON (``.json``, with node coordinates) or CSV (``.csv``)."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["node", "direction"])
            writer.writerows(dofs)
        return
    used = {n for n, _ in dofs}
    doc = {
        "dofs": [dof_label(*d) for d in dofs],
        "node_xy": {n: list(xy) for n, xy in node_xy.items() if n in used},
    }
    path.write_text(json.dumps(doc, indent=1))


def read_dof_map(path: str | Path) -> tuple[tuple[Dof, ...], dict[str, tuple[float, float]]]:
    """Read a DOF map written by :func:`write_dof_map` (or by hand; see the module notes)."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
        if rows and not {"node", "direction"} <= set(rows[0]):
            raise ValueError(f"{path}: a CSV DOF map needs the columns 'node' and 'direction'")
        dofs = tuple(parse_dof_label(f"{r['node']}/{r['direction']}") for r in rows)
        return dofs, {}
    doc = json.loads(path.read_text())
    labels = doc["dofs"] if isinstance(doc, dict) else doc
    dofs = tuple(
        parse_dof_label(lab if isinstance(lab, str) else "/".join(map(str, lab))) for lab in labels
    )
    xy = doc.get("node_xy", {}) if isinstance(doc, dict) else {}
    return dofs, {str(n): (float(v[0]), float(v[1])) for n, v in xy.items()}


def export_linear(source: Any, path: str | Path, format: str | None = None) -> list[Path]:
    """Write M, K (and C if any) with the DOF map.

    Parameters
    ----------
    source : Model, Assembly or LinearPart
        A model is assembled at its current parameter values.
    path : str or Path
        Target file (``.npz``, ``.mat``) or, for MatrixMarket, the common stem
        (``dir/rig.mtx`` writes ``dir/rig.M.mtx`` and so on).
    format : {"npz", "mtx", "mat"}, optional
        Inferred from the suffix of ``path`` if omitted.

    Returns
    -------
    list of Path
        The files written.
    """
    path = Path(path)
    fmt = _infer_format(path, format)
    part = _as_part(source)
    mats: dict[str, Any] = {"M": part.M, "K": part.K} | (
        {"C": part.C} if part.C is not None else {}
    )
    labels = np.array([dof_label(*d) for d in part.dofs])
    names = [n for n in part.node_xy if any(n == d[0] for d in part.dofs)]
    xy = np.array([part.node_xy[n] for n in names], dtype=float).reshape(-1, 2)
    if fmt == "npz":
        np.savez(path, **mats, dofs=labels, node_names=np.array(names, dtype=str), node_xy=xy)
        written = [path if path.suffix == ".npz" else path.with_name(path.name + ".npz")]
    elif fmt == "mat":
        extra = {"node_names": np.array(names, dtype=object), "node_xy": xy} if names else {}
        scipy.io.savemat(path, {**mats, "dofs": np.array(list(labels), dtype=object), **extra})
        written = [path]
    else:
        stem = _mtx_stem(path)
        written = []
        for name, a in mats.items():
            target = stem.with_name(f"{stem.name}.{name}.mtx")
            scipy.io.mmwrite(target, scipy.sparse.coo_matrix(a), precision=17)
            written.append(target)
        target = stem.with_name(f"{stem.name}.dofs.json")
        write_dof_map(target, part.dofs, part.node_xy)
        written.append(target)
    log.info("exported %d DOFs as %s: %s", len(part.dofs), fmt, [str(p) for p in written])
    return written


def _dense(a: Any) -> np.ndarray:
    return a.toarray() if scipy.sparse.issparse(a) else np.asarray(a, dtype=float)


def _strings(a: Any) -> list[str]:
    out = []
    for item in np.asarray(a, dtype=object).ravel():
        while isinstance(item, np.ndarray):
            item = item.ravel()[0] if item.size else ""
        out.append(str(item).rstrip())
    return out


def _load_archive(path: Path, fmt: str) -> dict[str, Any]:
    if fmt == "npz":
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    return {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}


def _archive_dofs(data: Mapping[str, Any]) -> tuple[tuple[Dof, ...], dict]:
    dofs = tuple(parse_dof_label(s) for s in _strings(data["dofs"]))
    node_xy = {}
    if "node_names" in data and "node_xy" in data:
        coords = np.asarray(data["node_xy"], dtype=float).reshape(-1, 2).tolist()
        node_xy = {n: tuple(c) for n, c in zip(_strings(data["node_names"]), coords, strict=True)}
    return dofs, node_xy


def import_linear(
    path: str | Path | Mapping[str, str | Path],
    format: str | None = None,
    *,
    dof_map: str | Path | None = None,
    dofs: Sequence[str | Dof] | None = None,
) -> LinearPart:
    """Read matrices and DOF map written by :func:`export_linear` or another FE code.

    Parameters
    ----------
    path : str, Path or mapping
        The archive (``npz``, ``mat``), the MatrixMarket stem, or a mapping with keys ``M``,
        ``K``, optional ``C`` and ``dof_map`` naming MatrixMarket files.
    format : {"npz", "mtx", "mat"}, optional
        Inferred from the suffix if omitted (``mtx`` for a mapping).
    dof_map : str or Path, optional
        DOF map file (JSON or CSV), overriding the map in or beside the matrices.
    dofs : sequence of str or (node, direction), optional
        The DOF labels themselves, overriding any DOF map.

    Returns
    -------
    LinearPart
    """
    if isinstance(path, Mapping):
        files = {k: Path(v) for k, v in path.items()}
        fmt = format or "mtx"
        if fmt != "mtx":
            raise ValueError("format: a mapping of files is only used for 'mtx'")
    else:
        fmt = _infer_format(Path(path), format)
        stem = _mtx_stem(Path(path))
        files = {k: stem.with_name(f"{stem.name}.{k}.mtx") for k in ("M", "K", "C")}
        if fmt == "mtx":
            json_map = stem.with_name(f"{stem.name}.dofs.json")
            csv_map = stem.with_name(f"{stem.name}.dofs.csv")
            files["dof_map"] = csv_map if csv_map.exists() and not json_map.exists() else json_map
    if dof_map is not None:
        files["dof_map"] = Path(dof_map)
    if fmt == "mtx":
        data = {k: scipy.io.mmread(p) for k, p in files.items() if k in "MKC" and p.exists()}
    else:
        data = _load_archive(Path(path), fmt)
    for k in ("M", "K"):
        if k not in data:
            raise ValueError(f"{k}: matrix missing ({files.get(k, path)})")
    node_xy: dict[str, tuple[float, float]] = {}
    if dofs is not None:
        labels = tuple(parse_dof_label(d) if isinstance(d, str) else tuple(d) for d in dofs)
    elif "dof_map" in files:
        labels, node_xy = read_dof_map(files["dof_map"])
    elif "dofs" in data:
        labels, node_xy = _archive_dofs(data)
    else:
        raise ValueError(f"dof_map: {path} holds no 'dofs'; give a DOF map")
    C = _dense(data["C"]) if "C" in data else None
    return LinearPart(M=_dense(data["M"]), K=_dense(data["K"]), C=C, dofs=labels, node_xy=node_xy)
