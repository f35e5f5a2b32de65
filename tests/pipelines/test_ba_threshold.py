"""`ba.delta_sigmas`: the epipolar BA's kernel threshold is that many times the run's noise std (method.md 10)."""
from __future__ import annotations

import pytest

from gevi_cli import estimators as est
from gevi_cli.run.session import RunRequest, execute


def _ba_calls(monkeypatch, seq, tmp_path, sets=()):
    calls = []
    real = est.epipolar_local_ba

    def spy(window, options=None):
        r = real(window, options)
        calls.append((float(window.sigma), options.delta, r.delta))
        return r

    monkeypatch.setattr(est, "epipolar_local_ba", spy)
    execute(RunRequest(sequence=str(seq), method="cfo", out=str(tmp_path / "run"), quiet=True, sets=tuple(sets)),
            echo=lambda *a, **k: None)
    return calls


@pytest.mark.parametrize("k", [None, 1.5])
def test_kernel_threshold_is_k_sigma(monkeypatch, pool_render, tmp_path, k):
    sets = () if k is None else (f"ba.delta_sigmas={k}",)
    calls = _ba_calls(monkeypatch, pool_render, tmp_path, sets)
    assert len(calls) >= 5  # a 6 s render inserts keyframes all along
    factor = 3.0 if k is None else k  # the default is the 3 sigma_hat the estimator takes when given none
    for sigma, asked, used in calls:
        assert sigma > 0
        assert asked == used == pytest.approx(factor * sigma, rel=1e-15)
