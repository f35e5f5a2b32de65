"""A front end that replays exported tracks (:class:`~gevi_cli.datasets.track_export.TrackExport`).

The odometry back ends call it exactly like the image front end, with the export's
:class:`~gevi_cli.datasets.track_export.TrackFrame` s as frames: ``track`` hands out the frame's
tracked features, ``keyframe`` the exported stereo matches, and ``keyframe_decision`` says which
frames are keyframes (the export dictates them: the tracks of a frame refer to the ids of the latest
exported keyframe, so the back end must not choose its own).

>>> export = open_track_export(folder, calib="calib.txt")
>>> fe = ExportFrontEnd(export)
>>> for frame in export.frames():
...     obs = fe.track(frame)
...     if fe.keyframe_decision(frame):
...         stereo = fe.keyframe(frame)
"""
from __future__ import annotations

from gevi_cli.datasets.track_export import TrackExport, TrackFrame
from gevi_cli.errors import GeviError
from gevi_cli.observations import FeatureObs, RectifiedStereo, StereoObs


class ExportFrontEnd:
    """:class:`~gevi_cli.frontend.FrontEnd` over a track export.

    ``use_outlier_flags``: drop the tracks OV2SLAM flagged as outliers (its own back end's verdict)
    before handing them out; off by default, so the back end's own outlier rejection sees every track.
    ``timings`` holds the time spent reading the export (``{"read": seconds}``).
    """

    def __init__(self, export: TrackExport, use_outlier_flags: bool = False):
        self.export = export
        self.camera: RectifiedStereo = export.camera
        self.use_outlier_flags = bool(use_outlier_flags)
        self.timings: dict[str, float] = {"read": float(getattr(export, "read_seconds", 0.0))}

    def track(self, frame: TrackFrame, rotation=None, predicted=None) -> FeatureObs:
        """The frame's tracked left-image features (ids as in the export's stereo matches); the
        rotation and pixel priors are not needed (the tracks are already made)."""
        obs = frame.obs
        if self.use_outlier_flags and frame.outlier.any():
            keep = ~frame.outlier
            obs = FeatureObs(obs.ids[keep], obs.uv[keep])
        return obs

    def keyframe(self, frame: TrackFrame) -> StereoObs:
        """The frame's exported stereo matches; only exported keyframes have them."""
        if frame.stereo is None:
            raise GeviError(self.export.stereo_path,
                            f"frame {frame.index} is not a keyframe of the export (it has no stereo matches); "
                            "with exported tracks the keyframes are the export's (keyframe_decision)")
        return frame.stereo

    def reacquire(self, frame: TrackFrame, predicted=None, keep_tracks=False) -> None:
        """Exported tracks cannot be re-matched (no images): None."""
        return None

    def adopt(self, frame: TrackFrame, obs: FeatureObs) -> None:
        """Never called: :meth:`reacquire` offers nothing to adopt."""
        raise NotImplementedError("exported tracks cannot be re-acquired")

    def keyframe_decision(self, frame: TrackFrame) -> bool:
        """True exactly for the export's keyframes."""
        return frame.stereo is not None


__all__ = ["ExportFrontEnd"]
