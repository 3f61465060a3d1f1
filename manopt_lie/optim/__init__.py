"""Riemannian optimization: problems (a cost and its derivatives) and the solvers that minimize them."""

from .problem import Problem

__all__ = ["Problem"]
