"""Exception hierarchy of the estimator library.

Every estimator raises a subclass of :class:`EstimatorError` on degenerate input instead of
returning NaN, so a pipeline can ``except EstimatorError`` and fall back (e.g. insert a keyframe).
"""

from __future__ import annotations


class EstimatorError(ValueError):
    """Base class of all estimator failures."""


class TooFewPoints(EstimatorError):
    """Fewer correspondences than the estimator's minimum."""

    def __init__(self, n: int, minimum: int, what: str = "points"):
        super().__init__(f"need at least {minimum} {what}, got {n}")
        self.n = n
        self.minimum = minimum


class NonFiniteInput(EstimatorError):
    """An input array contains NaN or inf."""


class DegenerateInput(EstimatorError):
    """Geometrically degenerate configuration (singular or ill-conditioned system, kappa <= 0, ...)."""


class ShapeError(EstimatorError):
    """Input arrays have inconsistent or wrong shapes."""
