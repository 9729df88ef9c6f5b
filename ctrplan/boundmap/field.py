"""The bound map as the planner reads it: a tensor grid over the map coordinates, interpolated
multilinearly.

Each node stores the friction bound of Ha, Fagogenis & Dupont 2019 (doi:10.1109/TRO.2018.2878906;
the largest tip deviation of the 2^(n-1) bounding friction solutions of Section III from the
standard model, as :func:`ctrplan.mechanics.evaluate_bound` computes it: tip position [m] and
tip angle [rad]), the translation-last bound (the clearance-only deviation left after a final
translation, Section V-B) and a validity flag. Nodes where the model raised, did not converge,
or found the standard model elastically unstable are invalid: a query that draws on one returns
``invalid_value`` (default +inf) and :meth:`BoundField.is_valid` is False there.

Queries are joint vectors; the field maps them to its coordinates
(:class:`~ctrplan.coordinates.MapCoordinates`: base rotations and translations relative
to tube 1, on which the bound depends) and interpolates there. Axes may be nonuniform
(:mod:`ctrplan.boundmap.axes`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_savez
from .interp import cell_corners, multilinear
from ..coordinates import MapCoordinates
from .identity import BoundMapMismatchError

__all__ = ["QUANTITIES", "UNITS", "BoundField"]

# Stored per-node quantities, in this order, with units.
QUANTITIES = ("position", "angle", "translation_last_position", "translation_last_angle")
#: Unit of each stored quantity.
UNITS = {"position": "m", "angle": "rad", "translation_last_position": "m", "translation_last_angle": "rad"}

# Interpolation weights at or below this do not count when deciding whether an invalid node
# contaminates a query (a query exactly on a valid node is valid).
_WEIGHT_EPS = 1e-12

# Version of the .npz layout written by BoundField.save.
NPZ_FORMAT_VERSION = 2


def coordinates_from_dict(d: dict) -> MapCoordinates:
    """Inverse of :meth:`MapCoordinates.as_dict`."""
    return MapCoordinates(names=tuple(d["names"]), kinds=tuple(d["kinds"]), tubes=tuple(int(t) for t in d["tubes"]),
                          periodic=tuple(bool(p) for p in d["periodic"]), lower=tuple(d["lower"]),
                          upper=tuple(d["upper"]), matrix=np.asarray(d["matrix"], dtype=float).reshape(
                              len(d["names"]), -1),
                          offset=np.asarray(d["offset"], dtype=float), fixed_alpha=np.asarray(d["fixed_alpha"]),
                          fixed_beta=np.asarray(d["fixed_beta"]), home_alpha_1=float(d["home_alpha_1"]),
                          home_beta_1=float(d["home_beta_1"]))


class BoundField:
    """Friction bound on a tensor grid over the map coordinates, interpolated multilinearly.

    Parameters
    ----------
    axes : list of ndarray, shape (n_k,)
        Node coordinates of each map coordinate, increasing [rad or m]; periodic ones uniform,
        ``a_0 + 2 pi j / n_k``.
    periodic : sequence of bool, shape (d,)
    values : ndarray, shape (n_1, ..., n_d, 4)
        Per node, the quantities of :data:`QUANTITIES` [m, rad]; NaN at invalid nodes.
    valid : ndarray of bool, shape (n_1, ..., n_d)
    key : str
        :func:`~ctrplan.boundmap.identity.field_key` of the map.
    metadata : dict, optional
        Robot, joint names, spec, settings, evaluator, mechanics version, creation time ...
    coordinates : MapCoordinates, keyword-only, optional
        How joint vectors map to the grid; None: queries are map coordinates already.
    invalid_value : float, keyword-only
        Returned where an invalid node contributes (default +inf).

    Raises
    ------
    ValueError
        Inconsistent shapes, non-increasing axes, or a periodic axis that is not uniform.
    """

    def __init__(self, axes, periodic, values, valid, key: str, metadata: dict | None = None, *,
                 coordinates: MapCoordinates | None = None, invalid_value: float = float("inf")):
        self.axes = [np.asarray(a, dtype=float) for a in axes]
        self.periodic = np.asarray(periodic, dtype=bool)
        self.shape = tuple(len(a) for a in self.axes)
        self.values = np.asarray(values, dtype=float)
        self.valid = np.asarray(valid, dtype=bool)
        d = len(self.axes)
        if self.values.shape != self.shape + (len(QUANTITIES),) or self.valid.shape != self.shape:
            raise ValueError(f"values need shape {self.shape + (len(QUANTITIES),)} and valid {self.shape}, "
                             f"got {self.values.shape} and {self.valid.shape}")
        if self.periodic.shape != (d,):
            raise ValueError(f"periodic needs {d} flags, got {self.periodic.shape}")
        for k, a in enumerate(self.axes):
            if a.size < 2 or np.any(np.diff(a) <= 0.0):
                raise ValueError(f"axis {k} needs at least 2 increasing nodes, got {a}")
            if self.periodic[k] and not np.allclose(np.diff(a), 2.0 * np.pi / a.size, rtol=0.0, atol=1e-9):
                raise ValueError(f"periodic axis {k} must be uniform with spacing 2 pi / {a.size}")
        if coordinates is not None and coordinates.dim != d:
            raise ValueError(f"{d} axes but {coordinates.dim} map coordinates ({', '.join(coordinates.names)})")
        self.key = str(key)
        self.metadata = dict(metadata or {})
        self.coordinates = coordinates
        self.invalid_value = float(invalid_value)
        self._axes_flat = np.concatenate(self.axes)
        self._start = np.cumsum([0] + [a.size for a in self.axes[:-1]]).astype(np.int64)
        self._size = np.array(self.shape, dtype=np.int64)
        self._strides = np.array([int(np.prod(self.shape[j + 1:])) for j in range(d)], dtype=np.int64)
        self._flat_valid = np.ascontiguousarray(self.valid.reshape(-1))
        flat = self.values.reshape(-1, len(QUANTITIES))
        self._flat_values = np.ascontiguousarray(np.where(self._flat_valid[:, None], np.nan_to_num(flat), 0.0))

    @property
    def n_coordinates(self) -> int:
        """Number of map coordinates d."""
        return len(self.axes)

    @property
    def n_joints(self) -> int:
        """Length of the joint vectors the field takes."""
        return self.coordinates.matrix.shape[1] if self.coordinates is not None else len(self.axes)

    @property
    def coordinate_names(self) -> list[str]:
        return list(self.coordinates.names) if self.coordinates is not None else [f"u_{k + 1}" for k in
                                                                                range(len(self.axes))]

    # ------------------------------------------------------------------ interpolation
    def to_map(self, q) -> np.ndarray:
        """Map coordinates of joint vectors ``q`` (shape (m, n_joints)) -> (m, d)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[1] != self.n_joints:
            raise ValueError(f"queries need shape (m, {self.n_joints}), got {q.shape}")
        return q if self.coordinates is None else self.coordinates.from_joints(q)

    def interpolate(self, u, quantities=QUANTITIES):
        """Interpolate at map coordinates.

        Parameters
        ----------
        u : array-like, shape (m, d)
            Map coordinates [rad or m]; periodic ones may be unwrapped, others are clamped.
        quantities : sequence of str
            Any of :data:`QUANTITIES`.

        Returns
        -------
        values : ndarray, shape (m, len(quantities))
            [m or rad]; NaN where ``ok`` is False.
        ok : ndarray of bool, shape (m,)
            No invalid node carries weight.
        """
        u = np.ascontiguousarray(np.atleast_2d(np.asarray(u, dtype=float)))
        if u.shape[1] != len(self.axes):
            raise ValueError(f"map coordinates need shape (m, {len(self.axes)}), got {u.shape}")
        cols = np.array([QUANTITIES.index(q) for q in quantities], dtype=np.int64)
        out = np.empty((u.shape[0], cols.size))
        ok = np.empty(u.shape[0], dtype=np.bool_)
        multilinear(u, self._axes_flat, self._start, self._size, self.periodic, self._strides, self._flat_values,
                    self._flat_valid, cols, _WEIGHT_EPS, out, ok)
        out[~ok] = np.nan
        return out, ok

    def cell_weights(self, u) -> tuple[np.ndarray, np.ndarray]:
        """The nodes the interpolation at each point reads, and their weights.

        Parameters
        ----------
        u : array-like, shape (m, d)
            Map coordinates [rad or m] (periodic ones may be unwrapped, others are clamped).

        Returns
        -------
        index : ndarray of int, shape (m, 2^d)
            Flat (C-order) indices of the corners of each point's cell.
        weight : ndarray, shape (m, 2^d)
            Their multilinear weights (each row sums to 1); the interpolated value is
            ``sum(weight * values.reshape(-1, 4)[index], axis=1)`` where no invalid node has
            weight.
        """
        u = np.ascontiguousarray(np.atleast_2d(np.asarray(u, dtype=float)))
        if u.shape[1] != len(self.axes):
            raise ValueError(f"map coordinates need shape (m, {len(self.axes)}), got {u.shape}")
        d = len(self.axes)
        index = np.empty((u.shape[0], 1 << d), dtype=np.int64)
        weight = np.empty((u.shape[0], 1 << d))
        cell_corners(u, self._axes_flat, self._start, self._size, self.periodic, self._strides, index, weight)
        return index, weight

    def kernel_arrays(self, quantity: str = "position") -> tuple:
        """Arrays of the compiled interpolation of one quantity, for compiled callers:
        ``(matrix (d, n_joints), offset (d,), axes, start, size, periodic, strides, values, valid,
        column, eps)`` with the joint-to-map coordinates first (identity without ``coordinates``);
        the rest are what ``ctrplan.boundmap.interp.locate`` and ``corner_sum`` take besides
        the point and its cell."""
        if quantity not in QUANTITIES:
            raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
        d = len(self.axes)
        if self.coordinates is None:
            matrix, offset = np.eye(d), np.zeros(d)
        else:
            matrix, offset = self.coordinates.matrix, self.coordinates.offset
        return (np.ascontiguousarray(matrix, dtype=float), np.ascontiguousarray(offset, dtype=float),
                self._axes_flat, self._start, self._size, self.periodic, self._strides, self._flat_values,
                self._flat_valid, int(QUANTITIES.index(quantity)), _WEIGHT_EPS)

    def __call__(self, q, quantity: str = "position"):
        """Interpolated bound at joint vectors.

        Parameters
        ----------
        q : array-like, shape (n_joints,) or (m, n_joints)
            Joint vectors [rad or m] (map coordinates when the field has no ``coordinates``).
        quantity : str
            One of :data:`QUANTITIES`.

        Returns
        -------
        float or ndarray, shape (m,)
            [m] or [rad]; ``invalid_value`` where an invalid node contributes.

        Raises
        ------
        ValueError
            Unknown quantity or wrong query shape.
        """
        if quantity not in QUANTITIES:
            raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
        single = np.ndim(q) == 1
        vals, ok = self.interpolate(self.to_map(q), (quantity,))
        res = np.where(ok, vals[:, 0], self.invalid_value)
        return float(res[0]) if single else res

    def is_valid(self, q):
        """False where an invalid node contributes to the interpolation.

        Parameters
        ----------
        q : array-like, shape (n_joints,) or (m, n_joints)

        Returns
        -------
        bool or ndarray of bool, shape (m,)
        """
        single = np.ndim(q) == 1
        _, ok = self.interpolate(self.to_map(q), ("position",))
        return bool(ok[0]) if single else ok

    def nodes(self) -> np.ndarray:
        """All grid nodes in C order, shape (prod(shape), d) [map coordinates]."""
        mesh = np.meshgrid(*self.axes, indexing="ij")
        return np.stack([g.reshape(-1) for g in mesh], axis=1)

    # ------------------------------------------------------------------ persistence
    def save(self, path) -> Path:
        """Write the field to one compressed ``.npz`` (atomically, :func:`ctrplan.io.atomic_savez`;
        missing parent folders are created) with its key, coordinates and metadata (JSON).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {f"axis_{j}": a for j, a in enumerate(self.axes)}
        coords = json.dumps(self.coordinates.as_dict() if self.coordinates is not None else None)
        atomic_savez(path, key=np.array(self.key), periodic=self.periodic, values=self.values,
                     valid=self.valid, metadata=np.array(json.dumps(self.metadata, default=repr)),
                     coordinates=np.array(coords), format_version=np.array(NPZ_FORMAT_VERSION), **arrays)
        return path

    @classmethod
    def load(cls, path, key: str | None = None, **kwargs) -> "BoundField":
        """Read a field from an ``.npz`` written by :meth:`save`.

        (:func:`ctrplan.boundmap.load_bound_map` reads both ``.npz`` files and zarr stores.)

        Parameters
        ----------
        path : str or Path
        key : str, optional
            Expected key; a mismatch raises.
        **kwargs
            Passed to the constructor (``invalid_value``).

        Raises
        ------
        BoundMapMismatchError
            ``key`` is given and differs from the stored key, or the file is of an older format
            (a map computed by older code: recompute it).
        FileNotFoundError
        """
        with np.load(Path(path), allow_pickle=False) as z:
            version = int(z["format_version"]) if "format_version" in z else 1
            if version != NPZ_FORMAT_VERSION:
                raise BoundMapMismatchError(path, "format_version", version, NPZ_FORMAT_VERSION)
            stored = str(z["key"])
            if key is not None and stored != key:
                raise BoundMapMismatchError(path, "key", stored[:12] + "...", key[:12] + "...")
            d = int(z["periodic"].shape[0])
            axes = [z[f"axis_{j}"] for j in range(d)]
            cdict = json.loads(str(z["coordinates"]))
            coords = coordinates_from_dict(cdict) if cdict is not None else None
            return cls(axes, z["periodic"], z["values"], z["valid"], stored, json.loads(str(z["metadata"])),
                       coordinates=coords, **kwargs)
