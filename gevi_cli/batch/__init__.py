"""`gevi batch` / `gevi regress`: sequences x methods x trials into one results tree, one report, a gate.

config (parse + validate the YAML) -> plan (run specs with stable paths) -> renders (simulated
sequences into the cache) -> executors (local processes or dask) running worker.run_one -> evaluate
(the `gevi eval` code over the tree) -> report (tables, runtime, report.md/html) -> regress (gate).
See docs/batch.md.
"""
