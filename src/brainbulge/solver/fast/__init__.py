"""Fast paths that give the plain path's answer sooner, each with an ``applies(form)`` test
and an equivalence test against the plain path: the closed-form MINI tangent
(:mod:`.mini_tangent`; in 2D with the residual, :mod:`.mini_plane`) and local relaxation at
residual hotspots (:mod:`.hotspot`)."""
