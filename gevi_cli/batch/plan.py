"""Expand a batch config into run specs (sequence x method x trial) with stable ids and folders.

Results tree (``-o OUT``)::

    OUT/runs/<method>/<sequence>/trial<k>/   one `gevi run` folder per run (+ run.log, done.json)
    OUT/report/                              the report (see gevi_cli.batch.report)

``<method>/<sequence>/`` is the layout ``gevi eval --results OUT/runs`` reads.  Trial ``k`` (1-based)
runs with ``--seed k``; a ``seed_per_trial`` simulated sequence is also rendered with seed ``k``.  CFO
takes no seed (OpenCV's 5-point RANSAC keeps its own): it runs once per sequence, whatever ``trials``
says, except on a ``seed_per_trial`` render, whose trials are different renders (:func:`deterministic`).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from gevi_cli.batch.config import BatchConfig, RunInputs, SequenceEntry, SimSpec
from gevi_cli.errors import GeviError


@dataclass(frozen=True)
class RunSpec:
    """One run; everything a worker needs, as plain values (it is pickled to other processes/hosts)."""

    run_id: str  # "<method>/<sequence>/trial<k>"
    method: str  # the method's label, e.g. "cfo --pnp epnp"
    method_id: str
    sequence: str
    trial: int
    seed: int | None  # None: the method takes no seed (CFO)
    run_dir: str
    params: tuple  # (RunRequest field, value) of the method
    sim: SimSpec | None = None  # the render this run reads (resolved to ``source`` before dispatch)
    source: str | None = None  # dataset path given to `gevi run`
    inputs: RunInputs = RunInputs()

    def request(self):
        """The :class:`RunRequest` of this run (what `gevi run` would build from its options)."""
        from gevi_cli.run.session import RunRequest

        kw = dict(self.params)
        if "sets" in kw:
            kw["sets"] = tuple(kw["sets"])
        return RunRequest(sequence=self.source, seed=self.seed, out=self.run_dir, quiet=True,
                          **self.inputs.request_kwargs(), **kw)


def sim_for_trial(seq: SequenceEntry, trial: int) -> SimSpec | None:
    if seq.sim is None:
        return None
    return dataclasses.replace(seq.sim, seed=trial) if seq.seed_per_trial else seq.sim


def deterministic(method: str) -> bool:
    """The method's runs on one input are identical to the byte: it takes no seed (CFO; GeVI's 3-point RANSAC
    draws from one)."""
    from gevi_cli.pipelines.config import SEEDED_METHODS

    return method not in SEEDED_METHODS


def trials_run(m, seq: SequenceEntry) -> int:
    """How many of method entry ``m``'s trials run on ``seq``: one for a deterministic method on one input."""
    return 1 if deterministic(m.method) and not seq.seed_per_trial else m.trials


def expand(cfg: BatchConfig, out: Path) -> list[RunSpec]:
    """Every run of the batch, in a stable order (sequence, method, trial); skipped sequences left out."""
    runs = []
    for seq in cfg.sequences:
        if seq.skip_reason:
            continue
        for m in cfg.methods:
            if seq.methods is not None and m.name not in seq.methods:
                continue
            for k in range(1, trials_run(m, seq) + 1):
                rid = f"{m.ident}/{seq.name}/trial{k}"
                seed = None if deterministic(m.method) else k
                runs.append(RunSpec(run_id=rid, method=m.name, method_id=m.ident, sequence=seq.name, trial=k, seed=seed,
                                    run_dir=str(Path(out) / "runs" / rid), params=m.params, sim=sim_for_trial(seq, k),
                                    source=seq.path, inputs=seq.inputs))
    return runs


def check_methods_fit(cfg: BatchConfig) -> None:
    """Each method against each sequence's kind of input, as `gevi run` would check it, at the door: GeVI
    needs an IMU (a gevi method on a kitti-format render is a config error; datasets are checked by the
    run itself and recorded as crashed), and a method that sets what does not apply to the input (``frontend.*``
    or ``keyframe.*`` on a track export, ``verify.use_export_flags`` on images) is one too."""
    from gevi_cli.run.method_options import check_method_config
    from gevi_cli.run.session import is_track_export

    for seq in cfg.sequences:
        if seq.skip_reason:
            continue
        methods = [m for m in cfg.methods if seq.methods is None or m.name in seq.methods]
        if seq.sim is not None:
            kind = seq.sim.fmt
            for m in methods:
                if m.method == "gevi" and seq.sim.fmt == "kitti":
                    raise GeviError(f"{cfg.path}:{seq.line}", f"sequences.{seq.name}: method {m.name!r} needs an IMU "
                                                              "but a kitti-format render has none; list methods: for it")
        elif seq.path is None:
            continue
        elif seq.inputs.kind == "ov2slam-tracks" or (seq.inputs.kind is None and is_track_export(Path(seq.path))):
            kind = "ov2slam-tracks"
        else:
            kind = seq.inputs.kind or "images"
        for m in methods:
            try:
                check_method_config(m.params, kind)
            except GeviError as exc:
                raise GeviError(f"{cfg.path}:{m.line}", f"methods: {m.name!r} on sequences.{seq.name}: "
                                                        f"{exc.one_line()}") from None


@dataclass(frozen=True)
class BaselineRun:
    """One baseline trajectory (or its absence) for one sequence."""

    name: str
    ident: str
    sequence: str
    path: str | None  # the trajectory file; None with state "failed" (no file) or "n/a"
    state: str  # "ok", "failed" (the system ran and wrote no trajectory), "n/a" (not run on this sequence)
    reason: str
    frame: str
    T_B_C0: object
    fmt: str
    trial: str = ""  # "run<k>" when the baseline lists several files (runs) per sequence
    stamps_ns: tuple | None = None  # int ns per row (``stamps: sequence``), else the file's own stamps


def sequence_stamps(seq: SequenceEntry) -> tuple:
    """The stamps (int ns) of the frames every run of the dataset sequence ``seq`` is given."""
    from gevi_cli.run.session import RunRequest, frame_range, open_input

    req = RunRequest(sequence=seq.path, **seq.inputs.request_kwargs())
    source, _ = open_input(req)
    start, stop = frame_range(req, len(source))
    return tuple(int(t) for t in source.stamps_ns[start:stop])


def baseline_runs(cfg: BatchConfig) -> list[BaselineRun]:
    """Resolve the baseline templates per sequence and read every file once (an unreadable one, or one
    whose rows do not match the sequence's frames under ``stamps: sequence``, is a config error, exit 2,
    before any run)."""
    from gevi_cli.trajectory import read_trajectory

    out = []
    for b in cfg.baselines:
        if b.skip_reason:
            continue
        where = f"{cfg.path}:{b.line}"
        for seq in cfg.sequences:
            if seq.skip_reason or (b.sequences is not None and seq.name not in b.sequences):
                continue
            d = cfg.resolve(b.path.format(sequence=seq.name, stride=seq.inputs.stride))
            common = {"name": b.name, "ident": b.ident, "sequence": seq.name, "frame": b.frame, "T_B_C0": b.T_B_C0,
                      "fmt": b.fmt}
            if not d.exists():
                out.append(BaselineRun(path=None, state="n/a", reason=f"{d} is absent", **common))
                continue
            if d.is_dir() and not b.files:
                raise GeviError(where, f"baselines.{b.name}: {d} is a folder; name the trajectory inside it with file:")
            stamps = None
            if b.stamps == "sequence":
                if seq.path is None:
                    raise GeviError(where, f"baselines.{b.name}: stamps: sequence needs a dataset (path:) sequence, "
                                           f"not the render {seq.name}")
                stamps = sequence_stamps(seq)
            files = [d / f for f in b.files] if d.is_dir() else [d]
            for k, f in enumerate(files, start=1):
                trial = f"run{k}" if len(files) > 1 else ""
                if not f.is_file():
                    out.append(BaselineRun(path=None, state="failed", reason=f"no trajectory written ({f.name} absent)",
                                           trial=trial, **common))
                    continue
                try:
                    traj = read_trajectory(f)  # every row is validated here, once
                except GeviError as exc:
                    raise GeviError(where, f"baselines.{b.name}: unreadable: {exc.one_line()}") from None
                except OSError as exc:
                    raise GeviError(where, f"baselines.{b.name}: {f}: {exc.strerror}") from None
                if traj.meta["format"] != b.fmt:
                    raise GeviError(where, f"baselines.{b.name}: {f} reads as {traj.meta['format']}, the config "
                                           f"declares format: {b.fmt}")
                if stamps is not None and len(traj) != len(stamps):
                    raise GeviError(where, f"baselines.{b.name}: {f} has {len(traj)} rows but {seq.name} gives its "
                                           f"runs {len(stamps)} frames (stamps: sequence needs one row per frame)")
                out.append(BaselineRun(path=str(f), state="ok", reason="", trial=trial, stamps_ns=stamps, **common))
    return out
