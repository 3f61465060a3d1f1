"""Riemannian manifolds: the geometry optimizers need (CONVENTIONS §6)."""

from .base import Manifold, MissingOperationError
from .blocks import Blocks, Values
from .euclidean import Euclidean
from .grassmann import Grassmann
from .lie_group import LieGroupManifold
from .product import Power, Product, ProductVector
from .sphere import Sphere
from .stiefel import SpecialOrthogonal, Stiefel

__all__ = [
    "Manifold",
    "MissingOperationError",
    "LieGroupManifold",
    "Euclidean",
    "Sphere",
    "Stiefel",
    "Grassmann",
    "SpecialOrthogonal",
    "Product",
    "Power",
    "ProductVector",
    "Blocks",
    "Values",
]
