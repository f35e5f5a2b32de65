"""Find estimates and ground truths from the command line arguments.

Two ways to name estimates (they can be combined):

* ``-e NAME=PATH`` (repeatable): one estimate file of method NAME for the single sequence given by
  ``--gt PATH`` (the sequence is named ``--sequence`` or after the GT).  ``PATH`` may also be a folder
  of trials (see below).
* ``--results ROOT``: a results tree ``ROOT/<method>/<sequence>/`` (or ``ROOT/<method>/<sequence>.txt``
  as kitti-odom-eval lays out results).  A sequence folder holds

  - one trajectory file, or
  - trial folders ``run*/`` with one trajectory file each, or
  - several trajectory files that differ only by a trailing number (``stamped_traj_estimate0.txt``,
    ``...1.txt``: rpg_trajectory_evaluation's layout); each is a trial.

  Files named like ground truth (``*groundtruth*``, ``gt.*``, ``gt_*``) are not estimates; such a file
  in the sequence folder is that sequence's ground truth unless ``--gt-root``/``--gt SEQ=PATH`` names
  one.  A sequence folder named ``<anything>_<method>_<SEQ>`` (rpg: ``laptop_vislam_rp_MH_04``) is
  sequence ``SEQ``.

Ground truth of sequence S: ``--gt S=PATH``, else ``--gt-root DIR`` with ``DIR/S`` (a dataset folder,
or a folder holding one GT file) or a file ``DIR/S.<ext>``, else the GT file inside the sequence folder.
PATH can be a trajectory file or a dataset folder (``gevi_cli.datasets.open_sequence``: its ground
truth, body frame, and its ``T_B_C0``).

Alignment hints for ``--align auto``: the first of ``config.yaml``, ``meta.yaml``, ``meta.json``,
``eval_cfg.yaml`` found in the run folder, the sequence folder or the method folder.  Keys:
``align``/``align_type`` (a method name, rpg's ``posyaw``/``se3``/``sim3``/``none``), else
``sensor``/``mode``/``setup``/``config`` text: containing "inertial"/"imu"/"vio" -> posyaw, "mono"
-> sim3, "stereo" -> se3; ``scale_free: true`` -> sim3.  No hint -> se3.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gevi_cli.errors import DataError, GeviError

TRAJ_EXTS = {".txt", ".csv", ".tum", ".kitti", ".log", ".traj", ""}
HINT_FILES = ("config.yaml", "meta.yaml", "meta.json", "eval_cfg.yaml")
_GT_RE = re.compile(r"(groundtruth|ground_truth|^gt$|^gt_|_gt$)", re.IGNORECASE)


@dataclass
class EstimateSpec:
    """One estimate file (or a missing one) of one method, sequence and trial."""

    method: str
    sequence: str
    trial: str
    path: Path | None
    hint_dirs: list = field(default_factory=list)


def is_gt_name(p: Path) -> bool:
    return bool(_GT_RE.search(p.stem))


def _traj_files(folder: Path) -> list[Path]:
    out = []
    for p in sorted(folder.iterdir()):
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in TRAJ_EXTS and not is_gt_name(p):
            if p.name.lower() in ("times.txt", "readme.txt", "readme", "calib.txt"):
                continue
            out.append(p)
    return out


def _natural_key(s: str):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", s)]


def run_primary(folder: Path) -> Path | None:
    """The primary trajectory of a `gevi run` folder (named by its ``status.json``), else None."""
    status = folder / "status.json"
    if not status.is_file():
        return None
    try:
        name = json.loads(status.read_text()).get("primary")
    except (ValueError, AttributeError):
        raise GeviError(status, "is not a gevi run status file (invalid JSON)") from None
    if not isinstance(name, str) or not name:
        raise GeviError(status, "names no primary trajectory")
    return folder / name if (folder / name).is_file() else None


def _run_folders(folder: Path) -> list[Path]:
    """`gevi run` folders inside a sequence folder (the ``latest`` link is not a trial of its own)."""
    return sorted([p for p in folder.iterdir() if p.is_dir() and not p.is_symlink() and (p / "status.json").is_file()],
                  key=lambda p: _natural_key(p.name))


def trials_in(folder: Path) -> list[tuple[str, Path | None]]:
    """(trial name, file) of a sequence (or -e) folder; see module docstring.  Raises on ambiguity.

    A `gevi run` folder (it holds ``status.json``) is one estimate: the primary trajectory it names
    (other trajectories and CSVs in it are not estimates).  A folder of run folders
    (``results/<method>/<sequence>/<timestamp>/``) holds one trial per run folder.
    """
    if (folder / "status.json").is_file():
        return [("", run_primary(folder))]
    runs = _run_folders(folder)
    if runs:
        return [(r.name, run_primary(r)) for r in runs]
    runs = sorted([p for p in folder.iterdir() if p.is_dir() and p.name.startswith("run")],
                  key=lambda p: _natural_key(p.name))
    if runs:
        out = []
        for r in runs:
            files = _traj_files(r)
            if len(files) > 1:
                named = [f for f in files if f.stem.startswith(("traj", "stamped_traj", "estimate", "f_", "vio"))]
                files = named if len(named) == 1 else files
            if len(files) > 1:
                raise GeviError(r, f"holds {len(files)} trajectory files ({', '.join(f.name for f in files[:4])}); "
                                   "expected one per run folder")
            out.append((r.name, files[0] if files else None))
        return out
    files = _traj_files(folder)
    if not files:
        return [("", None)]
    if len(files) == 1:
        return [("", files[0])]
    stems = {re.sub(r"\d+$", "", f.stem) for f in files}
    if len(stems) == 1 and all(re.search(r"\d+$", f.stem) for f in files):
        files = sorted(files, key=lambda f: _natural_key(f.name))
        return [(f.stem, f) for f in files]
    raise GeviError(folder, f"holds several trajectory files ({', '.join(f.name for f in files[:5])}); "
                            "put trials in run*/ folders or name them <stem><k>.txt")


def gt_file_in(folder: Path) -> Path | None:
    cands = [p for p in sorted(folder.iterdir()) if p.is_file() and is_gt_name(p) and p.suffix.lower() in TRAJ_EXTS]
    return cands[0] if cands else None


def sequence_name(folder_or_file: Path, method: str) -> str:
    name = folder_or_file.stem if folder_or_file.is_file() else folder_or_file.name
    marker = f"_{method}_"
    if marker in name:
        return name.split(marker, 1)[1]
    return name


def discover_results(root: Path) -> tuple[list[EstimateSpec], dict[str, Path]]:
    """Estimates of a results tree and the GT files found inside sequence folders."""
    root = Path(root)
    if not root.is_dir():
        raise GeviError(root, "--results must be a folder <root>/<method>/<sequence>/")
    specs: list[EstimateSpec] = []
    local_gt: dict[str, Path] = {}
    methods = [p for p in sorted(root.iterdir()) if p.is_dir() and not p.name.startswith(".")]
    if not methods:
        raise GeviError(root, "holds no method folders; expected <root>/<method>/<sequence>/")
    for mdir in methods:
        method = mdir.name
        for sdir in sorted(mdir.iterdir()):
            if sdir.name.startswith("."):
                continue
            if sdir.is_dir():
                seq = sequence_name(sdir, method)
                gt = gt_file_in(sdir)
                if gt is not None:
                    local_gt.setdefault(seq, gt)
                for trial, f in trials_in(sdir):
                    hints = [f.parent] if f is not None and f.parent != sdir else []
                    if f is None and trial and (sdir / trial).is_dir():
                        hints = [sdir / trial]
                    specs.append(EstimateSpec(method, seq, trial, f, hints + [sdir, mdir]))
            elif sdir.is_file() and sdir.suffix.lower() in TRAJ_EXTS and not is_gt_name(sdir):
                specs.append(EstimateSpec(method, sequence_name(sdir, method), "", sdir, [mdir]))
    if not specs:
        raise GeviError(root, "no trajectory files found under <root>/<method>/<sequence>/")
    return specs, local_gt


def gt_for_sequence(seq: str, gt_map: dict[str, Path], gt_root: Path | None, local_gt: dict[str, Path]) -> Path | None:
    if seq in gt_map:
        return gt_map[seq]
    if gt_root is not None:
        d = gt_root / seq
        if d.is_dir():
            return d
        files = [p for p in sorted(gt_root.glob(f"{seq}.*")) if p.is_file()]
        if len(files) >= 1:
            return files[0]
    return local_gt.get(seq)


def parse_named(spec: str, option: str) -> tuple[str, str]:
    if "=" not in spec:
        raise GeviError(option, f"expected NAME=PATH, got {spec!r}")
    name, path = spec.split("=", 1)
    if not name or not path:
        raise GeviError(option, f"expected NAME=PATH, got {spec!r}")
    return name, path


# ---------------------------------------------------------------------------------------- hints
def _read_hint(path: Path) -> dict:
    if path.suffix != ".json":
        from gevi_cli.datasets.yamlio import load_yaml

        return load_yaml(path, empty_ok=True, what="alignment hint")
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except json.JSONDecodeError as exc:  # a broken hint file is the user's to fix
        raise GeviError(f"{path}:{exc.lineno}", f"alignment hint is not valid JSON ({exc.msg})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise GeviError(path, f"cannot read alignment hint ({type(exc).__name__})") from None
    return data if isinstance(data, dict) else {}


def align_from_hint(dirs: list[Path]) -> tuple[str, str]:
    """(alignment, where it came from) for ``--align auto``."""
    from gevi_cli.evaluation.align import ALIGN_METHODS

    for d in dirs:
        for name in HINT_FILES:
            p = Path(d) / name
            if not p.is_file():
                continue
            data = _read_hint(p)
            for key in ("align", "align_type", "alignment"):
                v = data.get(key)
                if isinstance(v, str) and v.lower() in ALIGN_METHODS:
                    return v.lower(), f"{p}: {key}"
            if data.get("scale_free") is True:
                return "sim3", f"{p}: scale_free"
            text = " ".join(str(data.get(k, "")) for k in ("sensor", "sensors", "mode", "setup", "config", "pipeline"))
            text = text.lower()
            if any(w in text for w in ("inertial", "imu", "vio")):
                return "posyaw", f"{p}: inertial"
            if "mono" in text:
                return "sim3", f"{p}: monocular (scale-free)"
            if "stereo" in text:
                return "se3", f"{p}: stereo"
    return "se3", "default (no hint)"


# --------------------------------------------------------------------------------- ground truth
def load_T_B_C0(path: Path) -> np.ndarray:
    """A 4x4 cam0->body transform from a text file (16 or 12 numbers) or YAML (``T_B_C0``, ``T_BS``)."""
    path = Path(path)
    if not path.is_file():
        raise GeviError("--T-B-C0", f"{path}: no such file")
    vals = None
    from gevi_cli.datasets.yamlio import load_yaml, matrix

    if path.suffix.lower() in (".yaml", ".yml"):
        data = load_yaml(path)  # takes what the dataset readers take (EuRoC's %YAML:1.0 header)
        for key in ("T_B_C0", "T_BS", "T_B_C"):
            if isinstance(data, dict) and key in data:
                vals = matrix(data[key], path, key).reshape(-1)
                break
        if vals is None:
            raise GeviError(path, "expected a key T_B_C0 (or T_BS) holding a 4x4 matrix")
    else:
        try:
            vals = np.array([float(x) for x in re.split(r"[\s,;\[\]]+", path.read_text()) if x], dtype=np.float64)
        except ValueError:
            raise GeviError(path, "expected 16 (or 12) numbers of a 4x4 cam0->body transform") from None
    if vals.size == 12:
        vals = np.concatenate([vals, [0, 0, 0, 1]])
    if vals.size != 16:
        raise GeviError(path, f"expected 16 (or 12) numbers of a 4x4 cam0->body transform, got {vals.size}")
    return matrix(vals.reshape(4, 4), path, "T_B_C0")  # the checks every calibration reader applies


def load_groundtruth(path: Path, gt_frame: str = "body", allow_jumps: bool = False):
    """(Trajectory, T_B_C0 or None) from a trajectory file or a dataset folder.

    ``allow_jumps``: a ground-truth *file* with position jumps is read as written (--allow-jumps).
    """
    from gevi_cli.trajectory import read_trajectory

    path = Path(path)
    if path.is_dir():
        gt_file = gt_file_in(path) if not (path / "mav0").exists() else None
        if gt_file is not None and not _is_dataset(path):
            return read_trajectory(gt_file, name="groundtruth", frame=gt_frame, allow_jumps=allow_jumps), None
        from gevi_cli.datasets import open_sequence

        seq = open_sequence(path)
        gt = seq.groundtruth
        if gt is None:
            raise GeviError(path, "the dataset has no ground truth")
        return gt, np.asarray(seq.calibration.T_B_C0, dtype=np.float64)
    if not path.exists():
        raise GeviError(path, "no such ground-truth file or dataset folder")
    return read_trajectory(path, name="groundtruth", frame=gt_frame, allow_jumps=allow_jumps), None


def run_sequence_times(run_folder: Path) -> Path | None:
    """The ``times.txt`` of the KITTI sequence a `gevi run` folder ran on, or None when it is not such a
    folder (no ``status.json`` + ``config.yaml`` of a run with ``kind: kitti``).

    The run's ``config.yaml`` names the sequence as given on the command line (a relative path is
    relative to where the run was started); a sequence that is no longer there is an error.
    """
    config = Path(run_folder) / "config.yaml"
    if not ((Path(run_folder) / "status.json").is_file() and config.is_file()):
        return None
    from gevi_cli.datasets.yamlio import load_yaml

    doc = load_yaml(config, empty_ok=True, what="run configuration")
    if not isinstance(doc, dict) or doc.get("kind") != "kitti" or not doc.get("sequence"):
        return None
    seq = Path(str(doc["sequence"]))
    candidates = [seq / "times.txt"] + sorted(seq.glob("sequences/*/times.txt"))  # a dataset root of one sequence
    times = next((c for c in candidates if c.is_file()), None)
    if times is None:
        raise GeviError(config, f"its KITTI sequence {seq} has no times.txt here (moved, or a relative path from "
                                "another folder): cannot stamp a KITTI ground truth to compare with this run; "
                                "give the ground truth with stamps (TUM) or the sequence folder")
    return times


def stamp_kitti_groundtruth(gt, times: Path):
    """The KITTI (unstamped) ground truth ``gt`` stamped with a sequence's ``times.txt`` (s -> ns).

    Row i of a KITTI file is frame i (a kitti-idx row carries its frame index), and frame i happened at
    line i of ``times.txt``: so a plain KITTI file must have exactly one row per time, and a kitti-idx
    file no index past the last time; anything else is refused (the files are of different sequences).
    """
    from gevi_cli.datasets.kitti import read_times
    from gevi_cli.trajectory import Trajectory
    from gevi_cli.trajectory.trajectory import KITTI_NOMINAL_PERIOD_NS

    stamps = read_times(Path(times))
    where = gt.meta.get("path") or "ground truth"
    frames = gt.t_ns // KITTI_NOMINAL_PERIOD_NS
    if gt.meta.get("format") == "kitti" and len(gt) != len(stamps):
        raise DataError(where, f"has {len(gt)} poses but {times} lists {len(stamps)} frames; row i of a KITTI file is "
                               "frame i, so they must match (a ground truth of another sequence, or cut short?)")
    if frames[-1] >= len(stamps):
        raise DataError(where, f"has frame index {int(frames[-1])} but {times} lists only {len(stamps)} frames "
                               "(a ground truth of another sequence?)")
    meta = dict(gt.meta, stamped_from=str(times))
    return Trajectory(stamps[frames], gt.positions, gt.quat_wxyz, frame=gt.frame, name=gt.name, meta=meta)


def _is_dataset(path: Path) -> bool:
    from gevi_cli.datasets import detect_kind

    try:
        detect_kind(path)
        return True
    except GeviError:  # not a dataset layout
        return False
