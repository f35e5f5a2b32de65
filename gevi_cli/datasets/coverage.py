"""How well a ground truth covers the image frames of a sequence."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli.trajectory import Trajectory


@dataclass(frozen=True)
class Coverage:
    """Frames with a ground-truth pose nearby.

    A frame is covered when it lies inside the GT time span and a GT sample is within
    ``tolerance_ns`` of it (so a pose can be associated or interpolated for it).
    """

    covered: int
    total: int
    start_gap_s: float  # GT start - first frame (> 0: GT starts late)
    end_gap_s: float  # last frame - GT end (> 0: GT ends early)
    largest_inner_gap_s: float

    def describe(self) -> str:
        parts = [f"{self.covered} of {self.total} frames"]
        if self.start_gap_s > 0:
            parts.append(f"GT starts {self.start_gap_s:.2f} s after the first frame")
        if self.end_gap_s > 0:
            parts.append(f"GT ends {self.end_gap_s:.2f} s before the last frame")
        return ", ".join(parts)


def frame_coverage(frames_ns: np.ndarray, gt: Trajectory, tolerance_ns: int | None = None) -> Coverage:
    """Coverage of ``frames_ns`` by ``gt``; tolerance defaults to 1.5 GT periods (at least 1 ms)."""
    g = gt.t_ns
    if tolerance_ns is None:
        period = np.median(np.diff(g)) if len(g) > 1 else 0
        tolerance_ns = int(max(1.5 * period, 1_000_000))
    j = np.clip(np.searchsorted(g, frames_ns), 1, len(g) - 1) if len(g) > 1 else np.zeros(len(frames_ns), int)
    nearest = np.minimum(np.abs(g[j] - frames_ns), np.abs(g[np.maximum(j - 1, 0)] - frames_ns))
    inside = (frames_ns >= g[0] - tolerance_ns) & (frames_ns <= g[-1] + tolerance_ns)
    covered = inside & (nearest <= tolerance_ns)
    inner = np.diff(g).max() * 1e-9 if len(g) > 1 else 0.0
    return Coverage(int(covered.sum()), len(frames_ns), float(g[0] - frames_ns[0]) * 1e-9,
                    float(frames_ns[-1] - g[-1]) * 1e-9, float(inner))
