"""Golden files in and out: the errors and exit codes every golden module shares
(:mod:`~refraster.golden.io.errors`), buffer kinds and their PNG encodings
(:mod:`~refraster.golden.io.buffers`), the versioned schemas (:mod:`~refraster.golden.io.schema`),
scene packages (:mod:`~refraster.golden.io.package`), reading a golden or a candidate without
trusting either (:mod:`~refraster.golden.io.read`) and writing without destroying data
(:mod:`~refraster.golden.io.write`). Import the modules themselves; this package re-exports
nothing."""
