"""Render the simulated sequences of a batch into the cache before any run is dispatched.

The driver renders (one render at a time, with the simulator's own process pool) because dask
workers are daemonic and cannot fork render pools.  Cache folder: ``<cache>/batch-renders/<key>/``
with ``<cache>`` the config's ``cache:`` or gevi's user cache (``$GEVI_CACHE_DIR``, else
``$XDG_CACHE_HOME/gevi``, else ``~/.cache/gevi``).  ``<key>`` names preset and seed and ends in a
hash of every option and the gevi version, so a changed option or simulator never reuses a render.
Writes are atomic: :func:`gevi_cli.simulate.generate.simulate` renders into a temporary sibling and
renames it into place, so an interrupted render leaves no half sequence at ``<key>``.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

from gevi_cli.batch.config import SimSpec

#: bump when the meaning of the cache key changes
CACHE_LAYOUT = 1


def cache_root(configured: str | None) -> Path:
    from gevi_cli.simulate.sample import cache_dir

    return (Path(configured).expanduser() if configured else cache_dir()) / "batch-renders"


def render_key(sim: SimSpec) -> str:
    from gevi_cli import __version__

    fields = dataclasses.asdict(sim)
    if not fields["disparity_shift_px"]:  # an option added later: renders without it keep their keys
        del fields["disparity_shift_px"]
    doc = {"layout": CACHE_LAYOUT, "gevi": __version__, **fields}
    h = hashlib.sha256(json.dumps(doc, sort_keys=True, default=list).encode()).hexdigest()[:12]
    return f"{sim.preset}_s{sim.seed}_{h}"


def _dataset_path(folder: Path, sim: SimSpec) -> Path:
    return folder / "sequences" / "00" if sim.fmt == "kitti" else folder


def is_rendered(folder: Path) -> bool:
    return (folder / "simulation.yaml").is_file()


def simulation_config(sim: SimSpec):
    from gevi_cli.simulate.generate import SimulationConfig
    from gevi_cli.simulate.imu import ImuParams

    imu_kw = dict(sim.imu)
    noise_free = imu_kw.pop("no_imu_noise", False)
    names = {"imu_rate": "rate_hz", "gyro_noise": "gyro_noise_density", "gyro_walk": "gyro_random_walk",
             "acc_noise": "acc_noise_density", "acc_walk": "acc_random_walk"}
    imu = ImuParams(**{names[k]: v for k, v in imu_kw.items()}) if imu_kw or noise_free else None
    if noise_free:
        imu = imu.noise_free()
    return SimulationConfig(sim.preset, seed=sim.seed, duration_s=sim.duration_s, rate_hz=sim.rate_hz,
                            resolution=tuple(sim.resolution) if sim.resolution else None, baseline_m=sim.baseline_m,
                            distortion=sim.distortion, image_noise=sim.image_noise, imu=imu,
                            supersample=sim.supersample, a_max=sim.a_max, moving_start=sim.moving_start,
                            disparity_shift_px=sim.disparity_shift_px)


def ensure_rendered(sims, cache: Path, echo=print, progress: bool = False) -> dict:
    """{SimSpec: dataset path} for every distinct render, rendering the missing ones (atomically)."""
    from gevi_cli.simulate.generate import simulate

    out = {}
    for sim in dict.fromkeys(sims):
        folder = cache / render_key(sim)
        if not is_rendered(folder):
            echo(f"gevi batch: rendering {sim.preset} seed {sim.seed} ({sim.duration_s or 'preset'} s) -> {folder}")
            folder.parent.mkdir(parents=True, exist_ok=True)
            try:
                simulate(simulation_config(sim), folder, sim.fmt, progress=progress)
            except Exception:
                if not is_rendered(folder):  # not a concurrent batch that finished the same render first
                    raise
        out[sim] = str(_dataset_path(folder, sim))
    return out
