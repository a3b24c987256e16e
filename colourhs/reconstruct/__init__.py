"""Depth reconstruction: MRF optimisation for Bayesian Helmholtz stereopsis."""
