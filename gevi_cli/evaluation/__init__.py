"""Evaluation of trajectories against ground truth (`gevi eval`).

One job per module: :mod:`evo_compat` (the only evo import, isolated), :mod:`associate`, :mod:`align`
(incl. 4-DOF posyaw), :mod:`ate`, :mod:`rpe`, :mod:`kitti_devkit`, :mod:`evaluate` (one estimate),
:mod:`inputs` (results-tree discovery, GT loading), :mod:`tables`, :mod:`report` (eval folder),
:mod:`plots`, :mod:`runner` (the CLI pipeline).  See docs/eval.md.
"""
