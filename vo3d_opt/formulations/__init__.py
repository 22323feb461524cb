"""Formulations: the geometry of one decision turned into optimisation problems
(sampled reference, plane_qp, cone_qp, nlp)."""
