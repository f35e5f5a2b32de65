"""The `gevi run` options that choose and configure a method: one definition, used by `gevi run`'s command
and by batch configs (a method entry is these options, checked by the same parser)."""
from __future__ import annotations

import click

from gevi_cli.errors import GeviError
from gevi_cli.pipelines.config import METHODS, PNP_METHODS

#: the flags a batch method entry may use (sequence, seed and output belong to the batch)
METHOD_FLAGS = ("--method", "--config", "--set", "--pnp", "--no-ba", "--ransac", "--no-adaptive", "--no-fusion",
                "--imu-time-offset")

_OPTIONS = [
    click.option("--method", type=click.Choice(METHODS), default=None,
                 help="gevi: gravity-enhanced stereo-inertial odometry; cfo: CurrentFeature Odometry (stereo). "
                      "Default: gevi when the sequence has an IMU, else cfo."),
    click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
                 help="YAML overriding the defaults (after gevi_cli/configs/<kind>.yaml)."),
    click.option("--set", "sets", multiple=True, metavar="STAGE.KEY=VALUE", help="Override one key (repeatable)."),
    click.option("--pnp", type=click.Choice(PNP_METHODS), default=None,
                 help="Pose estimator (ablations; = --set pnp.method=...)."),
    click.option("--no-ba", is_flag=True, help="No epipolar local BA (= --set ba.enabled=false)."),
    click.option("--ransac", type=click.Choice(["3pt", "5pt"]), default=None,
                 help="gevi: verification RANSAC (ablation; = --set verify.ransac=...)."),
    click.option("--no-adaptive", is_flag=True, help="gevi: fixed gravity-prior weight (= --set fusion.adaptive=false)."),
    click.option("--no-fusion", is_flag=True, help="gevi: 4-DOF only, roll/pitch from the IMU alone "
                                                   "(= --set fusion.mode=4dof)."),
    click.option("--imu-time-offset", type=float, default=None, metavar="SECONDS",
                 help="gevi: camera-IMU time shift t_imu = t_cam + shift (default: the calibration's)."),
]


def method_options(func):
    """Decorate a click command with the method options."""
    for option in reversed(_OPTIONS):
        func = option(func)
    return func


@click.command("run")
@method_options
def _parser(**params):  # pragma: no cover - never invoked, only its context is made
    pass


def parse_method_args(args: list[str], where: str) -> tuple:
    """(RunRequest field, value) pairs from method options, checked by `gevi run`'s own option definitions;
    a one-line GeviError at ``where`` otherwise."""
    for a in args:
        if a.startswith("-") and a.split("=")[0] not in METHOD_FLAGS:
            raise GeviError(where, f"option {a} is not a method option; allowed: {', '.join(sorted(METHOD_FLAGS))} "
                                   "(sequence, seed and output are the batch's)")
    try:
        ctx = _parser.make_context("run", list(args), resilient_parsing=False)
    except click.exceptions.UsageError as exc:
        raise GeviError(where, exc.format_message()) from None
    params = [(k, tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in ctx.params.items()
              if v not in (None, False, ())]
    if not dict(params).get("method"):
        raise GeviError(where, "name the method first: gevi ... or cfo ...")
    return tuple(sorted(params))


def check_method_config(params: tuple, kind: str | None = None) -> None:
    """Resolve the configuration a method entry's ``params`` (from :func:`parse_method_args`) make, for
    input ``kind`` (None: any), with `gevi run`'s checks; a one-line GeviError naming the option or file."""
    from gevi_cli.run.session import RunRequest, resolve_config

    values = dict(params)
    req = RunRequest(sequence=None, **{k: v for k, v in values.items()})
    resolve_config(req, kind, values["method"])
