"""Offline evaluation: the replay loop (``replay``), the offline runner (``runner``), fault
injection (``faults``), the tunnel evaluation (``tunnel``), metrics via evo (``metrics``),
plots, and the pure helpers the benchmarks report with (``comparison``, ``return_check``,
``timing``, ``run_diagnostics``)."""
