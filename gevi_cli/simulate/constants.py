"""Constants of the simulated sensors shared by the generator and the writers.

A leaf module (it imports nothing from ``gevi_cli``), so that ``generate.py`` and
``writers/*.py`` can both take them without importing each other.
"""
from __future__ import annotations

#: rate of the simulated motion-capture (marker) poses [Hz]
MOCAP_RATE_HZ = 100.0
#: per-sample noise of the motion-capture poses: position [m], rotation [deg]
MOCAP_NOISE_POS_M = 0.0005
MOCAP_NOISE_ROT_DEG = 0.1
