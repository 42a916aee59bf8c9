"""One-off investigations behind the design of the fusion and the detector's speed (their
write-ups are in ``docs/``; see ``benchmarks/studies/README.md``)."""
