"""Benchmarks (``python -m bench.<name>``). A benchmark's results section is stamped with the
commit of the code it runs, taken when the benchmark starts (:data:`START_COMMIT`, read by
``bench.results_doc``): code edited while it runs does not mark its figures ``+dirty``."""

from bench.results_doc import run_commit

#: ``bench.results_doc.run_commit()`` when this process first imported ``bench``.
START_COMMIT = run_commit()
