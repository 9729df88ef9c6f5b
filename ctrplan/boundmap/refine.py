"""A bound map refined where the planner goes, and the coarse preview map a new robot plans with
first.

A map's error at a configuration is its interpolation error (docs/boundmaps.md): up to a few mm
between the nodes of the shipped six-joint map, more between those of a coarse one. The planner
reads the map, and the plan's waypoints then get the exact bound (Section V-B of Ha, Fagogenis &
Dupont 2019). Refinement closes the loop, in three steps:

1. :func:`subdivided`: the map on a finer grid, a node inserted midway between every two
   neighbouring nodes (once or more), its values interpolated (those of the old nodes
   unchanged);
2. :func:`cell_nodes` and :func:`with_nodes`: the exact bound at every node of the cells the
   plan's path crosses (evaluated at the nodes' representative configurations, as a map's
   nodes are, :func:`evaluate_nodes`), so that the map there is the exact bound interpolated
   over one fine cell;
3. :func:`refined_field`: the node values of the waypoints' cells corrected by the smallest
   change (in the least-squares sense) that makes the map interpolate the exact bound at every
   waypoint (:class:`ExactSamples`).

The next plan reads the refined map: where it goes again, its cost is the exact bound
interpolated over fine cells, and at the earlier waypoints the exact bound itself. Away from
the cells the plans crossed the map is the subdivided one.

With ``m`` samples whose cells have corners ``j`` and multilinear weights ``W`` (m, N), the
correction ``delta`` (N,) of one quantity is the minimum-norm solution of ``W delta = r`` with
``r`` the samples' exact values minus the map's there:
``delta = W^T (W W^T + lambda I)^-1 r``, ``lambda`` a ridge of :data:`RIDGE` times the largest
diagonal entry of ``W W^T`` (samples so close that their weights are nearly the same and whose
values differ get the least-squares compromise). Node values that would fall below zero are
clipped at zero (every map quantity is a bound magnitude). After step 2 the residuals are the
fine cells' interpolation errors, so the corrections are small.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_savez
from .axes import MapSpec
from .field import _WEIGHT_EPS as WEIGHT_EPS, QUANTITIES, BoundField

__all__ = ["ExactSamples", "refined_field", "subdivided", "cell_nodes", "with_nodes", "evaluate_nodes", "preview_spec",
           "RIDGE", "PREVIEW_FACTOR"]

#: Relative ridge of the minimum-norm correction (of the largest diagonal entry of ``W W^T``).
RIDGE = 1e-6
#: The preview map has 1 / PREVIEW_FACTOR of the nodes of the full map along every coordinate
#: (rounded up, at least 2; 3 along a periodic one).
PREVIEW_FACTOR = 2


@dataclass(frozen=True, eq=False)
class ExactSamples:
    """Exact bounds at configurations, in a map's coordinates.

    Attributes
    ----------
    u : ndarray, shape (m, d)
        Map coordinates of the configurations [rad or m]
        (:meth:`~ctrplan.coordinates.MapCoordinates.from_joints`).
    values : ndarray, shape (m, 4)
        The exact :data:`~ctrplan.boundmap.field.QUANTITIES` there [m, rad].
    ok : ndarray of bool, shape (m,)
        The model converged and the standard solution is stable (as a map node's ``valid``).
    """

    u: np.ndarray
    values: np.ndarray
    ok: np.ndarray

    def __post_init__(self):
        u = np.atleast_2d(np.asarray(self.u, float))
        values = np.asarray(self.values, float).reshape(u.shape[0], len(QUANTITIES))
        ok = np.asarray(self.ok, bool).reshape(u.shape[0])
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "ok", ok)

    @classmethod
    def empty(cls, d: int) -> "ExactSamples":
        """No sample, over ``d`` map coordinates."""
        return cls(np.zeros((0, d)), np.zeros((0, len(QUANTITIES))), np.zeros(0, bool))

    @classmethod
    def from_results(cls, field: BoundField, q, results) -> "ExactSamples":
        """The samples of exact bound results at joint vectors.

        Parameters
        ----------
        field : BoundField
            Gives the map coordinates of ``q``.
        q : array-like, shape (m, n_joints)
            Joint vectors [rad or m].
        results : sequence of BoundResult or None, length m
            :func:`ctrplan.mechanics.evaluate_bound` at each (None: the model failed there).

        Returns
        -------
        ExactSamples
            ``ok`` False where a result is None, not converged, unstable or not finite.
        """
        q = np.atleast_2d(np.asarray(q, float))
        if len(results) != q.shape[0]:
            raise ValueError(f"{q.shape[0]} joint vectors but {len(results)} results")
        values = np.full((q.shape[0], len(QUANTITIES)), np.nan)
        ok = np.zeros(q.shape[0], bool)
        for i, res in enumerate(results):
            if res is None:
                continue
            values[i] = [float(getattr(res, name)) for name in QUANTITIES]
            diag = getattr(res, "diagnostics", None)
            ok[i] = bool(np.all(np.isfinite(values[i]))) and (
                diag is None or (bool(diag.converged) and not bool(diag.unstable)))
        return cls(field.to_map(q), values, ok)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.u.shape[0])

    def merged(self, other: "ExactSamples") -> "ExactSamples":
        """These samples and ``other``'s, without repeats of identical coordinates (the later
        sample kept)."""
        u = np.concatenate([self.u, other.u])
        values = np.concatenate([self.values, other.values])
        ok = np.concatenate([self.ok, other.ok])
        _, first = np.unique(u[::-1], axis=0, return_index=True)
        keep = np.sort(u.shape[0] - 1 - first)
        return ExactSamples(u[keep], values[keep], ok[keep])

    def save(self, path) -> Path:
        """Write to one ``.npz`` (atomically)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_savez(path, u=self.u, values=self.values, ok=self.ok)
        return path

    @classmethod
    def load(cls, path) -> "ExactSamples":
        """Read what :meth:`save` wrote.

        Raises
        ------
        FileNotFoundError
        ValueError
            Not such a file.
        """
        with np.load(Path(path), allow_pickle=False) as z:
            try:
                return cls(z["u"], z["values"], z["ok"])
            except KeyError as exc:
                raise ValueError(f"{path}: not a file of exact bound samples (no {exc})") from None


def refined_field(field: BoundField, samples: ExactSamples) -> BoundField:
    """The map with its node values corrected to interpolate the exact samples (module docstring).

    Parameters
    ----------
    field : BoundField
        The map [m, rad].
    samples : ExactSamples
        Over the map's coordinates; samples that are not ``ok``, or where the map is invalid (an
        invalid node carries weight), are left out.

    Returns
    -------
    BoundField
        Same axes, validity, key and coordinates; every quantity corrected; ``metadata``
        ``refined_samples`` (the samples used) and ``refined_nodes`` (the nodes changed).

    Raises
    ------
    ValueError
        Samples over another number of coordinates.
    """
    d = field.n_coordinates
    if samples.u.shape[1] != d:
        raise ValueError(f"samples over {samples.u.shape[1]} coordinates, the map has {d}")
    base, inside = field.interpolate(samples.u)
    use = samples.ok & inside & np.all(np.isfinite(samples.values), axis=1)
    flat = np.nan_to_num(field.values.reshape(-1, len(QUANTITIES)))
    m = int(use.sum())
    touched = np.zeros(0, np.int64)
    if m:
        index, weight = field.cell_weights(samples.u[use])
        weight = np.where(weight > WEIGHT_EPS, weight, 0.0)
        touched, local = np.unique(index.reshape(-1), return_inverse=True)
        w = np.zeros((m, touched.size))
        np.add.at(w, (np.repeat(np.arange(m), 1 << d), local), weight.reshape(-1))
        gram = w @ w.T
        gram[np.diag_indices(m)] += RIDGE * float(np.max(np.diag(gram)))
        residual = samples.values[use] - base[use]
        delta = w.T @ np.linalg.solve(gram, residual)
        flat[touched] = np.maximum(flat[touched] + delta, 0.0)
    values = np.where(field.valid[..., None], flat.reshape(field.values.shape), np.nan)
    meta = {**field.metadata, "refined_samples": int(m), "refined_nodes": int(touched.size)}
    return BoundField(field.axes, field.periodic, values, field.valid, field.key, meta,
                      coordinates=field.coordinates, invalid_value=field.invalid_value)


def preview_spec(spec: MapSpec, periodic) -> MapSpec:
    """The preview map's spec: :data:`PREVIEW_FACTOR` times fewer nodes along every coordinate.

    Parameters
    ----------
    spec : MapSpec
        The full map's (its resolution per map coordinate).
    periodic : sequence of bool, shape (d,)
        Which coordinates are periodic (at least 3 nodes there).

    Returns
    -------
    MapSpec
        Same placement and pilot settings.
    """
    res = tuple(max(3 if p else 2, -(-n // PREVIEW_FACTOR)) for n, p in zip(spec.resolution, periodic))
    return MapSpec(res, spec.placement, pilot_lines=spec.pilot_lines, pilot_step_m=spec.pilot_step_m,
                   pilot_step_rad=spec.pilot_step_rad, pilot_seed=spec.pilot_seed)


def _subdivided_axis(a: np.ndarray, periodic: bool) -> np.ndarray:
    if periodic:
        h = 2.0 * np.pi / a.size
        return a[0] + np.arange(2 * a.size) * (h / 2.0)
    return np.sort(np.concatenate([a, 0.5 * (a[1:] + a[:-1])]))


def subdivided(field: BoundField, levels: int = 1) -> BoundField:
    """The map on a grid with a node midway between every two neighbouring nodes (n nodes become
    2n - 1 along a bounded coordinate, 2n along a periodic one), ``levels`` times.

    Parameters
    ----------
    field : BoundField
    levels : int
        Times to subdivide (>= 0).

    Returns
    -------
    BoundField
        Values at the new nodes interpolated (the old nodes' unchanged), valid where the
        interpolation is; same key, coordinates and metadata (``subdivided_from``: the old
        resolution).

    Raises
    ------
    ValueError
        ``levels`` < 0.
    """
    if levels < 0:
        raise ValueError(f"levels must be >= 0, got {levels!r}")
    axes = list(field.axes)
    for _ in range(int(levels)):
        axes = [_subdivided_axis(a, bool(p)) for a, p in zip(axes, field.periodic)]
    shape = tuple(a.size for a in axes)
    mesh = np.meshgrid(*axes, indexing="ij")
    nodes = np.stack([g.reshape(-1) for g in mesh], axis=1)
    values, ok = field.interpolate(nodes)
    meta = {**field.metadata, "subdivided_from": list(field.shape)}
    return BoundField(axes, field.periodic, values.reshape(shape + (len(QUANTITIES),)), ok.reshape(shape), field.key,
                      meta, coordinates=field.coordinates, invalid_value=field.invalid_value)


def cell_nodes(field: BoundField, u) -> np.ndarray:
    """Flat (C-order) indices of every node of the cells the points lie in.

    Parameters
    ----------
    field : BoundField
    u : array-like, shape (m, d)
        Map coordinates [rad or m].

    Returns
    -------
    ndarray of int, shape (k,)
        Sorted, without repeats (up to ``m 2^d``).
    """
    u = np.atleast_2d(np.asarray(u, float))
    if u.shape[0] == 0:
        return np.zeros(0, np.int64)
    index, _ = field.cell_weights(u)
    return np.unique(index)


def with_nodes(field: BoundField, index, values, ok) -> BoundField:
    """The map with the values and validity of some nodes replaced.

    Parameters
    ----------
    field : BoundField
    index : array-like of int, shape (k,)
        Flat (C-order) node indices.
    values : array-like, shape (k, 4)
        :data:`~ctrplan.boundmap.field.QUANTITIES` there [m, rad].
    ok : array-like of bool, shape (k,)
        Valid (as a map node's: converged and stable).

    Returns
    -------
    BoundField
        Same axes, key, coordinates and metadata.
    """
    index = np.asarray(index, np.int64)
    flat = np.array(field.values.reshape(-1, len(QUANTITIES)), copy=True)
    valid = np.array(field.valid.reshape(-1), copy=True)
    ok = np.asarray(ok, bool) & np.all(np.isfinite(np.asarray(values, float)), axis=1)
    flat[index] = np.where(ok[:, None], np.asarray(values, float), np.nan)
    valid[index] = ok
    return BoundField(field.axes, field.periodic, flat.reshape(field.values.shape), valid.reshape(field.shape),
                      field.key, field.metadata, coordinates=field.coordinates, invalid_value=field.invalid_value)


def evaluate_nodes(robot, field: BoundField, index, settings=None, n_jobs: int = 1, *,
                   evaluator=None) -> tuple[np.ndarray, np.ndarray]:
    """The exact map quantities at some nodes of a map (as its nodes were computed:
    :func:`~ctrplan.boundmap.compute.node_values` at their representative
    configurations).

    Parameters
    ----------
    robot : Robot
    field : BoundField
        With ``coordinates`` (the robot's map coordinates).
    index : array-like of int, shape (k,)
        Flat (C-order) node indices.
    settings : ModelSettings, optional
        The map's model settings.
    n_jobs : int
        Local worker processes (:class:`ctrplan.parallel.Executor`).
    evaluator : callable, optional, keyword-only
        Default :func:`ctrplan.mechanics.evaluate_bound`.

    Returns
    -------
    values : ndarray, shape (k, 4)
        [m, rad]; NaN where the model failed.
    ok : ndarray of bool, shape (k,)

    Raises
    ------
    ValueError
        A map without coordinates.
    """
    from ..parallel import Executor
    from .compute import _run_chunks

    if evaluator is None:
        from ..mechanics import evaluate_bound as evaluator
    if field.coordinates is None:
        raise ValueError("the map has no coordinates: its nodes have no configuration")
    index = np.asarray(index, np.int64)
    values = np.full((index.size, len(QUANTITIES)), np.nan)
    ok = np.zeros(index.size, bool)
    if not index.size:
        return values, ok
    sub = np.unravel_index(index, field.shape)
    u = np.stack([a[i] for a, i in zip(field.axes, sub)], axis=1)
    alpha, beta = field.coordinates.configuration(u)
    parts = np.array_split(np.arange(index.size), min(int(n_jobs), index.size))
    tasks = [(k, alpha[part], beta[part]) for k, part in enumerate(parts)]
    with Executor(min(int(n_jobs), len(parts))) as ex:
        for k, (vals, good, *_rest) in _run_chunks(ex, tasks, robot, evaluator, settings):
            values[parts[k]] = vals
            ok[parts[k]] = good
    return values, ok
