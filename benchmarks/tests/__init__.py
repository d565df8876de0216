"""The benchmarks' own tests (``pytest benchmarks/tests``, and the whole suite's command).

A package, so that a file here may share its name with one under ``tests/`` (both
``test_ablation.py``): pytest imports these as ``tests.test_<script>`` with ``benchmarks/`` on
``sys.path``."""
