"""The `gevi` command line: a thin click group.

Subcommands live in ``gevi_cli/commands/<name>.py`` (each defines ``command``) and are imported
only when invoked, so ``gevi --help`` stays fast (no numpy/cv2/evo import).  User errors are
:class:`gevi_cli.errors.GeviError` and print as one line with exit status 2.
"""
from __future__ import annotations

import importlib
import sys

import click

from gevi_cli import __version__
from gevi_cli.errors import GeviError

# name -> (module, one-line help shown by `gevi --help` without importing the module)
COMMANDS: dict[str, tuple[str, str]] = {
    "info": ("gevi_cli.commands.info", "Describe a sequence: sensors, rates, calibration, ground-truth coverage."),
    "convert": ("gevi_cli.commands.convert", "Convert a trajectory file between TUM, EuRoC csv and KITTI formats."),
    "eval": ("gevi_cli.commands.eval", "ATE/RPE/KITTI tables and plots of estimates against ground truth."),
    "simulate": ("gevi_cli.commands.simulate", "Render a synthetic stereo-IMU sequence with exact ground truth."),
    "run": ("gevi_cli.commands.run", "Run odometry (GeVI stereo-inertial or CurrentFeature stereo) and evaluate it."),
    "imu": ("gevi_cli.commands.imu", "IMU report: rate, gaps, standstills, biases, noise, roll/pitch over the stream."),
    "batch": ("gevi_cli.commands.batch", "Sequences x methods x trials from a YAML config: runs, evaluation, one report."),
    "regress": ("gevi_cli.commands.regress", "Compare a batch's ATE/RPE/frames tracked with expected values (CI gate)."),
}

EPILOG = """\b
Examples:
  gevi info datasets/euroc/V1_01_easy
  gevi info ../shared/data/euroc_micro --gt ../shared/data/euroc_micro/groundtruth/V1_01_easy.csv
  gevi convert estimate.csv estimate.tum --to tum
  gevi simulate --sample
  gevi eval --gt groundtruth.csv -e ours=traj.tum -e orbslam3=f_dataset.txt
  gevi run                     # GeVI on the built-in pool-easy sample
  gevi run ../shared/data/kitti06_head/dataset/sequences/06 --method cfo
  gevi imu ../shared/data/euroc_micro --gt ../shared/data/euroc_micro/groundtruth/V1_01_easy.csv
  gevi batch configs/batch/ci.yaml && gevi regress results/batch/ci --against tests/regression/expected.yaml
"""


class LazyGroup(click.Group):
    """A group whose subcommands are imported on first use."""

    def list_commands(self, ctx):
        return [name for name in COMMANDS if _available(name)]

    def get_command(self, ctx, name):
        if name not in COMMANDS or not _available(name):
            return None
        module = importlib.import_module(COMMANDS[name][0])
        return module.command

    def format_commands(self, ctx, formatter):
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


def _available(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(COMMANDS[name][0]) is not None


@click.group(cls=LazyGroup, epilog=EPILOG, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="gevi")
@click.option("--debug", is_flag=True, help="Show full tracebacks for errors.")
@click.pass_context
def cli(ctx, debug):
    """gevi: stereo and stereo-inertial odometry (GeVI, CurrentFeature Odometry) and evaluation."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


def main(argv=None):
    debug = "--debug" in (argv if argv is not None else sys.argv[1:])
    try:
        code = cli.main(args=argv, prog_name="gevi", standalone_mode=False)
        # without standalone mode click returns (does not raise) a command's Exit code
        if isinstance(code, int) and code:
            sys.exit(code)
    except GeviError as err:
        if debug:
            raise
        click.echo(f"gevi: error: {err.one_line()}", err=True)
        sys.exit(err.exit_code)
    except click.exceptions.Abort:
        click.echo("gevi: aborted", err=True)
        sys.exit(130)
    except click.exceptions.ClickException as err:
        # usage errors (unknown option, missing argument, bad choice): one line, exit 2
        where = ""
        if isinstance(err, click.exceptions.BadParameter) and err.param is not None:
            where = f"{err.param.get_error_hint(err.ctx)}: " if err.ctx else ""
        click.echo(f"gevi: error: {where}{err.format_message()}", err=True)
        sys.exit(2)
    except click.exceptions.Exit as err:
        sys.exit(err.exit_code)


if __name__ == "__main__":
    main()
