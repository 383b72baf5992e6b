"""Comparing a candidate with a golden: the run over scenes and buffers
(:mod:`~refraster.golden.compare.run`, ``golden compare``), the tolerance profiles stored in the
manifest (:mod:`~refraster.golden.compare.profiles`), per-buffer metrics
(:mod:`~refraster.golden.compare.metrics`), domain checks (:mod:`~refraster.golden.compare.domain`)
and the HTML report (:mod:`~refraster.golden.compare.report`). Import the modules themselves;
this package re-exports nothing (:func:`refraster.golden.compare` is the run's entry point)."""
