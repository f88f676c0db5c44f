"""The results pages' tables, made from the raw results committed under ``docs/results/`` and written into
``docs/results.md``, ``docs/ablation.md`` and ``docs/switching_results.md``:

    python -m benchmarks.results            # rewrite every page's generated blocks
    python -m benchmarks.results --check    # exit 1 naming the first table that differs from its evidence

:mod:`~benchmarks.results.doc` writes and checks the pages; :mod:`~benchmarks.results.headline`,
:mod:`~benchmarks.results.robustness`, :mod:`~benchmarks.results.switches` and :mod:`~benchmarks.results.sweep` make
the tables; :mod:`~benchmarks.results.evidence` reads and writes what they share. ``python -m
benchmarks.results.library_report`` and ``python -m benchmarks.results.plot_push_curves`` make the training records'
table and the push-curve figures of ``docs/benchmarks.md`` and ``docs/results_history.md``.
"""
