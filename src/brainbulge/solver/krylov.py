"""Block-preconditioned Krylov solver for the condensed MINI (P1-bubble / P1) tangent.

After static condensation of the bubbles the tangent restricted to the free DOFs reads::

    K = [[A, B^T],
         [B, -C]]

with ``A`` the (condensed) displacement stiffness, ``B`` the linearised constraint and
``C >= 0`` the pressure-pressure block that condensing the bubbles leaves behind (MINI's
stabilisation, of order ``h^2 / mu``). ``A`` is not always positive definite: at a swollen
state the geometric term ``p d2J`` makes it indefinite where the pressure exceeds the local
shear modulus (seen on the 3D inclusion with a soft inclusion). The default preconditioner is
block upper-triangular, in right-preconditioned GMRES::

    P = [[A~, B^T], [0, -S~]]
    A^-1 ~ one V-cycle of smoothed-aggregation AMG (pyamg), rigid-body modes as the
           near-nullspace, aggregation on node blocks, Gauss-Seidel smoothing
    S^-1 ~ one AMG V-cycle on S~ = C + B diag(A)^-1 B^T      (schur="simple")

The textbook ``S~ = M_p / mu`` (``schur="mass"``) is spectrally equivalent to ``S`` for one
continuous pressure, but the pressure here is broken across material zones, and the zones
include one-element-thick layers (CSF, cortex): with the exact ``A`` the mass-matrix Schur
complement needed 162-194 GMRES iterations on the 21k-tet brain (61 with one continuous
pressure), ``C + B diag(A)^-1 B^T`` 48; ``S`` against ``M_p / mu`` has eigenvalues from 0.0035
to 6.2, the small ones in CSF and gray-matter interface modes. ``method="minres"`` (block
diagonal ``diag(A~, S~)``) needs an SPD ``A~``: pass ``reference=reference_stiffness(form)``.

The AMG hierarchies are set up once (``setup``) and reused across Newton iterations: only the
finest level's matrix and smoother are refreshed; everything is rebuilt when a solve takes more
than ``refresh_factor`` times the iterations of the first solve after the last set-up, after a
failed solve, or on request (``refresh()``). Every solve checks the true residual
``|rhs - K x| / |rhs|`` and raises :class:`ConvergenceError` if it is above ``rtol``.

Both Krylov methods are written here rather than taken from SciPy: SciPy's ``minres`` stops
on its preconditioned residual estimate (it reported success at a true relative residual of
0.2 on the brain's tangent) and its ``gmres`` preconditions from the left, so it too stops on the
preconditioned residual. Here GMRES is right-preconditioned (it minimises the true residual)
and MINRES restarts from the true defect until the true residual meets the tolerance.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.solver.sparse_reuse import PatternGather
from brainbulge.solver.threaded_csr import threaded
from brainbulge.solver.threads import serial_openblas

log = logging.getLogger("brainbulge")

METHODS = ("gmres", "minres")
SCHUR = ("simple", "simple-diag", "mass")
# Weak couplings of the SIMPLE Schur approximation dropped before its AMG. Its distance-2
# stencil (B D^-1 B^T) has many weak entries that "strength: symmetric, theta 0" aggregates
# as strong; dropping them below 0.05 sqrt(|S_ii S_jj|) made the AMG both cheaper and better.
# Measured on the 111k-tet brain (left flap, both sides, krylov): one tangent 55 -> 37 GMRES
# iterations and 0.10 -> 0.07 s per preconditioner application; the whole scenario 906 ->
# 481 GMRES iterations, 13 -> 10 Newton iterations, 129 -> 69 s linear solves.
SCHUR_DROP = 0.05


# --- what the solver needs to know about the discretisation ----------------------------
@dataclass
class DisplacementLayout:
    """Where each free displacement DOF sits: its mesh vertex and its component.

    Attributes:
        coords: (n_vertices, dim) vertex coordinates.
        vertex: (n_free_u,) vertex of each free displacement DOF, in the order of the free
            DOFs; -1 at the DOFs of higher-order hierarchical basis functions (Taylor-Hood's
            P2 edge functions), which vanish at every vertex and carry no part of a rigid
            motion.
        component: (n_free_u,) component (0 = x, 1 = y, 2 = z) of each.
    """

    coords: np.ndarray
    vertex: np.ndarray
    component: np.ndarray

    @property
    def dim(self) -> int:
        return int(self.coords.shape[1])

    @property
    def linear(self) -> np.ndarray:
        """(n_free_u,) True at the DOFs of vertex (P1 hat) basis functions."""
        return self.vertex >= 0

    def rigid_body_modes(self) -> np.ndarray:
        """(n_free_u, 3 or 6) translations and linearised rotations about the centroid
        (zero at hierarchical higher-order DOFs: a linear field is their P1 part alone)."""
        dim = self.dim
        X = np.where(self.linear[:, None], self.coords[self.vertex] - self.coords.mean(axis=0),
                     0.0)
        c = np.where(self.linear, self.component, -1)
        n = len(c)
        modes = [(c == i).astype(float) for i in range(dim)]
        # rotation about axis k: (e_k x X)_c, i.e. for (i, j) = (x, y): (-y, x)
        pairs = [(0, 1)] if dim == 2 else [(0, 1), (1, 2), (2, 0)]
        for i, j in pairs:
            m = np.zeros(n)
            m[c == i] = -X[c == i, j]
            m[c == j] = X[c == j, i]
            modes.append(m)
        return np.column_stack(modes)


def free_dofs(form) -> np.ndarray:
    """Indices of the free DOFs exactly as :class:`NewtonSolver` restricts the tangent."""
    return np.flatnonzero(np.array(list(form.fes.FreeDofs(form.condense)), dtype=bool))


def displacement_layout(form, free: np.ndarray | None = None) -> DisplacementLayout:
    """Vertex and component of every free displacement DOF of a MINI (P1 + condensed
    bubble) or Taylor-Hood (hierarchical P2) ``form``.

    Built from each vertex's DOF numbers (:func:`vertex_dofs`), so it does not rely on
    NGSolve's DOF ordering (which for VectorH1 is: all x-components, then all y, then all z,
    each with the vertex DOFs first). Free DOFs that are no vertex's (P2 edge functions) get
    vertex -1 and the component of their block of the ordering.
    """
    from brainbulge.geometry.ngsolve_arrays import vertex_coordinates, vertex_dofs

    if free is None:
        free = free_dofs(form)
    mesh = form.mesh
    fes = form.fes
    rng = fes.Range(0)
    V = fes.components[0]
    dim = mesh.dim
    vert_of = np.full(V.ndof, -1, dtype=np.int64)
    comp_of = np.full(V.ndof, -1, dtype=np.int64)
    dofs = vertex_dofs(V, mesh)
    if dofs.shape != (mesh.nv, dim):
        raise InputError("the Krylov solver needs the MINI element (P1 + condensed bubbles)")
    vert_of[dofs] = np.arange(mesh.nv)[:, None]
    comp_of[dofs] = np.arange(dim)[None, :]
    free_u = free[(free >= rng.start) & (free < rng.stop)] - rng.start
    higher = vert_of[free_u] < 0
    if np.any(higher):
        if V.ndof % dim or not np.array_equal(comp_of[dofs], dofs // (V.ndof // dim)):
            raise InputError("the Krylov solver does not know this displacement space's "
                             "DOF numbering; use the direct solver")
        comp_of[free_u[higher]] = free_u[higher] // (V.ndof // dim)
    coords = vertex_coordinates(mesh)
    return DisplacementLayout(coords, vert_of[free_u], comp_of[free_u])


def pressure_schur_mass(form, free: np.ndarray | None = None, weighted: bool = True):
    """Pressure mass matrix weighted by ``1 / mu`` (CSR over the free pressure DOFs).

    ``weighted=False`` gives ``M_p / mu_max`` instead (the unweighted mass with one scale).
    """
    import ngsolve as ngs

    if free is None:
        free = free_dofs(form)
    mesh = form.mesh
    mats = form.problem.materials
    if weighted:
        inv_mu = mesh.MaterialCF({r: 1.0 / m.shear_modulus for r, m in mats.items()}, default=0)
    else:
        inv_mu = ngs.CF(1.0 / form.mu_max)
    _, *ps = form.fes.TrialFunction()
    _, *qs = form.fes.TestFunction()
    m = ngs.BilinearForm(form.fes, symmetric=False)
    m += sum((p * q for p, q in zip(ps[1:], qs[1:], strict=True)), ps[0] * qs[0]) * inv_mu * ngs.dx
    m.Assemble()
    M = sp.csr_matrix(m.mat.CSR())
    rng = form.fes.Range(0)
    free_p = free[(free < rng.start) | (free >= rng.stop)]
    return M[free_p][:, free_p].tocsr()


def reference_stiffness(form, free: np.ndarray | None = None, deviatoric: bool = False):
    """Linear-elastic stiffness ``2 mu eps(u) : eps(v)`` of the condensed displacement space
    (CSR over the free displacement DOFs): SPD whatever the state, for the AMG when the
    tangent's displacement block is indefinite (compressive pressure beyond ``mu``).

    ``deviatoric=True`` uses ``2 mu dev eps : dev eps`` (the rest tangent of the isochoric
    energy) instead.
    """
    import ngsolve as ngs

    if free is None:
        free = free_dofs(form)
    mesh = form.mesh
    mats = form.problem.materials
    mu = mesh.MaterialCF({r: m.shear_modulus for r, m in mats.items()}, default=0)
    u, *ps = form.fes.TrialFunction()
    v, *qs = form.fes.TestFunction()
    eu, ev = ngs.Sym(ngs.Grad(u)), ngs.Sym(ngs.Grad(v))
    if deviatoric:
        d = mesh.dim
        eu = eu - ngs.Trace(eu) / d * ngs.Id(d)
        ev = ev - ngs.Trace(ev) / d * ngs.Id(d)
    a = ngs.BilinearForm(form.fes, symmetric=True, condense=form.condense)
    # with a vanishing pressure term in the same integrand: NGSolve's static condensation
    # failed (CalcLU: matrix singular, NGSolve 6.2.2608) for the displacement term alone or
    # with the pressure term as a separate integrator
    pq = sum((p * q for p, q in zip(ps[1:], qs[1:], strict=True)), ps[0] * qs[0])
    a += (2 * mu * ngs.InnerProduct(eu, ev) + 1e-30 * pq) * ngs.dx
    with ngs.TaskManager():
        a.Assemble()
    A = sp.csr_matrix(a.mat.CSR())
    rng = form.fes.Range(0)
    free_u = free[(free >= rng.start) & (free < rng.stop)]
    return A[free_u][:, free_u].tocsr()


# --- the solver ------------------------------------------------------------------------
@dataclass
class KrylovStats:
    """What the last solves did (for benchmarks and logs)."""

    setups: int = 0
    setup_time_s: float = 0.0
    solves: int = 0
    solve_time_s: float = 0.0
    iterations: list[int] = field(default_factory=list)
    residuals: list[float] = field(default_factory=list)


SMOOTHER_KEYS = ("presmoother", "postsmoother")


def _smoother_setup(name: str):
    from pyamg.relaxation import smoothing

    return getattr(smoothing, f"setup_{name}")


_SMOOTHER_SETUP = {
    name: (lambda lvl, _n=name, **kw: _smoother_setup(_n)(lvl, **kw))
    for name in ("gauss_seidel", "block_gauss_seidel", "jacobi", "block_jacobi")
}


class _AMG:
    """One smoothed-aggregation V-cycle as a linear operator, with hierarchy reuse.

    ``slot`` maps the unknowns into the (possibly padded) AMG index space; unused slots
    carry identity rows decoupled from the rest.
    """

    def __init__(self, n_pad: int, slot: np.ndarray, blocksize: int, B: np.ndarray | None,
                 options: dict) -> None:
        self.n_pad = n_pad
        self.slot = slot
        self.empty = np.setdiff1d(np.arange(n_pad), slot)
        self.blocksize = blocksize
        self.B = B
        self.options = options
        self.ml = None
        # the finest level of each new matrix, padded by a plan made once per pattern
        self._padded_csr = PatternGather(lambda A: self._pad(A, 0.0), fill=self._fill)

    @staticmethod
    def _fill(A: sp.spmatrix) -> float:
        """The diagonal of the identity rows at unused slots: the mean diagonal."""
        diag = np.abs(A.diagonal())
        return float(np.mean(diag[diag > 0])) if np.any(diag > 0) else 1.0

    def _pad(self, A: sp.spmatrix, fill: float) -> sp.csr_matrix:
        coo = A.tocoo()
        rows = np.concatenate([self.slot[coo.row], self.empty])
        cols = np.concatenate([self.slot[coo.col], self.empty])
        vals = np.concatenate([coo.data, np.full(len(self.empty), fill)])
        Ap = sp.csr_matrix((vals, (rows, cols)), shape=(self.n_pad, self.n_pad))
        Ap.sum_duplicates()
        Ap.sort_indices()
        return Ap

    def padded(self, A: sp.spmatrix) -> sp.spmatrix:
        """``A`` in the AMG's index space (BSR node blocks when ``blocksize > 1``)."""
        Ap = self._pad(A, self._fill(A))
        if self.blocksize > 1:
            return Ap.tobsr(blocksize=(self.blocksize, self.blocksize))
        return Ap

    def _options(self) -> dict:
        opts = dict(
            strength=("symmetric", {"theta": 0.0}),
            smooth=("jacobi", {"omega": 4.0 / 3.0}),
            improve_candidates=None,
            max_coarse=500,
            coarse_solver="splu",
        )
        opts.update({k: v for k, v in self.options.items() if k not in SMOOTHER_KEYS})
        return opts

    def _smoothers(self) -> tuple[tuple[str, dict], tuple[str, dict]]:
        """A forward Gauss-Seidel sweep before the coarse correction, a backward one after
        it: the V-cycle stays symmetric (the post-smoother is the pre-smoother's adjoint)
        with half the sweeps of symmetric sweeps on both sides. On a 1.40M-tet fine-stage
        system (1.08M unknowns): 78 GMRES iterations instead of 68, 55 s instead of 64 s."""
        pre = self.options.get("presmoother", ("gauss_seidel", {"sweep": "forward"}))
        post = self.options.get("postsmoother", ("gauss_seidel", {"sweep": "backward"}))
        for name, _ in (pre, post):
            if name not in _SMOOTHER_SETUP:
                raise InputError(f"AMG smoother {name!r} not supported; choose one of "
                                 f"{', '.join(_SMOOTHER_SETUP)}")
        return pre, post

    def setup(self, A: sp.spmatrix) -> None:
        """Aggregate on node blocks (BSR), then smooth and transfer in CSR.

        pyamg's block Gauss-Seidel on BSR was 2x slower per sweep than the scalar one on
        CSR (3x3 blocks, 50k displacement DOFs), for about the same Krylov iterations.
        """
        import pyamg
        from pyamg.relaxation.smoothing import change_smoothers

        ml = pyamg.smoothed_aggregation_solver(self.padded(A), B=self.B, **self._options())
        for lvl in ml.levels:  # the cycle's products on all cores
            lvl.A = threaded(sp.csr_matrix(lvl.A))
            for name in ("P", "R"):
                if hasattr(lvl, name):
                    setattr(lvl, name, threaded(sp.csr_matrix(getattr(lvl, name))))
        pre, post = self._smoothers()
        change_smoothers(ml, pre, post)
        self.ml = ml

    def update(self, A: sp.spmatrix) -> None:
        """Keep the hierarchy, smooth with the new matrix on the finest level."""
        lvl = self.ml.levels[0]
        lvl.A = threaded(self._padded_csr(A))
        if len(self.ml.levels) == 1:
            return
        # not ml.change_solve_matrix: it rebuilds the smoothers without their options
        # (a forward sweep instead of the symmetric one: a non-symmetric preconditioner)
        (pre, pre_kw), (post, post_kw) = self._smoothers()
        lvl.presmoother = _SMOOTHER_SETUP[pre](lvl, **pre_kw)
        lvl.postsmoother = _SMOOTHER_SETUP[post](lvl, **post_kw)

    def __call__(self, r: np.ndarray) -> np.ndarray:
        ml = self.ml
        b = np.zeros(self.n_pad)
        b[self.slot] = r
        if len(ml.levels) == 1:
            return ml.coarse_solver(ml.levels[0].A, b)[self.slot]
        y = np.zeros(self.n_pad)
        # one V-cycle from zero (pyamg's solve() would also form the final residual)
        ml._MultilevelSolver__solve(0, y, b, "V")
        return y[self.slot]

    def describe(self) -> str:
        ml = self.ml
        return f"{len(ml.levels)} levels, operator complexity {ml.operator_complexity():.2f}"

    def release(self) -> None:
        """Drop the hierarchy and the padding plan (the next ``setup`` makes them again)."""
        self.ml = None
        self._padded_csr = PatternGather(self._padded_csr.transform, fill=self._fill)


class _HierarchicalTwoLevel:
    """One symmetric two-level cycle for a hierarchical P2 displacement block (Taylor-Hood).

    The P2 space splits into its P1 part (the vertex hat functions, whose block ``A_11`` is
    the P1 stiffness) and the edge functions, whose block is well conditioned after
    diagonal scaling, uniformly in ``h`` (the two-level hierarchical basis method: Bank,
    Dupont and Yserentant 1988; Axelsson and Vassilevski). So a Gauss-Seidel sweep over the
    whole block, the P1 AMG V-cycle on the vertex DOFs and a backward sweep make a
    symmetric cycle::

        x  = GS_forward(A, r)
        x += I_1 AMG_11(r - A x)|_1
        x  = GS_backward(A, r) from x

    Written here because pyamg's aggregation needs a nonzero near-nullspace on every node,
    and the rigid motions vanish on the hierarchical edge functions.
    """

    def __init__(self, linear: np.ndarray, amg: _AMG) -> None:
        self.linear = np.flatnonzero(linear)
        self.amg = amg
        self.A: sp.csr_matrix | None = None
        self._sub = PatternGather(lambda A: A[self.linear][:, self.linear])

    @property
    def ml(self):
        return self.amg.ml

    def setup(self, A: sp.spmatrix) -> None:
        self.A = sp.csr_matrix(A)
        self.amg.setup(self._sub(self.A))

    def update(self, A: sp.spmatrix) -> None:
        self.A = sp.csr_matrix(A)
        self.amg.update(self._sub(self.A))

    def __call__(self, r: np.ndarray) -> np.ndarray:
        from pyamg.relaxation.relaxation import gauss_seidel

        A = self.A
        x = np.zeros_like(r)
        gauss_seidel(A, x, r, iterations=1, sweep="forward")
        d = r - threaded(A) @ x
        x[self.linear] += self.amg(d[self.linear])
        gauss_seidel(A, x, r, iterations=1, sweep="backward")
        return x

    def describe(self) -> str:
        return f"P1 part: {self.amg.describe()}, Gauss-Seidel on the P2 block"

    def release(self) -> None:
        self.amg.release()
        self.A = None
        self._sub = PatternGather(self._sub.transform)


class BlockKrylovSolver:
    """GMRES / MINRES with an AMG block preconditioner for ``K x = r`` (the MINI tangent;
    Taylor-Hood's with a two-level cycle on its P2 block, :class:`_HierarchicalTwoLevel`).

    ``K`` may have more rows than ``is_u``: the extra trailing rows and columns are further
    multipliers (the active contact constraints of a primal-dual active set, with a zero
    diagonal block); their number may change from one solve to the next. Their Schur
    complement is approximated by ``diag(B_c diag(A)^-1 B_c^T)``.

    Args:
        is_u: (n_free,) True at displacement DOFs among the free DOFs.
        layout: vertex and component of each free displacement DOF (for the rigid-body
            near-nullspace and the node blocks of the AMG).
        schur_mass: (n_free_p, n_free_p) pressure mass matrix weighted by ``1/mu``; needed
            for ``schur="mass"`` only.
        method: ``"gmres"`` (block triangular) or ``"minres"`` (block diagonal, needs an SPD
            displacement preconditioner: give ``reference``).
        schur: ``"simple"``: ``S~ = C + B diag(A)^-1 B^T``, inverted by one AMG V-cycle;
            ``"mass"``: ``S~ = diag(M_p / mu + C)``.
        rtol: default relative tolerance on the true residual ``|r - K x| / |r|``.
        maxiter: Krylov iteration budget per solve (all restarts included).
        restart: GMRES restart length (basis vectors kept).
        refresh_factor: rebuild the AMG when a solve takes more than this times the
            iterations of the first solve after the last setup.
        amg: extra keyword arguments for ``pyamg.smoothed_aggregation_solver`` (both blocks).
        reference: an SPD displacement matrix (free u DOFs) to build the displacement AMG on,
            once, instead of the tangent's displacement block (see
            :func:`reference_stiffness`).
        schur_drop: with ``schur="simple"``, couplings of ``S~`` weaker than this times
            ``sqrt(|S_ii S_jj|)`` are dropped and lumped onto the diagonal before its AMG
            (see :data:`SCHUR_DROP`); 0 keeps ``S~`` whole.
        schur_reuse: with ``schur="simple"``, keep ``S~`` and its AMG from one solve to the
            next until :meth:`renew_schur` (Newton calls it at each load step) or a refresh;
            False rebuilds ``S~`` for every matrix.
    """

    def __init__(
        self,
        is_u: np.ndarray,
        layout: DisplacementLayout,
        schur_mass: sp.spmatrix | None = None,
        method: str = "gmres",
        schur: str = "simple",
        rtol: float = 1e-8,
        maxiter: int = 1000,
        restart: int = 100,
        refresh_factor: float = 1.5,
        amg: dict | None = None,
        reference: sp.spmatrix | None = None,
        schur_drop: float = SCHUR_DROP,
        schur_reuse: bool = True,
    ) -> None:
        if method not in METHODS:
            raise InputError(f"unknown Krylov method {method!r}; choose one of {METHODS}")
        if schur not in SCHUR:
            raise InputError(f"unknown Schur approximation {schur!r}; choose one of {SCHUR}")
        self.is_u = np.asarray(is_u, dtype=bool)
        self.iu = np.flatnonzero(self.is_u)
        self.ip = np.flatnonzero(~self.is_u)
        if len(layout.vertex) != len(self.iu):
            raise InputError("layout and is_u disagree on the number of displacement DOFs")
        if schur == "mass":
            if schur_mass is None or schur_mass.shape != (len(self.ip), len(self.ip)):
                raise InputError("schur='mass' needs schur_mass over the free pressure DOFs")
            self.mass_diag = np.asarray(schur_mass.diagonal(), dtype=float)
        self.layout = layout
        self.method = method
        self.schur = schur
        self.rtol = rtol
        self.maxiter = maxiter
        self.restart = restart
        self.refresh_factor = refresh_factor
        self.reference = reference
        self.schur_drop = schur_drop
        self.schur_reuse = schur_reuse
        self._schur_stale = True  # S~ to be rebuilt at the next solve
        self.stats = KrylovStats()
        self._ref_iterations: int | None = None
        self._refresh_requested = False
        self._ready = False
        self._block_plans: tuple[PatternGather, ...] = ()
        self._block_plans_rows = -1
        # displacement AMG on node blocks of the P1 DOFs: slot = dim * node + component
        lin = layout.linear
        nodes, node_idx = np.unique(layout.vertex[lin], return_inverse=True)
        dim = layout.dim
        slot = dim * node_idx + layout.component[lin]
        B = np.zeros((dim * len(nodes), 3 if dim == 2 else 6))
        B[slot] = layout.rigid_body_modes()[lin]
        amg_1 = _AMG(dim * len(nodes), slot, dim, B, amg or {})
        # MINI: the AMG alone; Taylor-Hood: around it, Gauss-Seidel on the P2 block
        self._amg_u = amg_1 if lin.all() else _HierarchicalTwoLevel(lin, amg_1)
        self._amg_p = _AMG(len(self.ip), np.arange(len(self.ip)), 1, None, amg or {})

    @classmethod
    def from_form(cls, form, **options) -> BlockKrylovSolver:
        """Everything the constructor needs, from a MINI or Taylor-Hood :class:`MixedForm`."""
        free = free_dofs(form)
        rng = form.fes.Range(0)
        is_u = (free >= rng.start) & (free < rng.stop)
        mass = pressure_schur_mass(form, free) if options.get("schur") == "mass" else None
        return cls(is_u, displacement_layout(form, free), mass, **options)

    # --- set-up and reuse ----------------------------------------------------------------
    def _blocks(self, K: sp.csr_matrix) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
        """``A``, ``B^T`` and ``C`` over the multiplier DOFs: the pressures, then any rows of
        ``K`` beyond ``len(is_u)`` (e.g. contact multipliers of an active set)."""
        n0 = len(self.is_u)
        if K.shape[0] < n0:
            raise InputError(f"the matrix has {K.shape[0]} rows, fewer than is_u ({n0})")
        if self._block_plans_rows != K.shape[0]:  # another number of multiplier rows
            iu, iq = self.iu, np.concatenate([self.ip, np.arange(n0, K.shape[0])])
            self._block_plans = (PatternGather(lambda M: M[iu][:, iu]),
                                 PatternGather(lambda M: M[iu][:, iq]),
                                 PatternGather(lambda M: M[iq][:, iq]))
            self._block_plans_rows = K.shape[0]
        A, Bt, Cneg = (plan(K) for plan in self._block_plans)
        return A, Bt, -Cneg

    def _d_inv(self, A: sp.csr_matrix) -> np.ndarray:
        d = np.abs(A.diagonal())
        return np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)

    def _schur_simple(self, A, Bt, C) -> sp.csr_matrix:
        """``C + B diag(A)^-1 B^T`` (SIMPLE's Schur complement) over the pressures."""
        n_p = len(self.ip)
        Bt = Bt[:, :n_p]
        S = (Bt.T @ sp.diags(self._d_inv(A)) @ Bt + C[:n_p][:, :n_p]).tocsr()
        if self.schur_drop > 0:
            # drop weak couplings (most of the distance-2 stencil of B D^-1 B^T) and add
            # their magnitude to the diagonal: stays SPD, a cheaper V-cycle
            coo = S.tocoo()
            dg = S.diagonal()
            weak = np.abs(coo.data) < self.schur_drop * np.sqrt(
                np.abs(dg[coo.row] * dg[coo.col]))
            weak &= coo.row != coo.col
            lump = np.bincount(coo.row[weak], np.abs(coo.data[weak]), minlength=S.shape[0])
            keep = ~weak
            S = sp.csr_matrix((coo.data[keep], (coo.row[keep], coo.col[keep])), shape=S.shape)
            S = (S + sp.diags(lump)).tocsr()
        return S

    def setup(self, K: sp.csr_matrix) -> None:
        """Build the AMG hierarchies (displacement block, and the Schur approximation)."""
        t0 = time.perf_counter()
        A, Bt, C = self._blocks(K)
        self._amg_u.setup(self.reference if self.reference is not None else A)
        if self.schur == "simple":
            self._amg_p.setup(self._schur_simple(A, Bt, C))
        self._schur_stale = False
        self._ready = True
        self._ref_iterations = None
        self._refresh_requested = False
        self.stats.setups += 1
        self.stats.setup_time_s += time.perf_counter() - t0
        log.debug("AMG setup %.2f s: displacements %s", time.perf_counter() - t0,
                  self._amg_u.describe())

    def refresh(self) -> None:
        """Rebuild the AMG hierarchies at the next solve."""
        self._refresh_requested = True

    def renew_schur(self) -> None:
        """Rebuild ``S~`` (and its finest AMG level) at the next solve: a new load step."""
        self._schur_stale = True

    def new_load_step(self) -> None:
        """:class:`brainbulge.solver.linear.LinearSolver`'s hook: a new load step renews
        ``S~`` (:meth:`renew_schur`)."""
        self.renew_schur()

    def release(self) -> None:
        """Free the AMG hierarchies and the sparse plans (a later solve makes them again)."""
        self._amg_u.release()
        self._amg_p.release()
        self._block_plans, self._block_plans_rows = (), -1
        self._ready = False

    def _update(self, K: sp.csr_matrix) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
        """New matrix: rebuild the hierarchies or reuse them (finest level refreshed)."""
        if not self._ready or self._refresh_requested:
            self.setup(K)
            return self._blocks(K)
        A, Bt, C = self._blocks(K)
        if self.reference is None:
            self._amg_u.update(A)
        if self.schur == "simple" and (self._schur_stale or not self.schur_reuse):
            self._amg_p.update(self._schur_simple(A, Bt, C))
            self._schur_stale = False
        return A, Bt, C

    # --- preconditioner ------------------------------------------------------------------
    def _preconditioner(self, A, Bt, C) -> Callable[[np.ndarray], np.ndarray]:
        iu = self.iu
        n0, n_p = len(self.is_u), len(self.ip)
        iq = np.concatenate([self.ip, np.arange(n0, n0 + Bt.shape[1] - n_p)])
        amg_u = self._amg_u
        # extra multipliers (rows beyond is_u): diag(B D^-1 B^T + C) of their own
        d_inv = self._d_inv(A)
        Bt_e = Bt[:, n_p:]
        e_diag = (Bt_e.multiply(Bt_e)).T @ d_inv + np.maximum(C.diagonal()[n_p:], 0.0)
        e_inv = np.divide(1.0, e_diag, out=np.zeros_like(e_diag), where=e_diag > 0)
        if self.schur == "simple":
            amg_p = self._amg_p
        else:
            if self.schur == "mass":
                s_diag = self.mass_diag + np.maximum(C.diagonal()[:n_p], 0.0)
            else:
                s_diag = self._schur_simple(A, Bt, C).diagonal()
            # pressure DOFs that no element couples (empty rows of K, zero mass) stay zero
            s_inv = np.divide(1.0, s_diag, out=np.zeros_like(s_diag), where=s_diag > 0)

            def amg_p(rp: np.ndarray) -> np.ndarray:
                return s_inv * rp

        def schur_inv(rq: np.ndarray) -> np.ndarray:
            return np.concatenate([amg_p(rq[:n_p]), e_inv * rq[n_p:]])

        if self.method == "minres":

            def apply(r: np.ndarray) -> np.ndarray:
                z = np.empty_like(r)
                z[iu] = amg_u(r[iu])
                z[iq] = schur_inv(r[iq])
                return z

            return apply

        def apply_tri(r: np.ndarray) -> np.ndarray:
            z = np.empty_like(r)
            zq = -schur_inv(r[iq])
            z[iq] = zq
            z[iu] = amg_u(r[iu] - Bt @ zq)
            return z

        return apply_tri

    # --- solve ---------------------------------------------------------------------------
    def solve(self, K: sp.csr_matrix, r: np.ndarray, rtol: float | None = None,
              x0: np.ndarray | None = None) -> np.ndarray:
        """``x`` with ``|r - K x| <= rtol |r|`` (true residual), else ConvergenceError.

        ``x0``: an initial guess (e.g. the solution of a nearby system); the tolerance stays
        relative to ``|r|``.
        """
        rtol = self.rtol if rtol is None else rtol
        t0 = time.perf_counter()
        A, Bt, C = self._update(K)
        K, Bt = threaded(K), threaded(Bt)  # Krylov and block products on all cores
        with serial_openblas():  # small BLAS-2 work: threads cost more than they give
            x, its, res = self._krylov(K, r, rtol, self._preconditioner(A, Bt, C), x0)
        if self._ref_iterations is None:
            self._ref_iterations = max(its, 1)
        elif its > self.refresh_factor * self._ref_iterations:
            log.debug("Krylov iterations %d > %.2g x %d: AMG refresh", its,
                      self.refresh_factor, self._ref_iterations)
            self._refresh_requested = True
        log.debug("    %s: %d iterations, relative residual %.1e (%.1f s)", self.method, its,
                  res, time.perf_counter() - t0)
        self.stats.solves += 1
        self.stats.iterations.append(its)
        self.stats.residuals.append(res)
        self.stats.solve_time_s += time.perf_counter() - t0
        if not res <= rtol:
            self._refresh_requested = True
            raise ConvergenceError(
                f"{self.method} reached a relative residual of {res:.2e} > {rtol:.1e} in "
                f"{its} iterations; raise maxiter or use the direct solver")
        return x

    def _krylov(self, K, r: np.ndarray, rtol: float, M,
                x0: np.ndarray | None = None) -> tuple[np.ndarray, int, float]:
        """Restarted Krylov on the true defect until the true residual meets ``rtol``."""
        r = np.asarray(r, dtype=float)
        norm_r = float(np.linalg.norm(r))
        x = np.zeros_like(r)
        if norm_r == 0.0:
            return x, 0, 0.0
        its = 0
        inner_rtol = rtol
        res = 1.0
        defect = r
        if x0 is not None and x0.shape == r.shape:
            defect = r - K @ x0
            res = float(np.linalg.norm(defect)) / norm_r
            if res < 1.0:  # a guess worse than zero is dropped
                x = np.array(x0, dtype=float)
                if res <= rtol:
                    return x, 0, res
            else:
                defect, res = r, 1.0
        while its < self.maxiter:
            target = inner_rtol * norm_r / np.linalg.norm(defect)
            if self.method == "minres":
                dx, k, est = _minres(K, defect, M, target, self.maxiter - its)
            else:
                dx, k, est = _gmres(K, defect, M, target, self.maxiter - its, self.restart)
            x += dx
            its += k
            defect = r - K @ x
            res = float(np.linalg.norm(defect)) / norm_r
            if not np.isfinite(res):
                return x, its, np.inf
            if res <= rtol or k == 0:
                return x, its, res
            # the Krylov estimate (MINRES: in the preconditioner's norm) was optimistic:
            # restart from the true defect asking for more than the remaining reduction
            inner_rtol = max(inner_rtol * rtol / res, 1e-16)
        return x, its, res


def _minres(K, b: np.ndarray, M, rtol: float, maxiter: int) -> tuple[np.ndarray, int, float]:
    """Preconditioned MINRES (Elman, Silvester & Wathen, Algorithm 4.1), ``x0 = 0``.

    Stops when the ``M^-1``-norm of the residual has dropped by ``rtol``; returns
    ``(x, iterations, estimated relative residual in that norm)``.
    """
    n = len(b)
    x = np.zeros(n)
    v_old = np.zeros(n)
    v = b.copy()
    z = M(v)
    gamma = np.sqrt(max(float(v @ z), 0.0))
    if gamma == 0.0:
        return x, 0, 0.0
    eta0 = eta = gamma
    gamma_old = 1.0
    s_old = s = 0.0
    c_old = c = 1.0
    w_old = np.zeros(n)
    w = np.zeros(n)
    for j in range(1, maxiter + 1):
        z /= gamma
        Az = K @ z
        delta = float(Az @ z)
        v_new = Az - (delta / gamma) * v - (gamma / gamma_old) * v_old
        z_new = M(v_new)
        vz = float(v_new @ z_new)
        if vz < 0:
            raise ConvergenceError(
                "MINRES needs a positive definite preconditioner and this one is not (an "
                "indefinite displacement block): use method='gmres' or an SPD reference")
        gamma_new = np.sqrt(vz)
        a0 = c * delta - c_old * s * gamma
        a1 = np.hypot(a0, gamma_new)
        a2 = s * delta + c_old * c * gamma
        a3 = s_old * gamma
        c_old, c = c, a0 / a1
        s_old, s = s, gamma_new / a1
        w_new = (z - a3 * w_old - a2 * w) / a1
        x += (c * eta) * w_new
        eta = -s * eta
        w_old, w = w, w_new
        v_old, v = v, v_new
        z = z_new
        gamma_old, gamma = gamma, gamma_new
        if abs(eta) <= rtol * eta0 or gamma == 0.0:
            return x, j, abs(eta) / eta0
    return x, maxiter, abs(eta) / eta0


def _gmres(K, b: np.ndarray, M, rtol: float, maxiter: int,
           restart: int) -> tuple[np.ndarray, int, float]:
    """Right-preconditioned restarted GMRES, ``x0 = 0``; the residual it tracks is the true
    one (up to rounding). Returns ``(x, iterations, estimated relative residual)``.

    ``M`` is linear (AMG V-cycles with fixed smoothers, block substitutions), so the update of
    a cycle is ``x += M(V_k y)`` with one more application of ``M``, instead of keeping the
    preconditioned vectors ``Z_k = M V_k`` (flexible GMRES): half the basis memory, and half
    of its fresh pages, which are what a large basis costs here (a 60-row basis at 6M DOFs:
    0.6-10 s to fault in on this VM against 0.2 s to rewrite touched rows).
    """
    n = len(b)
    x = np.zeros(n)
    norm_b = float(np.linalg.norm(b))
    its = 0
    r = b.copy()
    beta = norm_b
    while its < maxiter:
        m = min(restart, maxiter - its)
        V = np.empty((m + 1, n))  # rows are written before they are read
        H = np.zeros((m + 1, m))
        cs = np.zeros(m)
        sn = np.zeros(m)
        g = np.zeros(m + 1)
        g[0] = beta
        V[0] = r / beta
        k = 0
        for k in range(m):
            w = K @ M(V[k])
            # classical Gram-Schmidt, twice (BLAS-2 on the basis)
            h = V[: k + 1] @ w
            w -= h @ V[: k + 1]
            h2 = V[: k + 1] @ w
            w -= h2 @ V[: k + 1]
            h += h2
            H[: k + 1, k] = h
            H[k + 1, k] = np.linalg.norm(w)
            if H[k + 1, k] > 0:
                V[k + 1] = w / H[k + 1, k]
            for i in range(k):  # apply the previous rotations
                t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
                H[i + 1, k] = -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
                H[i, k] = t
            d = np.hypot(H[k, k], H[k + 1, k])
            cs[k], sn[k] = H[k, k] / d, H[k + 1, k] / d
            H[k, k] = d
            H[k + 1, k] = 0.0
            g[k + 1] = -sn[k] * g[k]
            g[k] = cs[k] * g[k]
            its += 1
            if abs(g[k + 1]) <= rtol * norm_b or H[k, k] == 0:
                break
        k += 1
        y = np.linalg.solve(np.triu(H[:k, :k]), g[:k])
        x += M(y @ V[:k])
        r = b - K @ x
        beta = float(np.linalg.norm(r))
        if beta <= rtol * norm_b:
            break
    return x, its, beta / norm_b
