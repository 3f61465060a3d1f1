"""``symbolic(G)``: the CasADi twin of a numpy group class, over both twin modules
(:mod:`.lie` for SO2, SO3, SE2, SE3; :mod:`.lie_extended` for Sim3, Sim2, SE23, S3, bundles)."""

from __future__ import annotations

from ..lie import SE2, SE3, SO2, SO3, BundleGroup, LieGroup, RnGroup
from . import lie_extended as ext
from .lie import SymbolicGroup, SymSE2, SymSE3, SymSO2, SymSO3

__all__ = ["symbolic"]

_TWINS: dict[type[LieGroup], type[SymbolicGroup]] = {SO2: SymSO2, SO3: SymSO3, SE2: SymSE2, SE3: SymSE3}


def symbolic(group: type[LieGroup]) -> type[SymbolicGroup]:
    """The twin of a numpy group class (``symbolic(SO3) is SymSO3``): SO2, SO3, SE2, SE3, Sim3, Sim2,
    SE23, S3 and bundles of these and ``Rn(n)`` (:mod:`.lie_extended`); ``TypeError`` otherwise."""
    twin = _TWINS.get(group) or ext.TWINS.get(group) if isinstance(group, type) else None
    if twin is None and isinstance(group, type) and issubclass(group, BundleGroup):
        # Rⁿ parts have a twin inside bundles (ext.sym_rn); alone, Rⁿ needs none (plain CasADi vectors).
        # The ignores: mypy takes a class for not Hashable (python/mypy#20409); classes hash by identity.
        parts = [ext.sym_rn(p) if issubclass(p, RnGroup) else symbolic(p) for p in group.parts]  # type: ignore[arg-type]
        twin = ext.sym_bundle(group, tuple(parts))  # type: ignore[arg-type]
    if twin is None:
        name = getattr(group, "__name__", repr(group))
        raise TypeError(
            f"symbolic: no symbolic twin of {name}; supported groups are SO2, SO3, SE2, SE3, Sim3, Sim2, "
            "SE23, S3 and Bundles of these and Rn(n)"
        )
    return twin
