"""Front ends: from a sequence's frames to feature observations with persistent ids.

A front end implements :class:`FrontEnd`; the odometry back ends (``gevi_cli.pipelines``) call it and
never look at images themselves, so the same back end runs on our LK front end
(:mod:`gevi_cli.frontend.image_frontend`) and on exported tracks (:mod:`gevi_cli.frontend.export`).
"""
from __future__ import annotations

from typing import Protocol

from gevi_cli.frontend.types import FeatureObs, RectifiedStereo, StereoObs


class FrontEnd(Protocol):
    """What a back end needs from a front end.

    Call order per frame: ``track(frame)`` always (the first call initialises); then, if the frame
    becomes a keyframe, ``keyframe(frame)`` for the same frame.
    """

    camera: RectifiedStereo

    def track(self, frame, rotation=None) -> FeatureObs:
        """Left-image features of ``frame`` with the ids they had in earlier frames.  ``rotation``:
        the back end's predicted rotation ``R_cp`` since the previous frame (rectified left camera,
        previous -> current coordinates) or None; a front end may use it as a tracking prior."""

    def keyframe(self, frame) -> StereoObs:
        """Make ``frame`` a keyframe: (re-)detect where features are missing and match left->right."""

    def keyframe_decision(self, frame) -> bool | None:
        """None: the back end's keyframe rule decides; True/False: the source dictates it."""


__all__ = ["FrontEnd", "FeatureObs", "StereoObs", "RectifiedStereo"]
