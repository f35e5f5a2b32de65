"""`gevi convert IN OUT --to FORMAT`: rewrite a trajectory in another format."""
from __future__ import annotations

import click

from gevi_cli.trajectory.formats import WRITE_FORMATS


@click.command("convert")
@click.argument("src", type=click.Path())
@click.argument("dst", type=click.Path())
@click.option("--to", "fmt", type=click.Choice(WRITE_FORMATS), required=True, help="Output format.")
@click.option("--allow-jumps", is_flag=True,
              help="Read a trajectory whose position jumps (refused by default as corrupt rows) as written.")
def command(src, dst, fmt, allow_jumps):
    """Read SRC (format detected from its content) and write DST as TUM, EuRoC csv or KITTI.

    Stamps are kept exactly (ns); KITTI output drops them (row i is pose i, or the frame index for
    kitti-idx).
    """
    from gevi_cli.trajectory import read_trajectory, write_trajectory

    traj = read_trajectory(src, allow_jumps=allow_jumps)
    for warning in traj.meta["warnings"]:
        click.echo(f"warning: {warning}", err=True)
    if fmt in ("tum", "euroc") and traj.indexed:
        click.echo(f"warning: {src}: has no stamps (KITTI); writing frame index x 0.1 s as time", err=True)
    write_trajectory(traj, dst, fmt)
    click.echo(f"{src} ({traj.meta['format']}, {len(traj)} poses) -> {dst} ({fmt})")
