"""The resolved skull edge in 2D, prototype: one contact constraint against a rounded skull.

The paper's skull ``S = {r >= R, |delta| >= beta/2}`` (``delta`` the angle from the
opening's centre) with its edge rounded by ``rho``, two ways (``--rounding``):

- ``turned``: the points within ``rho`` of the core ``{R + rho <= r <= R + T - rho,
  |delta| >= beta/2}`` (``RigidSkull2D`` with a thickness ``T`` far beyond any bulge). The
  inner surface is the circle ``r = R`` up to the nominal edge angle; there it turns outward
  on a circle of radius ``rho`` into the end face, ``rho`` inside the opening.
- ``opened``: ``S`` opened by a disk of radius ``rho`` (:class:`OpenedSkull`): the arc ends
  about ``rho`` into the bone, the end face stays on the nominal edge's ray.

Either gap ``g`` is the exact signed distance outside the skull (C1). The whole material arc
(under the skull and in the opening) is in frictionless contact with it (``--law``): by the
product's exact multipliers at the contact points (``multipliers``), or by a penalty
``kappa/2 max(-g, 0)^2`` at 5 Gauss points per boundary edge (``penalty``, ``--kappa``), so
that a point sliding past the edge is released continuously and tissue bulging out cannot
enter the end face. No held arc, no rezoning, no hotspot relaxation.

Per run: load reached, Newton iterations, wall time, the top-of-bulge displacement ``u_y(0,
R)`` [R], the largest crossing of the deformed boundary (8 points per boundary segment) into
the rounded skull and into the sharp ``S`` [R], how far the skull side's material slid along
the arc [deg], and the smallest ``J`` of the P1 part.

Options: ``--rho`` (in R; the edge's mesh size is ``rho / --hc-ratio`` from 8 degrees
before to 8 degrees past the edge), ``--h``, ``--full`` (else the half domain, ``u_x = 0`` on
the symmetry axis), ``--steps`` (equal load steps, grown by the ramp), ``--trust`` (an update
never moves a vertex more than this fraction of its smallest incident edge; 0: off;
``--trust-max``: the radius doubles while the residual falls), ``--no-line-search`` (the
capped step is taken as it is), ``--element``. The Newton study (docs/design.md): ``--ramp
slide`` (increments sized by the slide near the edge, :mod:`edge2d_ramp`) with
``--predictor none``, ``--law augmented`` (the penalty's multipliers on the Gauss points,
updated after each load step), the step bounds ``--jcap`` (by ``J``), ``--trust-normal``
(the normal moves near the skull), ``--cap-near`` (the cap near the rounding only),
``--cap-mode local``, ``--soc`` (a second-order correction), ``--frozen`` (no curvature
term), ``--finite``, ``--inter-tol``; ``--trace`` and ``--sweep`` (:mod:`edge2d_report`).
``newton_all`` counts every Newton iteration, failed attempts included.

Rerun: ``python benchmarks/bench_edge_2d.py --table`` (every row, each in its own process;
about 30 min on 2 cores alone).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time

import numpy as np

from edge2d_geometry import THICKNESS, OpenedSkull, mesh

#: the benchmark's rows: overrides of :data:`DEFAULTS` (docs/design.md's record)
DEFAULTS = {"alpha": 80.0, "beta": 60.0, "contact": "sliding", "rho": 0.03, "h": 0.05,
            "half": True, "steps": 40, "trust": 0.2, "element": "mini", "line_search": True,
            "rounding": "turned", "hc_ratio": 3.0, "law": "multipliers"}
PENALTY = {"law": "penalty", "line_search": False}
TABLE = [
    # the product's exact multipliers at the contact points
    {}, {"half": False}, {"contact": "noslip"}, {"element": "taylor-hood"},
    {"steps": 10, "trust": 0.0}, {"h": 0.035}, {"rho": 0.05}, {"rho": 0.015},
    *({"alpha": a, "beta": 30.0, **v} for a in (60.0, 80.0) for v in (
        {}, {"line_search": False}, {"line_search": False, "hc_ratio": 5.0},
        {"rounding": "opened"}, {"element": "taylor-hood", "line_search": False})),
    # a penalty at 5 Gauss points per boundary edge
    PENALTY, {**PENALTY, "element": "taylor-hood"},
    {**PENALTY, "element": "taylor-hood", "half": False},
    *({"alpha": a, "beta": 30.0, **PENALTY, "element": el} for a in (60.0, 80.0)
      for el in ("mini", "taylor-hood")),
]


def run(alpha: float, beta: float, contact: str, rho: float, h: float, half: bool,
        steps: int, trust: float, element: str = "mini", max_iterations: int = 20,
        line_search: bool = True, rounding: str = "turned", hc_ratio: float = 3.0,
        law: str = "multipliers", kappa: float = 1e7, trust_max: float = 0.0,
        onset: float = 0.0, trace: bool = False, frozen: bool = False,
        inter_tol: float = 1e-6, ramp: str = "fixed", slide: float = 1.0,
        dt0: float = 0.05, predictor: str = "secant", cap_mode: str = "global",
        finite_backtrack: bool = False, soc: bool = False, jcap: float = 0.0,
        al_tol: float = 2e-4, al_passes: int = 6, budget: int = 400,
        trust_normal: float = 0.0, cap_near: float = 0.0) -> dict:
    import ngsolve as ngs

    from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_coordinates
    from brainbulge.geometry.skull2d import RigidSkull2D
    from brainbulge.materials import preset
    from brainbulge.model.problem import Contact, Problem
    from brainbulge.solver import newton as newton_mod
    from brainbulge.solver.mixed import MixedForm
    from brainbulge.solver.options import SolverOptions
    from brainbulge.solver.ramp import NewtonSolver

    R = 1.0
    hc = rho / hc_ratio
    m = mesh(R, alpha, beta, h, hc, rho, half=half)
    skull = (OpenedSkull(R, beta, rho) if rounding == "opened" else
             RigidSkull2D(R=R, beta_deg=beta, center_deg=90.0, thickness=THICKNESS,
                          edge_radius=rho))
    mat = preset("paper")["gray"]
    materials = {r: mat for r in set(m.GetMaterials())}
    sym = {0: "symmetry"} if half else {}
    if contact == "sliding" and law != "multipliers":  # the contact is in the energy
        problem = Problem(m, materials, {"swelling": 1.2}, clamped="base",
                          clamped_components=sym)
    elif contact == "sliding":
        problem = Problem(m, materials, {"swelling": 1.2}, clamped="base",
                          clamped_components=sym,
                          contacts=[Contact("skull|opening", skull)])
    else:  # noslip: the skull's arc clamped, the opening in contact (the energy's, or here)
        problem = Problem(m, materials, {"swelling": 1.2}, clamped="base|skull",
                          clamped_components=sym,
                          contacts=[Contact("opening", skull)] if law == "multipliers" else [])
    form = MixedForm(problem, element=element)
    al = None
    if law == "augmented":  # (1/2 kappa) max(lam + kappa s, 0)^2, lam per Gauss point
        ir = ngs.IntegrationRule(ngs.SEGM, 9)
        dsg = ngs.ds("skull|opening", intrules={ngs.SEGM: ir})
        L = ngs.SurfaceL2(m, order=4, definedon=m.Boundaries("skull|opening"))
        lam = ngs.GridFunction(L)
        lu, lv = L.TnT()
        Minv = ngs.BilinearForm(lu * lv * dsg).Assemble().mat.Inverse(
            L.FreeDofs(), inverse="sparsecholesky")
        u = form.fes.TrialFunction()[0]
        s = -skull.gap(ngs.CF((ngs.x + u[0], ngs.y + u[1])))
        q = lam + kappa * s
        form.a += ngs.Variation(ngs.IfPos(q, q * q, 0) / (2 * kappa) * dsg)
        gu = form.gfu.components[0]
        q_state = lam - kappa * skull.gap(ngs.CF((ngs.x + gu[0], ngs.y + gu[1])))
        gp = m.MapToAllElements(ir, m.Boundaries("skull|opening"))
        pen_cf = ngs.IfPos(q_state, 1.0, 0.0)
        pen_depth = -skull.gap(ngs.CF((ngs.x + gu[0], ngs.y + gu[1])))

        def al_update() -> None:
            f = ngs.LinearForm(ngs.IfPos(q_state, q_state, 0) * lv * dsg).Assemble()
            lam.vec.data = Minv * f.vec

        al = (al_update, lambda: float(np.max(np.asarray(pen_depth(gp)))))
    if law == "penalty":
        # kappa/2 max(-g, 0)^2 over the material arc, at 5 Gauss points per edge for P2
        u = form.fes.TrialFunction()[0]
        if frozen:  # the gap linearised at the current state: no curvature in the tangent
            gu = form.gfu.components[0]  # the state Newton works on (x is gfu.vec)
            xk = ngs.CF((ngs.x + gu[0], ngs.y + gu[1]))
            eps = 1e-6
            nk = [(skull.gap(xk + eps * ngs.CF(ei)) - skull.gap(xk - eps * ngs.CF(ei)))
                  / (2 * eps) for ei in ((1, 0), (0, 1))]
            g = skull.gap(xk) + nk[0] * (u[0] - gu[0]) + nk[1] * (u[1] - gu[1])
        else:
            g = skull.gap(ngs.CF((ngs.x + u[0], ngs.y + u[1])))
        s = ngs.IfPos(-g, -g, 0)  # penetration
        if onset > 0:  # C2: cubic up to the onset depth, then the quadratic
            e = ngs.IfPos(s - onset, 0.5 * kappa * (s * s - onset * s + onset**2 / 3),
                          kappa * s * s * s / (6 * onset))
        else:
            e = 0.5 * kappa * s * s
        form.a += ngs.Variation(e * ngs.ds("skull|opening", bonus_intorder=5))
        # the penalty's Gauss points (order 9 on a segment: the 5 points of the integral)
        gp = m.MapToAllElements(ngs.IntegrationRule(ngs.SEGM, 9), m.Boundaries("skull|opening"))
        gu = form.gfu.components[0]
        pen_cf = ngs.IfPos(-skull.gap(ngs.CF((ngs.x + gu[0], ngs.y + gu[1]))), 1.0, 0.0)
    opt = SolverOptions(steps=steps, hotspot_relaxation=False, max_iterations=max_iterations,
                        closed_form=law == "multipliers", intermediate_tolerance=inter_tol)
    solver = NewtonSolver(form, opt)

    # the trust region: scale each Newton update so that no vertex moves more than
    # `trust` times its smallest incident edge
    X = vertex_coordinates(m)
    els, _ = element_vertices(m)
    hv = np.full(len(X), np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        L = np.linalg.norm(X[els[:, a]] - X[els[:, b]], axis=1)
        np.minimum.at(hv, els[:, a], L)
        np.minimum.at(hv, els[:, b], L)
    from brainbulge.geometry.ngsolve_arrays import vertex_dofs

    V = form.fes.components[0]
    vd = vertex_dofs(V, m) + form.fes.Range(0).start
    limited = [0]
    # the rounding's centres (the end face's side of each edge): the near-edge cap's
    half_b = math.radians(beta / 2)
    centres = [(R + rho) * np.array([math.cos(math.pi / 2 + sg * half_b),
                                     math.sin(math.pi / 2 + sg * half_b)])
               for sg in ((1,) if half else (1, -1))]
    dof_factor_map = (None, None)
    if cap_mode == "local":  # (element, DOF) pairs: a DOF's factor is its elements' least
        pe, pd = [], []
        for k, el in enumerate(m.Elements(ngs.VOL)):
            dn = [d for d in form.fes.GetDofNrs(el) if d >= 0]
            pe += [k] * len(dn)
            pd += dn
        dof_factor_map = (np.array(pe), np.array(pd))
    # the trace: per Newton iteration (load, cap factor, |R| after, penetrating Gauss
    # points, how many entered / left the penetrating set)
    its_log: list[tuple] = []
    last_set = [None]

    def record(f, trial):
        if not trace:
            return
        n_in = n_out = n_act = -1
        if law != "multipliers":
            act = np.asarray(pen_cf(gp)).ravel() > 0.5
            n_act = int(act.sum())
            if last_set[0] is not None:
                n_in = int((act & ~last_set[0]).sum())
                n_out = int((~act & last_set[0]).sum())
            last_set[0] = act
        its_log.append((float(form.load.Get()), f, trial, n_act, n_in, n_out))
    radius = [trust]  # the trust region's radius, in local edge lengths
    newton_tol = [0.0]  # the tolerance of the Newton solve running (its Armijo test's)

    def armijo(eq, state, x0, dx, dlams, norm, tol, retry, opt):
        """The backtracking line search the product once had (``s`` halved from 1 until
        ``|R| < (1 - 1e-4 s) |R_0|``, down to 1/1024): the comparison rows with a line
        search."""
        x, s = state.x, 1.0
        while True:
            x.data = x0.x - s * dx
            state.set_multipliers([l0 - s * dl for l0, dl in zip(x0.lam, dlams, strict=True)])
            trial = eq.scaled_norm(eq.residual(x))
            if trial < (1 - 1e-4 * s) * norm or trial <= tol:
                return s, trial
            s *= 0.5
            if s < 1 / 1024:
                state.restore(x0)
                return None, trial

    def step(eq, opt, x0, limit_step, run):
        """Newton's iteration (solver/newton.py's ``_step``: the direction, scaled by the
        options' step limit) with the prototype's step bounds and update (:func:`capped`)."""
        x = eq.state.x
        dx, dlams = eq.newton_direction(x, eq.tangent(x), run.eta)
        f = 1.0 if limit_step is None else limit_step(x, dx)
        if f < 1:
            dx.data = f * dx
            dlams = [f * d for d in dlams]
        return capped(eq, eq.state, x0, dx, dlams, run.residuals[-1], newton_tol[0], False,
                      opt)

    def capped(eq, state, x0, dx, dlams, norm, tol, retry, opt):
        """Newton's line search (solver/newton.py) with the prototype's step bounds before it
        (or instead of it, without the line search); ``x0`` the state's snapshot."""
        x = state.x
        f = 1.0
        if jcap > 0:  # the largest step keeping J >= jcap J(x0) at the integration points
            f = j_step(dx)
        if trust > 0:
            d = dx.FV().NumPy()[vd]
            move = np.linalg.norm(d, axis=1) / hv
            if cap_near > 0:  # only the vertices near the rounded edge are capped
                pos = X + x0.x.FV().NumPy()[vd]
                dist = np.min([np.linalg.norm(pos - c, axis=1) for c in centres], axis=0)
                move = np.where(dist < cap_near * rho, move, 0.0)
            fm = radius[0] / max(move.max(), 1e-300)
            if fm < 1 and trace:
                iv = int(np.argmax(move))
                p = X[iv]
                print(f"  load {float(form.load.Get()):.4f} cap {fm:.2f} at r "
                      f"{np.hypot(*p):.4f} theta {np.degrees(np.arctan2(p[1], p[0])):.2f} "
                      f"hv {hv[iv]:.4f} moves {np.linalg.norm(d[iv]):.2e}", file=sys.stderr)
            if fm < 1 and cap_mode == "local":  # each element's DOFs by its vertices' cap
                fv = np.minimum(radius[0] / np.maximum(move, 1e-300), 1.0)
                fd = np.ones(form.fes.ndof)
                np.minimum.at(fd, dof_factor_map[1], fv[els].min(axis=1)[dof_factor_map[0]])
                dx.FV().NumPy()[:] *= fd
                limited[0] += 1
            else:
                f = min(f, fm)
        if trust_normal > 0:  # the boundary's moves along the skull's normal, near it
            a0 = x0.x.FV().NumPy()
            p0 = X[bverts] + a0[vd_b]
            g0, n0 = skull.gap_and_normal(p0)
            dn = np.abs(np.einsum("ij,ij->i", n0, dx.FV().NumPy()[vd_b]))
            near_skull = g0 < hv[bverts]
            fn = trust_normal * hv[bverts] / np.maximum(dn, 1e-300)
            f = min(f, float(fn[near_skull].min(initial=1.0)))
        if f < 1:
            limited[0] += 1
            dx.data = f * dx
            dlams = [f * dl for dl in dlams]
        if not line_search:  # the capped step is taken whatever the residual does
            sc = 1.0
            while True:  # halved only while the trial state is not finite (inverted)
                x.data = x0.x - sc * dx
                state.set_multipliers([l0 - sc * dl for l0, dl in zip(x0.lam, dlams,
                                                                       strict=True)])
                if soc:
                    second_order_correction(x0.x, x)
                trial = eq.scaled_norm(eq.residual(x))
                if np.isfinite(trial) or not finite_backtrack or sc < 1 / 64:
                    break
                sc *= 0.5
            f *= sc
            record(f, trial)
            if trust_max > trust:  # the radius grows while the residual falls
                radius[0] = (min(2 * radius[0], trust_max) if trial < norm
                             else max(radius[0] / 2, trust))
            return 1.0, trial
        out = armijo(eq, state, x0, dx, dlams, norm, tol, retry, opt)
        record(f * (out[0] or 0.0), out[1])
        return out

    # the step bound by J: det(F - f G) = jcap det F at the first such f > 0
    gdu = ngs.GridFunction(V)
    urange = form.fes.Range(0)
    jpts = m.MapToAllElements(ngs.IntegrationRule(ngs.TRIG, 4), ngs.VOL)
    uF = form.gfu.components[0]

    def j_step(dx) -> float:
        gdu.vec.FV().NumPy()[:] = dx.FV().NumPy()[urange.start:urange.stop]
        G = np.asarray(ngs.Grad(gdu)(jpts)).reshape(-1, 2, 2)
        F = np.asarray(ngs.Grad(uF)(jpts)).reshape(-1, 2, 2) + np.eye(2)
        detF = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
        a = G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0]
        b = -(F[:, 1, 1] * G[:, 0, 0] + F[:, 0, 0] * G[:, 1, 1]
              - F[:, 0, 1] * G[:, 1, 0] - F[:, 1, 0] * G[:, 0, 1])
        c = (1 - jcap) * detF
        with np.errstate(invalid="ignore", divide="ignore"):
            disc = np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))
            roots = np.stack([(-b - disc) / (2 * a), (-b + disc) / (2 * a),
                              np.where(b != 0, -c / b, np.inf)])
        roots[:, (b * b - 4 * a * c) < 0] = np.inf
        roots[2, np.abs(a) > 1e-14] = np.inf
        roots[:2, np.abs(a) <= 1e-14] = np.inf
        roots[roots <= 0] = np.inf
        return float(min(roots.min(), 1.0))

    # the boundary vertices in contact with the skull (the second-order correction's)
    bnames = m.GetBoundaries()
    bverts = np.unique([v.nr for el in m.Elements(ngs.BND)
                        if bnames[el.index] in ("skull", "opening") for v in el.vertices])
    vd_b = vd[bverts]

    def second_order_correction(x0, x):
        """Move each penetrating boundary vertex along the skull's normal by what the gap's
        curvature added over the linear prediction (the Maratos effect's correction)."""
        a0, a1 = x0.FV().NumPy(), x.FV().NumPy()
        p0, p1 = X[bverts] + a0[vd_b], X[bverts] + a1[vd_b]
        g0, n0 = skull.gap_and_normal(p0)
        g1, n1 = skull.gap_and_normal(p1)
        glin = g0 + np.einsum("ij,ij->i", n0, p1 - p0)
        c = np.where(g1 < 0, np.maximum(glin - g1, 0.0), 0.0)
        a1[vd_b] += c[:, None] * n1

    newton_mod._step = step
    history: list[tuple[float, ...]] = []  # each Newton solve's scaled residuals

    def newton(tol: float) -> tuple[bool, int, float]:
        """One Newton solve at the form's load from its state (the slide ramp's)."""
        newton_tol[0] = tol
        res = solver.newton(tol)
        history.append(res.residuals)
        return res.converged, res.iterations, res.norm
    t0 = time.perf_counter()
    if ramp == "slide":  # increments sized by the slide near the edge (edge2d_ramp)
        from types import SimpleNamespace

        from edge2d_ramp import ramp as slide_ramp

        th = np.degrees(np.arctan2(X[:, 1], X[:, 0]))
        r = np.hypot(X[:, 0], X[:, 1])
        near = (r > R - 1e-6) & (np.min([np.abs(th - (90 + sg * beta / 2))
                                         for sg in (-1, 1)], axis=0) < 10)
        form.set_load(0.0)
        after = finish = None
        if al is not None:
            def after(x, t):  # the multipliers follow each converged step
                al[0]()
                return 0

            def finish(x):  # Uzawa at full load until the Gauss points' depth is al_tol
                its_all = 0
                for _ in range(al_passes):
                    if al[1]() <= al_tol:
                        return its_all, True
                    al[0]()
                    ok, its, _ = newton(opt.newton.tolerance)
                    its_all += its
                    if not ok:
                        return its_all, False
                return its_all, al[1]() <= al_tol
        rr = slide_ramp(newton, form, boundary_dofs=vd[near], dt0=dt0, target=slide * hc,
                        predictor=predictor, inter_tol=inter_tol,
                        final_tol=opt.newton.tolerance,
                        after_step=after, finish=finish, verbose=trace, budget=budget)
        sol = SimpleNamespace(converged=rr["converged"], load=rr["load"],
                              newton_iterations=rr["newton_all"], rejected_steps=rr["rejected"],
                              describe=lambda: "", accepted=rr["accepted"])
    else:
        sol = solver.solve()
        history = [r.residuals for r in sol.newton_results]
    wall = time.perf_counter() - t0

    u = form.output_displacement() if hasattr(form, "output_displacement") else form.u
    top = float(u(m(0.0, R * (1 - 1e-9)))[1])
    # the deformed boundary, sampled: crossing into the rounded skull and into sharp S
    from bench_hard_cases import region_gap

    bnd = [el for el in m.Elements(ngs.BND)
           if m.GetBoundaries()[el.index] in ("skull", "opening")]
    pts = []
    for el in bnd:
        a, b = (np.array(m[v].point[:2]) for v in el.vertices)
        for s in np.linspace(0, 1, 9):
            p = (1 - s) * a + s * b
            p = R * p / np.linalg.norm(p)  # on the (curved) arc
            pts.append(p)
    P = np.array(pts)
    uP = np.array([u(m(*p * (1 - 1e-12)))[:2] for p in P])
    xP = P + uP
    g_round = skull.gap_and_normal(xP)[0]
    i_worst = int(np.argmin(g_round))
    theta_ref = np.degrees(np.arctan2(P[:, 1], P[:, 0]))
    theta_def = np.degrees(np.arctan2(xP[:, 1], xP[:, 0]))
    skull_side = np.abs(theta_ref - 90) >= beta / 2
    slide = float(np.max(np.abs(theta_def - theta_ref)[skull_side]))
    g_sharp = region_gap(R, beta, 90.0, xP)[0]
    if trace:
        from edge2d_report import print_trace

        print_trace(its_log, history)
    uL = form.output_displacement() if hasattr(form, "output_displacement") else form.u
    JL = ngs.Det(ngs.Id(2) + ngs.Grad(uL))
    Jmin = float(np.min(JL(m.MapToAllElements(ngs.IntegrationRule(ngs.TRIG, 2), ngs.VOL))))
    return {"alpha": alpha, "beta": beta, "contact": contact, "rho": rho, "h": h,
            "half": half, "steps": steps, "trust": trust, "element": element,
            "converged": sol.converged, "load": round(sol.load, 4),
            "newton": sol.newton_iterations,
            "newton_all": sum(len(h) - 1 for h in history), "rejected": sol.rejected_steps,
            "limited": limited[0], "wall_s": round(wall, 1), "top_uy": top,
            "crossing_round": float(max(-g_round.min(), 0)),
            "crossing_sharp": float(max(-g_sharp.min(), 0)), "Jmin": Jmin,
            "slide_deg": slide, "worst_ref_deg": float(theta_ref[i_worst]),
            "worst_def_deg": float(theta_def[i_worst]),
            "ndof": form.fes.ndof, "reason": sol.describe()[:160]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--alpha", type=float, default=80)
    ap.add_argument("--beta", type=float, default=60)
    ap.add_argument("--contact", default="sliding")
    ap.add_argument("--rho", type=float, default=0.03)
    ap.add_argument("--h", type=float, default=0.05)
    ap.add_argument("--full", action="store_true", help="the full domain, not the half")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--trust", type=float, default=0.2)
    ap.add_argument("--element", default="mini")
    ap.add_argument("--no-line-search", action="store_true")
    ap.add_argument("--rounding", default="turned", choices=("turned", "opened"))
    ap.add_argument("--hc-ratio", type=float, default=3.0, help="rho / edge mesh size")
    ap.add_argument("--trust-max", type=float, default=0.0,
                    help="the trust radius doubles while the residual falls, up to this")
    ap.add_argument("--law", default="multipliers",
                    choices=("multipliers", "penalty", "augmented"))
    ap.add_argument("--al-tol", type=float, default=2e-4,
                    help="augmented: Uzawa passes at full load until no Gauss point is "
                    "deeper than this [R]")
    ap.add_argument("--kappa", type=float, default=1e7, help="penalty [stress/length]")
    ap.add_argument("--onset", type=float, default=0.0,
                    help="the penalty's cubic onset depth [R] (C2 law; 0: quadratic)")
    ap.add_argument("--frozen", action="store_true",
                    help="penalty: the gap linearised at the current state (no curvature "
                    "term in the tangent)")
    ap.add_argument("--inter-tol", type=float, default=1e-6,
                    help="Newton's tolerance below full load (the last step: 1e-9)")
    ap.add_argument("--ramp", default="fixed", choices=("fixed", "slide"),
                    help="fixed: the product's ramp (--steps); slide: increments sized by the "
                    "slide near the edge (benchmarks/edge2d_ramp.py)")
    ap.add_argument("--slide", type=float, default=1.0,
                    help="--ramp slide: the target slide per step, in edge mesh sizes")
    ap.add_argument("--dt0", type=float, default=0.05, help="--ramp slide: first increment")
    ap.add_argument("--predictor", default="secant", choices=("secant", "none"))
    ap.add_argument("--cap-mode", default="global", choices=("global", "local"),
                    help="global: the whole update scaled; local: each element's DOFs by "
                    "the least factor of its vertices")
    ap.add_argument("--finite", action="store_true",
                    help="without the line search: halve a step while its residual is not "
                    "finite (an inverted element)")
    ap.add_argument("--soc", action="store_true",
                    help="without the line search: a second-order correction of each update "
                    "(penetrating boundary vertices moved back by the gap's curvature term)")
    ap.add_argument("--jcap", type=float, default=0.0,
                    help="a step bound by the volume ratio: no update takes J below this "
                    "fraction of its value at any integration point (0: off)")
    ap.add_argument("--trust-normal", type=float, default=0.0,
                    help="an update never moves an arc vertex near the skull along the "
                    "skull's normal more than this fraction of its smallest edge (0: off)")
    ap.add_argument("--cap-near", type=float, default=0.0,
                    help="the --trust cap only for vertices within this many rho of a "
                    "rounding's centre (0: every vertex)")
    ap.add_argument("--trace", action="store_true",
                    help="per load step on stderr: iterations, caps, |R|, set changes")
    ap.add_argument("--table", action="store_true", help="every row of TABLE")
    ap.add_argument("--budget", type=int, default=400,
                    help="--ramp slide: stop after this many Newton iterations")
    ap.add_argument("--sweep", action="store_true",
                    help="the sector study's 32 scenarios (alphas x betas x sliding / "
                    "noslip) with the other options given, each in its own process")
    a = ap.parse_args()
    if a.sweep:
        from edge2d_report import sweep

        sweep(__file__, [arg for arg in sys.argv[1:] if arg != "--sweep"])
        return
    if not a.table:
        print(json.dumps(run(a.alpha, a.beta, a.contact, a.rho, a.h, not a.full, a.steps,
                             a.trust, a.element,
                             line_search=not a.no_line_search, rounding=a.rounding,
                             hc_ratio=a.hc_ratio, law=a.law, kappa=a.kappa,
                             trust_max=a.trust_max, onset=a.onset, trace=a.trace,
                             frozen=a.frozen, inter_tol=a.inter_tol, ramp=a.ramp,
                             slide=a.slide, dt0=a.dt0, predictor=a.predictor,
                             cap_mode=a.cap_mode, finite_backtrack=a.finite, soc=a.soc,
                             jcap=a.jcap, al_tol=a.al_tol, budget=a.budget,
                             trust_normal=a.trust_normal, cap_near=a.cap_near)))
        return
    keys = ("alpha", "beta", "contact", "law", "element", "rho", "hc_ratio", "h", "half",
            "steps", "trust", "line_search", "rounding")
    print("| " + " | ".join(keys) + " | load | Newton | wall s | u_y top | crossing round / "
          "sharp | slide deg | J min (P1 part) |")
    print("|" + "---|" * (len(keys) + 7))
    for row in TABLE:
        c = {**DEFAULTS, **row}
        cmd = [sys.executable, __file__, "--alpha", str(c["alpha"]), "--beta", str(c["beta"]),
               "--contact", c["contact"], "--rho", str(c["rho"]), "--h", str(c["h"]),
               "--steps", str(c["steps"]), "--trust", str(c["trust"]), "--element",
               c["element"], "--rounding", c["rounding"], "--hc-ratio", str(c["hc_ratio"]),
               "--law", c["law"]]
        cmd += ([] if c["half"] else ["--full"]) + ([] if c["line_search"]
                                                    else ["--no-line-search"])
        out = subprocess.run(cmd, capture_output=True, text=True)
        cells = " | ".join(str(c[k]) for k in keys)
        try:
            r = json.loads(out.stdout.strip().splitlines()[-1])
        except (IndexError, json.JSONDecodeError):
            print(f"| {cells} | failed: {out.stderr[-120:]!r} |", flush=True)
            continue
        print(f"| {cells} | {r['load']} | {r['newton']} | {r['wall_s']} | {r['top_uy']:.5f} | "
              f"{r['crossing_round']:.1e} / {r['crossing_sharp']:.1e} | {r['slide_deg']:.2f} | "
              f"{r['Jmin']:.3f} |", flush=True)


if __name__ == "__main__":
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    main()
