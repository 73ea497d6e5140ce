"""Benchmarks of the package, by what they answer (docs/layout.md "bench/"):

* :mod:`bench.accuracy`: the accuracy suite, ``python -m bench.accuracy.run_benchmark`` and
  its parts (scenarios, peers and their tuning, the real-truck family, issue 11's targets,
  the README's headline);
* :mod:`bench.probes`: speed and memory probes (bag I/O, estimate_bag, the nodes, fleets);
* :mod:`bench.studies`: investigations whose answer is written in docs/ or docs/notes/, kept
  as the command that reproduces it;
* :mod:`bench.output_hashes`: the no-change check (SHA-256 of the offline commands' bags).
"""
