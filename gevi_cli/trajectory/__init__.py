"""Trajectories: the one pose-series type and its file formats."""
from gevi_cli.trajectory.formats import WRITE_FORMATS, detect_format, read_trajectory, write_trajectory
from gevi_cli.trajectory.trajectory import Trajectory

__all__ = ["Trajectory", "read_trajectory", "write_trajectory", "detect_format", "WRITE_FORMATS"]
