"""Importing evo through gevi leaves the matplotlib backend and ~/.evo alone."""
import subprocess
import sys
import textwrap


def test_evo_import_keeps_backend_and_home(tmp_path):
    code = textwrap.dedent(f"""
        import matplotlib
        matplotlib.use("svg")
        from pathlib import Path
        import gevi_cli.evaluation.evo_compat as ec
        import gevi_cli.evaluation.plots, gevi_cli.evaluation.runner
        import evo.tools.settings as s          # already loaded by gevi: no new files
        from gevi_cli.evaluation.tables import Table, Cell
        from gevi_cli.evaluation.plots import plot_summary
        plot_summary(Path({str(tmp_path / 'p')!r}), Table("a", "A", ["m"], ["s"], {{("s", "m"): Cell([1.0], 1)}}))
        import sys
        print(matplotlib.get_backend(), s.SETTINGS.plot_backend, "matplotlib.pyplot" in sys.modules)
    """)
    home = tmp_path / "home"
    home.mkdir()
    p = subprocess.run([sys.executable, "-c", code], env={"HOME": str(home), "PATH": "/usr/bin:/bin",
                                                         "MPLCONFIGDIR": str(tmp_path / "mpl")},
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    backend, evo_backend, _ = p.stdout.split()
    assert backend == "svg" and evo_backend == "Agg"
    assert not (home / ".evo").exists()
    assert (tmp_path / "p" / "summary_ate.png").is_file()
