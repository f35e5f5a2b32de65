"""`gevi batch CONFIG.yaml`: sequences x methods x trials into one results tree and one report."""
from __future__ import annotations

import click

EPILOG = """\b
Examples:
  gevi batch configs/batch/ci.yaml
  gevi batch configs/batch/pool.yaml -o results/pool --jobs 2
  gevi batch configs/batch/pool.yaml --executor dask --scheduler tcp://10.0.0.5:8786
\b
Exit status: 0 all runs ran, 3 some lost tracking or crashed (see the report), 2 bad config.
Config schema, results tree, resume and the report: docs/batch.md.
"""


@click.command("batch", epilog=EPILOG, context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("-o", "--out", type=click.Path(file_okay=False), default=None,
              help="Results folder (default: the config's output:, else results/batch/<name>).")
@click.option("--jobs", "-j", type=click.IntRange(min=1, max=256), default=1, show_default=True,
              help="Local worker processes (1: in this process).")
@click.option("--force", is_flag=True, help="Redo finished runs too (default: resume, only missing runs).")
@click.option("--executor", type=click.Choice(["local", "dask"]), default="local", show_default=True,
              help="local: --jobs processes here; dask: the dask.distributed cluster at --scheduler.")
@click.option("--scheduler", metavar="ADDRESS", default=None, help="dask scheduler address (tcp://host:8786).")
@click.option("--sequences", "sequences", multiple=True, metavar="NAME[,NAME]",
              help="Run only these sequences of CONFIG (repeatable).")
@click.option("--trials", type=click.IntRange(min=1), default=None, help="Override every method's trial count.")
def command(config, out, jobs, force, executor, scheduler, sequences, trials):
    """Run every method (and trial) of CONFIG on every sequence, evaluate, and write one report."""
    from gevi_cli.batch.runner import run_batch
    from gevi_cli.run.threads import one_thread

    with one_thread():  # the renders and the evaluation here; each run pins its own (run.session.execute)
        code = run_batch(config, out, jobs=jobs, force=force, executor=executor, scheduler=scheduler,
                         echo=click.echo, sequences=sequences, trials=trials)
    if code:
        raise click.exceptions.Exit(code)
