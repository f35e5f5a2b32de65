"""One batch run, in whatever process executes it: `gevi run` in-process, crash-proof, resumable.

The run folder is a complete `gevi run` folder (trajectories, status.json, config.yaml,
timing.csv, frames.csv, eval/) plus ``run.log`` (what `gevi run` printed) and the completion
marker ``done.json``, written last and atomically.  A folder without ``done.json`` is incomplete
(killed midway) and is redone on resume; one with it is final (ok, lost-tracking or crashed).
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

MARKER = "done.json"


def read_marker(run_dir) -> dict | None:
    p = Path(run_dir) / MARKER
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _write_marker(run_dir: Path, doc: dict) -> None:
    tmp = run_dir / (MARKER + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    os.replace(tmp, run_dir / MARKER)


def _clear(run_dir: Path) -> None:
    """Remove what an earlier, incomplete attempt left (only inside the run's own folder)."""
    import shutil

    if run_dir.is_dir():
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True)


@dataclass
class Finished:
    """A batch run done: its marker (``done.json``) and the run's own evaluations
    (:class:`gevi_cli.run.pipeline.Evaluation`; empty when it crashed or had no ground truth), which the
    batch's evaluation takes instead of evaluating the run a second time."""

    marker: dict
    evaluations: list = field(default_factory=list)


def run_one(spec) -> Finished:
    """Run ``spec`` (a :class:`~gevi_cli.batch.plan.RunSpec`) into its folder, as `gevi run` does.

    Any exception becomes state ``crashed`` with its message; KeyboardInterrupt is not caught (the
    folder then has no marker and the run is redone on resume).  The run has one BLAS/OpenCV
    thread (:func:`gevi_cli.run.threads.one_thread`), in whatever process this is.
    """
    from gevi_cli import __version__
    from gevi_cli.errors import GeviError
    from gevi_cli.run.folder import RunStatus, read_status, write_status
    from gevi_cli.run.session import run_in_folder

    run_dir = Path(spec.run_dir)
    _clear(run_dir)
    t0 = time.perf_counter()
    code, message, evaluations = 0, "", []
    with open(run_dir / "run.log", "w", buffering=1) as log:

        def echo(msg="", err=False, **_):
            log.write(("[stderr] " if err else "") + str(msg) + "\n")

        try:
            result = run_in_folder(spec.request(), echo=echo)
            code, evaluations = result.exit_code, result.evaluations
        except GeviError as exc:
            code, message = 2, exc.one_line()
        except Exception as exc:  # noqa: BLE001 - a crash is recorded and the batch goes on
            import traceback

            code, message = 1, f"{type(exc).__name__}: {exc}"
            log.write(traceback.format_exc())
    status = read_status(run_dir)
    if code in (1, 2):
        # the driver wrote "crashed" if the odometry itself raised; a failure before (bad input) has no status
        st = RunStatus(**{k: v for k, v in (status or {}).items() if k in RunStatus.__dataclass_fields__})
        st.state, st.message = "crashed", message
        st.method, st.sequence, st.gevi_version = st.method or dict(spec.params).get("method", ""), spec.sequence, \
            __version__
        write_status(run_dir, st)
        status = st.__dict__
    doc = {"run_id": spec.run_id, "state": status.get("state", "crashed"), "message": status.get("message", message),
           "exit_code": code, "seed": spec.seed, "wall_s": round(time.perf_counter() - t0, 3),
           "gevi_version": __version__, "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    _write_marker(run_dir, doc)
    return Finished(doc, evaluations)
