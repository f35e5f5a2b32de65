"""`gevi regress RESULTS --against expected.yaml`: the regression gate over a `gevi batch` results tree."""
from __future__ import annotations

import click

EPILOG = """\b
Examples:
  gevi regress results/batch/ci --against tests/regression/expected.yaml
  gevi regress results/batch/ci --write-expected tests/regression/expected.yaml   # after a deliberate change
\b
Exit status: 0 nothing worse than expected beyond its tolerance, 1 a regression, 2 bad input.
"""


@click.command("regress", epilog=EPILOG, context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("results", type=click.Path(file_okay=False))
@click.option("--against", "expected", type=click.Path(dir_okay=False), default=None,
              help="Expected values with tolerances (YAML, see docs/batch.md).")
@click.option("--write-expected", "write", type=click.Path(dir_okay=False), default=None,
              help="Write RESULTS' values and tolerances (derived from the spread over trials) to this file.")
def command(results, expected, write):
    """Compare ATE/RPE/frames tracked of a batch with expected values; exit 1 on a regression."""
    from pathlib import Path

    from gevi_cli.batch.regress import compare, render, write_expected
    from gevi_cli.errors import GeviError

    if bool(expected) == bool(write):
        raise GeviError("gevi regress", "give exactly one of --against FILE or --write-expected FILE")
    if write:
        click.echo(f"wrote {write_expected(Path(results), Path(write))}")
        return
    rows, notes = compare(Path(results), Path(expected))
    click.echo(render(rows))
    for n in notes:
        click.echo(f"note: {n}")
    worse = [r for r in rows if r.verdict in ("WORSE", "FAILED")]
    better = [r for r in rows if r.verdict == "better"]
    click.echo(f"gevi regress: {len(rows)} values, {len(worse)} worse than expected, {len(better)} better")
    if worse:
        raise click.exceptions.Exit(1)
