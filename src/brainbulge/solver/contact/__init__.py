"""Frictionless contact with the rigid skull: contact points (:mod:`.points`), the
primal-dual active set that decides which of them touch (:mod:`.active_set`), and the
saddle-point systems it gives Newton (:mod:`.saddle`)."""
