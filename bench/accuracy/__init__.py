"""The accuracy suite: ``python -m bench.accuracy.run_benchmark --docs docs/benchmark.md``
writes docs/benchmark.md (our estimator beside its tuned peers on every scenario)."""
