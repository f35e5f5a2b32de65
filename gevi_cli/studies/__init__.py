"""Monte Carlo study set-ups of the papers, kept apart from the estimator library.

The synthetic scenes and simulators (``simulation``), the Monte Carlo drivers of the spec-11.3
(4-DOF) and spec-5.6 (6-DOF) protocols (``montecarlo``) and the S1 Fig. 4c outlier study
(``outlier_study``) behind the estimator figures (``scripts/fig4_*.py``) and the estimator tests.
They call ``gevi_cli.estimators`` the way the pipelines do; ``gevi_cli.estimators`` imports
nothing from here.
"""
