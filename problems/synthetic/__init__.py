"""Synthetic pose-graph and rotation-averaging instances with known ground truth.

Every generator is reproducible from ``seed`` (``np.random.default_rng(seed)``),
vectorized (10⁵ poses in a fraction of a second) and returns an :class:`Instance`:
the problem, the ground truth it was sampled from, the mask of corrupted edges
and the generator's arguments.

Noise model (poses)
    ``Z_e = (X_i⁻¹ X_j) ⊕ ε = X_i⁻¹ X_j Exp(ε)``, ``ε ~ N(0, Σ)`` in tangent
    coordinates ``(ρ, θ)`` (CONVENTIONS §2), ``Σ = diag(σ_t² I_d, σ_R² I_r)``.
    The information matrix is ``Ω = Σ⁻¹``, so the geodesic cost ``½ Σ rᵀΩr``,
    ``r = Log(Z⁻¹ X_i⁻¹ X_j) = −ε`` at the truth, is the exact negative
    log-likelihood. An exact component (``σ = 0``) gets the weight
    :data:`EXACT_WEIGHT` ``= 1`` instead of ``∞``: with noise-free measurements
    ``Ω = I``, and the truth is a zero-cost global optimum whatever the weights.
Outliers
    Each edge off the *backbone* (the odometry chain of a trajectory, the random
    Hamiltonian path of a rotation-averaging graph) is corrupted independently
    with probability ``outlier_rate``: its measurement is replaced by a uniformly
    random relative pose (Haar rotation; translation uniform in the box
    ``[−e, e]`` of every displacement within the scene, ``e`` the extent of the
    true positions per axis) while keeping the nominal information. The backbone
    is never corrupted, so the inlier graph stays connected and the truth stays
    identifiable (up to the global gauge).
Edges
    Edge ``(i, j)`` has ``i < j``. Trajectories number their poses along the
    trajectory: the first ``n − 1`` edges are the odometry ``(k, k+1)``, then the
    loop closures in lexicographic order, each candidate kept independently with
    probability ``loop_closure_probability``.

The random stream is consumed in a fixed order (truth, edges, noise, outlier mask,
outlier values), so a seed gives the same instance on every platform for a given
version of this module.
"""

from .base import DEFAULT_ROTATION_NOISE, DEFAULT_TRANSLATION_NOISE, EXACT_WEIGHT, Instance
from .landmarks import landmark_world
from .rotations import rotation_averaging
from .trajectories import circle2d, cube, grid2d, sphere, torus

__all__ = [
    "EXACT_WEIGHT",
    "DEFAULT_ROTATION_NOISE",
    "DEFAULT_TRANSLATION_NOISE",
    "Instance",
    "circle2d",
    "cube",
    "grid2d",
    "landmark_world",
    "rotation_averaging",
    "sphere",
    "torus",
]
