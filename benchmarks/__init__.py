"""Scripts that produce every published number; results go to ``benchmarks/results/``.

Run them from the repository root with the package's Python, as modules:
``python -m benchmarks.speed``, ``python -m benchmarks.studies.lidar_factor``.
"""
