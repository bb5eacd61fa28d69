"""Scalar summaries of a solution: extremes of the fields and checks of the constraint.

Stretches and strains are singular (order r^-1/2 in the stress) at the opening corners and where
a swelling interface meets a constrained boundary, so their raw extremes grow without bound
under refinement. Both are reported: ``raw_max_*`` / ``raw_min_*`` over all integration points,
and mesh-convergent ``max_*`` / ``min_*`` over the integration points farther than
``edge_exclusion`` from every singular point.

Where the singular places are too many to leave out (the 3D brain: every edge and corner of a
voxel-built tissue interface, where the stiffness or ``Js`` jumps), the volume percentiles
``pXX_*`` are the mesh-convergent measure, as the 95th-percentile maximum principal strain
("MPS95") is in brain-injury biomechanics: the value ``v`` with ``|{x : f(x) <= v}| >= q |Omega|``
for the fraction ``q``, over the same points as ``max_*`` weighted by their quadrature
volumes. A singular peak changes it only by the volume it covers, which vanishes under
refinement.

Every stretch and strain is evaluated from the recovered gradient (the region-wise L2
projection of ``Grad u`` onto continuous P1, :mod:`brainbulge.results.measures.recovery`), not from
the element-wise constant ``Grad u``: the element-to-element noise of the latter moved the
percentiles with the mesh. ``J`` and the constraint statistics use the solution's own ``J``.
"""

from __future__ import annotations

import dataclasses
import logging
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import ngsolve as ngs
import numpy as np

from brainbulge.results.measures.fields import output_fields, sample
from brainbulge.results.measures.quadrature import QuadraturePoints, quadrature_points
from brainbulge.results.measures.recovery import recovered_gradient
from brainbulge.results.measures.schema import CSF, EXTREMES, PERCENTILES, stem_key
from brainbulge.solver.options import Solution

log = logging.getLogger("brainbulge")


def away_from(X: np.ndarray, points: list[tuple[float, ...]], radius: float) -> np.ndarray:
    """Mask of rows of ``X`` farther than ``radius`` from all ``points``."""
    keep = np.ones(len(X), dtype=bool)
    for p in points:
        keep &= np.linalg.norm(X - np.asarray(p)[: X.shape[1]], axis=1) > radius
    return keep


def field_extremes(
    X: np.ndarray,
    fields: dict[str, np.ndarray],
    keep: np.ndarray,
    prefix: str = "",
) -> dict[str, object]:
    """``max_*``/``min_*`` over ``keep``, ``raw_*`` over all points, and argmax locations."""
    out: dict[str, object] = {}
    for stem, (name, kinds) in EXTREMES.items():
        if name not in fields:  # the shear stress of samples without materials
            continue
        v = fields[name]
        for kind in kinds:
            # (an inverted point, J <= 0, has no stress: NaN there, left out)
            f = np.nanargmax if kind == "max" else np.nanargmin
            i_raw = int(f(v))
            out[stem_key(f"raw_{kind}", stem, prefix)] = float(v[i_raw])
            if keep.any():
                idx = np.flatnonzero(keep)
                i = int(idx[f(v[idx])])
                out[stem_key(kind, stem, prefix)] = float(v[i])
                if kind == "max":
                    out[stem_key("argmax", stem, prefix)] = [float(c) for c in X[i]]
    return out


def weighted_percentiles(v: np.ndarray, w: np.ndarray, qs: tuple[int, ...]) -> np.ndarray:
    """numpy's weighted ``inverted_cdf`` percentiles ``qs`` (all >= 50 or all <= 50) of values
    ``v`` with weights ``w``: ``p_q = min {v_i : sum_{v_j <= v_i} w_j >= q/100 sum_j w_j}``.

    Only the tail that holds them is sorted: a threshold ``t`` from ``np.partition`` (linear
    time) such that the points beyond it carry more than the tail's weight, then
    ``p_q = min {v_i >= t : W(v < t) + sum_{t <= v_j <= v_i} w_j >= q W}`` (the mirror for
    low percentiles). Exact; a full weighted sort of the 17M points of a 1.40M-tet brain took
    7 s per field, the tail 1.9 s (both on a busy machine).
    """
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    q = np.asarray(qs, dtype=float) / 100
    n = len(v)
    upper = bool(q.min() >= 0.5)
    if not upper and q.max() > 0.5:
        raise ValueError(f"percentiles {qs} must all be >= 50 or all <= 50")
    total = w.sum()
    m = max(int(4 * (1 - q.min() if upper else q.max()) * n), 1024)
    while m < n:
        if upper:
            sel = v >= np.partition(v, n - m)[n - m]
            if total - w[sel].sum() < q.min() * total:
                break
        else:
            sel = v <= np.partition(v, m - 1)[m - 1]
            if w[sel].sum() >= q.max() * total:
                break
        m *= 2
    else:
        return np.percentile(v, np.asarray(qs, dtype=float), weights=w, method="inverted_cdf")
    vs, ws = v[sel], w[sel]
    order = np.argsort(vs, kind="stable")
    below = total - ws.sum() if upper else 0.0  # weight of the points before the tail
    cum = below + np.cumsum(ws[order])
    idx = np.searchsorted(cum, q * total, side="left")
    return vs[order][np.minimum(idx, len(vs) - 1)]


def exceeded_in(v: np.ndarray, w: np.ndarray, volume: float) -> float:
    """The value that ``v`` exceeds in a volume ``volume`` of the weights ``w``: the largest
    ``t`` with ``sum {w_i : v_i >= t} >= volume`` (the smallest ``v`` when the total weight is
    less). Only the top of ``v`` is sorted (``np.argpartition``, grown until it holds the
    volume)."""
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    n = len(v)
    m = min(n, 1024)
    while True:
        top = np.argpartition(v, n - m)[n - m:] if m < n else np.arange(n)
        if m == n or w[top].sum() >= volume:
            break
        m = min(n, 4 * m)
    order = top[np.argsort(v[top], kind="stable")[::-1]]
    k = int(np.searchsorted(np.cumsum(w[order]), volume, side="left"))
    return float(v[order[min(k, n - 1, len(order) - 1)]])


def field_percentiles(
    fields: dict[str, np.ndarray],
    weights: np.ndarray,
    keep: np.ndarray,
    prefix: str = "",
    peak_volume: float | None = None,
) -> dict[str, float]:
    """Volume percentiles ``pXX_*`` of the ``EXTREMES`` fields over ``keep``: the weighted
    percentiles of :func:`weighted_percentiles` with the points' quadrature weights (their
    volumes) as weights. With ``peak_volume`` (in the weights' units) also ``peak_*`` of the
    maxima: the value exceeded in that volume (:func:`exceeded_in`), a peak that, unlike the
    maximum of single points, converges under refinement."""
    out: dict[str, float] = {}
    w = np.asarray(weights, dtype=float)[keep]
    if not keep.any() or w.sum() <= 0:
        return out
    for stem, (name, kinds) in EXTREMES.items():
        if name not in fields:
            continue
        v = np.asarray(fields[name], dtype=float)[keep]
        ok = ~np.isnan(v)  # (an inverted point has no stress: left out)
        v, wv = v[ok], w[ok]
        if not len(v):
            continue
        for kind in kinds:
            qs = PERCENTILES[kind]
            for q, x in zip(qs, weighted_percentiles(v, wv, qs), strict=True):
                out[stem_key(f"p{q:02d}", stem, prefix)] = float(x)
            if kind == "max" and peak_volume is not None:
                out[stem_key("peak", stem, prefix)] = exceeded_in(v, wv, peak_volume)
    return out


def region_of_points(mesh, points) -> tuple[np.ndarray, list[str]]:
    """The region of each of the NGSolve mesh ``points``, as an index into the returned
    names (the last, ``none``, for a point in no region). Indices, not names: a name per
    point took ~60 bytes, 0.9 GB at a 1.40M-tet brain's 15M points."""
    names = list(dict.fromkeys(mesh.GetMaterials()))
    index = np.asarray(mesh.MaterialCF({r: float(i) for i, r in enumerate(names)},
                                       default=-1.0)(points)).reshape(-1)
    index = np.rint(index).astype(np.int16)
    index[index < 0] = len(names)
    return index, [*names, "none"]


def constraint_statistics(J: np.ndarray, Js: np.ndarray, weights: np.ndarray,
                          regions: np.ndarray, names: list[str]) -> dict[str, object]:
    """How well ``J = Js`` holds: statistics of ``|Je - 1| = |J / Js - 1|`` at the points.

    The constraint holds weakly (in the pressure space's sense: ``int q (J - Js) = 0`` for
    every pressure test function ``q``), not pointwise, so ``|Je - 1|`` is small but not zero
    and largest in a few elements at tissue interfaces and corners. Reported as volume-weighted
    ``median_abs_Je_minus_1`` and ``p95_abs_Je_minus_1`` over all points, the single largest
    point value as ``raw_max_abs_Je_minus_1``, and per region (``regions``: each point's
    index into ``names``) ``abs_Je_minus_1_by_region: {region: {"median", "p95",
    "raw_max"}}``.
    """
    dev = np.abs(J / Js - 1.0)
    w = np.asarray(weights, dtype=float)

    def stats(sel: np.ndarray | slice) -> dict[str, float]:
        v = dev[sel]  # one weighted sort for both percentiles
        med, p95 = np.percentile(v, (50, 95), weights=w[sel], method="inverted_cdf")
        return {"median": float(med), "p95": float(p95), "raw_max": float(v.max())}

    total = stats(slice(None))
    present = np.flatnonzero(np.bincount(regions, minlength=len(names)))
    return {
        "median_abs_Je_minus_1": total["median"],
        "p95_abs_Je_minus_1": total["p95"],
        "raw_max_abs_Je_minus_1": total["raw_max"],
        "abs_Je_minus_1_by_region": {names[r]: stats(regions == r) for r in
                                     sorted(present, key=lambda r: names[r])},
    }


#: integration points evaluated at a time: the (n, 3, 3) tensors behind the fields of one
#: chunk take ~75 MB (~0.3 GB in chunks of 1M points); all 21.6M points of a 1.54M-tet brain
#: at once took several GB more than the Newton solve itself
CHUNK = 250_000


class Selected(Mapping):
    """The fields ``fields`` (name -> array over the points) at the points ``sel`` (a
    mask), each cut out when it is read: one field's copy at a time, not all of them (at a
    1.40M-tet brain's 19.6M points a field takes 157 MB)."""

    def __init__(self, fields: dict[str, np.ndarray], sel: np.ndarray) -> None:
        self._fields = fields
        self._sel = sel

    def __getitem__(self, name: str) -> np.ndarray:
        return self._fields[name][self._sel]

    def __contains__(self, name: object) -> bool:
        return name in self._fields

    def __iter__(self) -> Iterator[str]:
        return iter(self._fields)

    def __len__(self) -> int:
        return len(self._fields)


@dataclass
class PointFields:
    """The scalar output fields at all order-4 integration points of a solution, the
    points of every percentile and extreme of the summary (and of a plan's damage measures,
    :mod:`brainbulge.results.measures.plan_measures`), sampled once.

    ``q``: the points' reference coordinates ``q.X`` and reference volumes ``q.weights``
    (its NGSolve point array dropped once sampled: 0.7 GB at 15M points); ``Js`` the
    swelling there, ``fields`` the 1D fields of
    :func:`~brainbulge.results.measures.fields.output_fields` (stretches and strains from the
    recovered gradient, ``J`` the solution's own); ``region`` each point's region as an
    index into ``region_names`` (:func:`region_of_points`).
    """

    q: QuadraturePoints
    Js: np.ndarray
    fields: dict[str, np.ndarray]
    region: np.ndarray
    region_names: list[str]

    @property
    def X(self) -> np.ndarray:
        """Reference coordinates of the points, ``(n, dim)``."""
        return self.q.X

    def in_regions(self, pattern: str) -> np.ndarray:
        """True at the points in a region whose whole name matches the regex ``pattern``."""
        rx = re.compile(f"^(?:{pattern})$")
        return np.array([bool(rx.match(n)) for n in self.region_names])[self.region]

    def mirrored(self) -> PointFields:
        """These points and their mirror images ``(-x, y, ...)`` about the plane ``x = 0``:
        the whole domain's points of a solution computed on its half ``x >= 0`` (the fields
        are scalars that the reflection leaves as they are; the vertical displacement too)."""
        X = self.q.X
        q = dataclasses.replace(self.q, X=np.concatenate([X, X * _REFLECT[:X.shape[1]]]),
                                weights=np.tile(self.q.weights, 2))
        fields = {k: np.tile(v, 2) for k, v in self.fields.items()}
        return PointFields(q=q, Js=fields["Js"], fields=fields,
                           region=np.tile(self.region, 2), region_names=self.region_names)


#: the reflection about the plane x = 0, per coordinate
_REFLECT = np.array([-1.0, 1.0, 1.0])


def point_fields(form, centre: np.ndarray,
                 fibres: Callable[[np.ndarray], np.ndarray] | None = None,
                 gradient: ngs.CoefficientFunction | None = None) -> PointFields:
    """:class:`PointFields` of ``form``'s state, evaluated ``CHUNK`` points at a time, with
    the recovered gradient ``gradient`` (computed here when not given), ``centre`` and
    ``fibres`` as for :func:`~brainbulge.results.measures.fields.output_fields`."""
    q = quadrature_points(form.mesh, order=4)
    G = gradient if gradient is not None else recovered_gradient(
        form.mesh, form.output_displacement())
    n = len(q.X)
    region = np.empty(n, dtype=np.int16)
    fields: dict[str, np.ndarray] = {}
    for a in range(0, n, CHUNK):  # filled in place: no second copy of the fields
        chunk = slice(a, min(a + CHUNK, n))
        s = sample(form, q.points[chunk], gradient=G)
        f = output_fields(s, centre, None if fibres is None else fibres(s.X))
        for k, v in f.items():
            if v.ndim == 1:
                fields.setdefault(k, np.empty(n, dtype=v.dtype))[chunk] = v
        del s, f  # (the chunk's tensors, before the next chunk's)
        region[chunk], names = region_of_points(form.mesh, q.points[chunk])
    # Js is one of the fields (output_fields gives the samples' own): one array for both
    return PointFields(q=dataclasses.replace(q, points=None), Js=fields["Js"], fields=fields,
                       region=region, region_names=names)


def solution_summary(
    sol: Solution,
    centre: np.ndarray,
    singular_points: list[tuple[float, ...]],
    edge_exclusion: float,
    near_singular: Callable[[np.ndarray], np.ndarray] | None = None,
    tissue: str | None = None,
    fibres: Callable[[np.ndarray], np.ndarray] | None = None,
    peak_volume: float | None = None,
    points: PointFields | None = None,
) -> dict[str, object]:
    """The summary of docs/model.md section 3 keys for any converged or partial solution.

    ``max_*``/``min_*`` leave out points within ``edge_exclusion`` of ``singular_points`` and,
    when given, points where ``near_singular(X)`` is true (e.g. a band around a 3D flap rim).
    ``tissue`` (a region regex) restricts the stretch and strain extremes to those regions;
    the others (an ultrasoft CSF filler) are reported with the prefix ``csf_``.
    ``fibres(X)`` gives unit axon directions at reference points (default: radial).
    ``peak_volume``: also ``peak_*``, the values exceeded in that volume
    (:func:`field_percentiles`). ``points``: the state's :func:`point_fields`, when the
    caller has them already (``fibres`` and ``centre`` then are theirs).
    """
    form = sol.form
    if points is None:
        points = point_fields(form, centre, fibres)
    q, X, Js, fields = points.q, points.X, points.Js, points.fields
    keep = away_from(X, singular_points, edge_exclusion)
    if near_singular is not None:
        for a in range(0, len(X), CHUNK):  # (a skull distance: several arrays per point)
            keep[a:a + CHUNK] &= ~near_singular(X[a:a + CHUNK])
    dim = form.dim
    J = fields["J"]
    out: dict[str, object] = {
        "converged": sol.converged,
        "load_reached": sol.load,
        "load_steps": len(sol.steps),
        "rejected_steps": sol.rejected_steps,
        "resumed_from_load": sol.resumed_from,
        "newton_iterations": sol.newton_iterations,
        "final_residual": sol.steps[-1].residual if sol.steps else None,
        "wall_time_s": round(sol.wall_time_s, 3),
        "assembly_time_s": round(sol.assembly_time_s, 3),
        "linear_solve_time_s": round(sol.solve_time_s, 3),
        "linear_iterations": sol.linear_iterations,
        "elements": form.mesh.ne,
        "dofs": form.fes.ndof,
        "max_displacement": float(fields["u_magnitude"].max()),
        "argmax_displacement": [float(c) for c in X[int(np.argmax(fields["u_magnitude"]))]],
        "max_vertical_displacement": float(fields["u_vertical"].max()),
        "min_vertical_displacement": float(fields["u_vertical"].min()),
    }
    if tissue is None:
        out.update(field_extremes(X, fields, keep))
        out.update(field_percentiles(fields, q.weights, keep, peak_volume=peak_volume))
    else:
        in_tissue = points.in_regions(tissue)
        for prefix, sel in (("", in_tissue), (CSF, ~in_tissue)):
            if sel.any():
                sub = Selected(fields, sel)
                out.update(field_extremes(X[sel], sub, keep[sel], prefix))
                out.update(field_percentiles(sub, q.weights[sel], keep[sel], prefix,
                                             peak_volume))
    out.update(constraint_statistics(J, Js, q.weights, points.region, points.region_names))
    out["inverted_points"] = inverted = int(np.count_nonzero(J <= 0))
    if inverted:
        log.warning("%d integration point(s) inverted (J <= 0): the stress is undefined there "
                    "and left out of the stress extremes", inverted)
    if "max_shear_stress" in fields:
        recovered = int(np.count_nonzero(np.isnan(fields["max_shear_stress"]) & (J > 0)))
        if recovered:
            log.warning("%d integration point(s) with an inverted recovered gradient: the "
                        "stress is undefined there and left out of the stress extremes",
                        recovered)
    out["raw_max_abs_J_minus_Js"] = float(np.max(np.abs(J - Js)))
    out["max_abs_J_minus_Js"] = float(np.max(np.abs(J - Js)[keep])) if keep.any() else None
    out["integral_J_minus_Js"] = float(np.sum((J - Js) * q.weights))
    out["swelling_volume"] = float(np.sum((Js - 1) * q.weights))
    out["max_pressure"] = float(fields["pressure"].max())
    out["min_pressure"] = float(fields["pressure"].min())
    out["max_penetration"] = sol.max_penetration
    if form.contacts_present:
        qb = quadrature_points(form.mesh, order=4, boundary=True)
        out["max_contact_pressure"] = float(np.max(qb(form.contact_pressure())))
    out["edge_exclusion"] = edge_exclusion
    out["singular_points"] = [[float(c) for c in p[:dim]] for p in singular_points]
    if sol.message:
        out["message"] = sol.message
    if not sol.converged and sol.failure_site is not None:
        out["failure_site"] = [float(c) for c in sol.failure_site]
    return out
