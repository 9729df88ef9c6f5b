"""Bound maps: the friction bound of a robot over its joint space, as the planner reads it.

The friction bound of Ha, Fagogenis & Dupont 2019 (doi:10.1109/TRO.2018.2878906; Section III, and
its translation-last variant, Section V-B) costs tens of milliseconds per configuration, far too
much inside a sampling planner. A bound map evaluates it once on a grid and interpolates:

- :mod:`~ctrplan.coordinates`: the map's coordinates, the base rotations and
  translations relative to tube 1 on which the bound depends (a six-joint robot has a 4-D map);
- :mod:`~ctrplan.boundmap.axes`: the grid spec (:class:`MapSpec`), uniform or adaptive nodes;
- :mod:`~ctrplan.boundmap.field`: :class:`BoundField`, the grid and its interpolation;
- :mod:`~ctrplan.boundmap.identity`: what a map was computed for and its key (robot file,
  model settings, spec, evaluator, mechanics version);
- :mod:`~ctrplan.boundmap.store`: the resumable zarr store and :func:`load_bound_map`;
- :mod:`~ctrplan.boundmap.compute`: computing a map locally or on a Dask cluster;
- :mod:`~ctrplan.boundmap.files`: shipped and cached maps of robot files;
- :mod:`~ctrplan.boundmap.accuracy`: a map against the exact model;
- :mod:`~ctrplan.boundmap.refine`: a map corrected to the exact bound where the planner goes, and
  the coarse preview map a new robot plans with first.
"""

from .accuracy import InterpolationError, interpolation_error, sample_exact
from .axes import PLACEMENTS, MapSpec, place_nodes, uniform_axis
from .compute import (DEFAULT_CHUNK_SIZE, BoundMapRun, ComputeOptions, SchedulerUnreachableError,
                      compute_bound_map_store, compute_field, node_values, start_local_cluster)
from ..coordinates import MapCoordinates, map_coordinates
from .field import QUANTITIES, UNITS, BoundField
from .files import compute_bound_map, default_spec, find_bound_map, load_or_compute_bound_map, map_file, map_paths
from .refine import (ExactSamples, cell_nodes, evaluate_nodes, preview_spec, refined_field, subdivided,
                     with_nodes)
from .identity import (BoundFieldKeyError, BoundMapMismatchError, MapIdentity, evaluator_name, field_key,
                       map_identity)
from .store import (STORE_SUFFIX, BoundMapStore, IncompleteBoundMapError, chunk_shape_for, is_store_path,
                    load_bound_map)

__all__ = [
    "MapCoordinates", "map_coordinates", "MapSpec", "PLACEMENTS", "place_nodes", "uniform_axis",
    "QUANTITIES", "UNITS", "BoundField", "BoundFieldKeyError", "BoundMapMismatchError", "MapIdentity",
    "evaluator_name", "field_key", "map_identity", "BoundMapStore", "IncompleteBoundMapError", "STORE_SUFFIX",
    "chunk_shape_for", "is_store_path", "load_bound_map", "DEFAULT_CHUNK_SIZE", "BoundMapRun", "ComputeOptions",
    "SchedulerUnreachableError", "compute_bound_map_store", "compute_field", "node_values",
    "start_local_cluster", "compute_bound_map", "default_spec", "find_bound_map", "load_or_compute_bound_map",
    "map_paths",
    "map_file",
    "InterpolationError", "interpolation_error", "sample_exact", "ExactSamples", "refined_field", "preview_spec",
    "subdivided", "cell_nodes", "with_nodes", "evaluate_nodes",
]


def __getattr__(name):
    # the name before it had one meaning (ctrplan.batch.evaluate_configuration runs a model by name)
    if name == "evaluate_configuration":
        import warnings

        warnings.warn("ctrplan.boundmap.evaluate_configuration is deprecated: use ctrplan.boundmap.node_values",
                      DeprecationWarning, stacklevel=2)
        return node_values
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
