"""Front ends: from a sequence's frames to feature observations with persistent ids.

A front end implements :class:`FrontEnd`; the odometry back ends (``gevi_cli.pipelines``) call it and
never look at images themselves, so the same back end runs on our LK front end
(:mod:`gevi_cli.frontend.image_frontend`) and on exported tracks (:mod:`gevi_cli.frontend.export`).
"""
from __future__ import annotations

from typing import Protocol

from gevi_cli.observations import FeatureObs, Prediction, RectifiedStereo, StereoObs


class FrontEnd(Protocol):
    """What a back end needs from a front end.

    Call order per frame: ``track(frame)`` always (the first call initialises); then, if the frame
    becomes a keyframe, ``keyframe(frame)`` for the same frame.
    """

    camera: RectifiedStereo
    timings: dict[str, float]  # stage -> seconds of the last call (track or keyframe)

    def track(self, frame, rotation=None, predicted=None) -> FeatureObs:
        """Left-image features of ``frame`` with the ids they had in earlier frames.  ``rotation``:
        the back end's predicted rotation ``R_cp`` since the previous frame (rectified left camera,
        previous -> current coordinates) or None; ``predicted``: a :class:`Prediction` of the pixels
        and patch scales of some features in ``frame``, or None.  A front end may use both as tracking priors."""

    def reacquire(self, frame, predicted=None, keep_tracks=False) -> FeatureObs | None:
        """After ``track(frame)``: the frame's features with the last keyframe's found again by
        descriptor (near ``predicted`` pixels where given; with ``keep_tracks``
        only those LK lost), or None when it cannot.  A proposal: the front end's state is unchanged until ``adopt``."""

    def adopt(self, frame, obs) -> None:
        """Make ``obs``, what ``reacquire(frame)`` returned, the front end's features of ``frame``."""

    def keyframe(self, frame) -> StereoObs:
        """Make ``frame`` a keyframe: (re-)detect where features are missing and match left->right."""

    def keyframe_decision(self, frame) -> bool | None:
        """None: the back end's keyframe rule decides; True/False: the source dictates it."""


__all__ = ["FrontEnd", "FeatureObs", "Prediction", "StereoObs", "RectifiedStereo"]
