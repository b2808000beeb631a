"""Processing a whole dataset: many subject folders, in parallel, on Dask distributed.

Modules, in the order a run uses them:

* :mod:`solver.dataset.discover`: the subject folders under a dataset folder (any depth)
  and where each one's output goes (the output tree mirrors the input tree).
* :mod:`solver.dataset.manifest`: what an output was made from (hashes of the inputs,
  addb version, solver source digest, settings, review record) so that a rerun skips what is unchanged.
* :mod:`solver.dataset.task`: one subject on one worker: the pipeline, its log, the
  manifest, the summary rows, all moved into place atomically.
* :mod:`solver.dataset.summary`: per-trial rows and the dataset totals in the terms of the
  AddBiomechanics Dataset paper (Werling et al.): hours, hours with measured force,
  contact classes, clinical-grade frames, residual distributions.
* :mod:`solver.dataset.report`: the static HTML report (inline SVG, no server).
* :mod:`solver.dataset.runner`: the Dask cluster (local or remote), submission, retries
  of subjects whose worker died, progress, and the summary files.
* :mod:`solver.dataset.lock`: one run at a time per output tree (a one-subject run into it
  too, and the review app's Reprocess beside its own background run).
* :mod:`solver.dataset.one_subject`: the manifest a whole one-subject run into an output
  tree leaves, as a dataset run would, so that the next dataset run skips that subject.
* :mod:`solver.dataset.interrupt`: the local cluster's workers ignore Ctrl-C (the command
  handles it), those started again after a death included.
"""
