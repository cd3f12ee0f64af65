"""Scale-out on existing engines: many materials on a Dask cluster (``batch-many``).

* :mod:`.items` finds the inputs, names them and plans what a (re)run has left to do;
* :mod:`.worker` is what a Dask worker runs for one item: ``batch.py`` in a child process, into a
  private folder that is renamed into place only when the item succeeded (atomic per item);
* :mod:`.batch_many` is the client: cluster, submission, progress, retries and the report.

Distributed *training* (torchrun + DDP) lives beside the loop, in
:mod:`specgen_addon.train.distributed`.
"""
