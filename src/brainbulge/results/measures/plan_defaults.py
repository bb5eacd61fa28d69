"""Defaults of the craniectomy planner, shared by its damage measures
(:mod:`brainbulge.results.measures.plan_measures`), the planner (:mod:`brainbulge.studies.plan`) and
the ``brainbulge plan`` parser, which must not load the solver stack to show them."""

#: maximum principal strain at which 50 % of axons were injured in vitro (Bain & Meaney 2000)
STRAIN_THRESHOLD = 0.18
#: the damage thresholds of the maximum principal strain the paper cites (Bain & Meaney 2000:
#: the optimal thresholds of electrophysiological impairment and of morphological injury in
#: vivo), one damage mask each in a 3D run's NIfTI maps
DAMAGE_THRESHOLDS = {"functional": STRAIN_THRESHOLD, "morphological": 0.21}
#: distances from the flap rim between which the rim measures are taken [mm]
RIM_BAND_MM = (5.0, 10.0)
#: flap diameters tried by default [mm]: the 12 cm guideline in the middle
DIAMETERS_MM = (80.0, 100.0, 120.0, 140.0, 160.0)
#: candidate centres by default (half on each side with ``swell = "both"``)
N_CENTRES = 10
#: linear solver of a plan: GMRES with AMG blocks (on the 111k-tet template, 2 workers,
#: PARDISO's Newton iterations took 17-40 s each)
LINEAR_SOLVER = "krylov"
