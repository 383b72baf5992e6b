"""Allowances: what a conformant backend may do differently, per pixel, stored beside a golden
scene's buffers and checked by the tolerant compare.

:mod:`~refraster.golden.allowances.core` derives the allowances of plain G-buffers (coverage,
intervals, face sets), dispatches a technique scene to its own module and holds the tolerant
check; one module per technique bounds that technique's output by its own arithmetic:
:mod:`~refraster.golden.allowances.layers` (layered depth images),
:mod:`~refraster.golden.allowances.clip` (clip surfaces and the cutaway's cut decision),
:mod:`~refraster.golden.allowances.edges` (edge maps and the NPR composite),
:mod:`~refraster.golden.allowances.cutaway` (the cutaway depth D),
:mod:`~refraster.golden.allowances.ghosts` (ghost lines) and
:mod:`~refraster.golden.allowances.halos` (4D halos);
:mod:`~refraster.golden.allowances.homogeneous` is the leaf they share. Why they live here and
not beside each technique: ``docs/architecture.md``, "The goldens". Import the modules
themselves; this package re-exports nothing."""
