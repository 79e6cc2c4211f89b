"""Dynamic models of the mechanism: scene, contact and impact laws, rigid and elastic models, solvers."""
