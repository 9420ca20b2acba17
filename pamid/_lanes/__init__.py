"""Lanes: batches of independent problems (muscles, folds, candidate sets, interval ends) run
as compiled programs, whatever is solved in them.

- ``_batch.py``: the packed batch (:class:`FitData`, ``pack``, ``pack_rows``), its size
  classes of rows and lanes (``padded_rows``, ``padded_lanes``: files of nearby size run the
  same compiled programs) and :func:`map_lanes`, which runs a function over lanes in chunks
  of one size on threads and devices;
- ``_sharding.py``: the devices lanes are split over (``use_devices``);
- ``_programs.py``: the compiled programs a process holds, kept below the system's limit on
  memory regions;
- ``_export_cache.py``: compiled programs kept on disk between processes (the command line's
  cache), and the start-up thread that loads them.

It knows nothing of models or solvers: the fitting code (``pamid._fit``), the diagnosis, the
decays and the sampler pass it functions.
"""
