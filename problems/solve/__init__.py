"""Numerics that know no model: the path follower and nonlinear solver
(:mod:`.driver`), the linear solvers and preconditioners, time integration."""
