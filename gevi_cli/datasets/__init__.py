"""Dataset readers: one module per kind, a registry, auto-detection.

>>> seq = open_sequence("datasets/euroc/V1_01_easy")          # kind detected from the layout
>>> for frame in seq.frames(step=2): ...                        # StereoFrame(t_ns, left, right)
"""
from gevi_cli.datasets.calibration import Rectification, StereoRig
from gevi_cli.datasets.registry import detect_kind, kinds, open_sequence
from gevi_cli.datasets.sequence import ImuData, Sequence, StereoFrame

__all__ = ["open_sequence", "detect_kind", "kinds", "Sequence", "StereoFrame", "ImuData", "StereoRig",
           "Rectification"]
