"""Expand a batch config into run specs (sequence x method x trial) with stable ids and folders.

Results tree (``-o OUT``)::

    OUT/runs/<method>/<sequence>/trial<k>/   one `gevi run` folder per run (+ run.log, done.json)
    OUT/report/                              the report (see gevi_cli.batch.report)

``<method>/<sequence>/`` is the layout ``gevi eval --results OUT/runs`` reads.  Trial ``k`` (1-based)
runs with ``--seed k``; a ``seed_per_trial`` simulated sequence is also rendered with seed ``k``.
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
    seed: int
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


def expand(cfg: BatchConfig, out: Path) -> list[RunSpec]:
    """Every run of the batch, in a stable order (sequence, method, trial); skipped sequences left out."""
    runs = []
    for seq in cfg.sequences:
        if seq.skip_reason:
            continue
        for m in cfg.methods:
            if seq.methods is not None and m.name not in seq.methods:
                continue
            for k in range(1, m.trials + 1):
                rid = f"{m.ident}/{seq.name}/trial{k}"
                runs.append(RunSpec(run_id=rid, method=m.name, method_id=m.ident, sequence=seq.name, trial=k, seed=k,
                                    run_dir=str(Path(out) / "runs" / rid), params=m.params, sim=sim_for_trial(seq, k),
                                    source=seq.path, inputs=seq.inputs))
    return runs


def check_methods_fit(cfg: BatchConfig) -> None:
    """GeVI needs an IMU: a gevi method on a kitti-format render is a config error (datasets are checked
    by the run itself and recorded as crashed)."""
    for seq in cfg.sequences:
        if seq.sim is None:
            continue
        for m in cfg.methods:
            if (seq.methods is None or m.name in seq.methods) and m.method == "gevi" and seq.sim.fmt == "kitti":
                raise GeviError(f"{cfg.path}:{seq.line}", f"sequences.{seq.name}: method {m.name!r} needs an IMU but "
                                                          "a kitti-format render has none; list methods: for it")


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


def baseline_runs(cfg: BatchConfig) -> list[BaselineRun]:
    """Resolve the baseline templates per sequence and read every file once (an unreadable one is a
    config error, exit 2, before any run)."""
    from gevi_cli.trajectory import read_trajectory

    out = []
    for b in cfg.baselines:
        if b.skip_reason:
            continue
        for seq in cfg.sequences:
            if seq.skip_reason or (b.sequences is not None and seq.name not in b.sequences):
                continue
            d = cfg.resolve(b.path.format(sequence=seq.name))
            common = {"name": b.name, "ident": b.ident, "sequence": seq.name, "frame": b.frame, "T_B_C0": b.T_B_C0,
                      "fmt": b.fmt}
            if not d.exists():
                out.append(BaselineRun(path=None, state="n/a", reason=f"{d} is absent", **common))
                continue
            f = d / b.file if b.file and d.is_dir() else d
            if d.is_dir() and not b.file:
                raise GeviError(f"{cfg.path}:{b.line}", f"baselines.{b.name}: {d} is a folder; name the trajectory "
                                                        "inside it with file:")
            if not f.is_file():
                out.append(BaselineRun(path=None, state="failed", reason=f"no trajectory written ({f.name} absent)",
                                       **common))
                continue
            try:
                found = read_trajectory(f).meta["format"]  # every row is validated here, once
            except GeviError as exc:
                raise GeviError(f"{cfg.path}:{b.line}", f"baselines.{b.name}: unreadable: {exc.one_line()}") from None
            except OSError as exc:
                raise GeviError(f"{cfg.path}:{b.line}", f"baselines.{b.name}: {f}: {exc.strerror}") from None
            if found != b.fmt:
                raise GeviError(f"{cfg.path}:{b.line}", f"baselines.{b.name}: {f} reads as {found}, the config "
                                                        f"declares format: {b.fmt}")
            out.append(BaselineRun(path=str(f), state="ok", reason="", **common))
    return out
